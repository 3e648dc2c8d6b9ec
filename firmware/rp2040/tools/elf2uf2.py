#!/usr/bin/env python3
"""Convert an RP2040 firmware ELF into a UF2 file and report its flash and RAM use.

Usage: elf2uf2.py FIRMWARE.elf OUT.uf2

Standard library only, so it runs on any machine with Python 3 (no crate to compile, no
libudev). The UF2 holds every loadable byte destined for the RP2040's XIP flash
(0x10000000..0x11000000) in 256-byte pages, one page per 512-byte UF2 block, with the RP2040
family ID (0xE48BFF56) as the bootrom's BOOTSEL drive expects.

Flash use = bytes of loadable segments stored in flash (code, read-only data and the initial
values of .data). RAM use = memory size of segments that live in SRAM (.data, .bss, .uninit).
The stack takes the rest of RAM at run time and is not counted.

The output is written atomically (temporary file in the same directory, then rename).
"""

import os
import struct
import sys
import tempfile

UF2_MAGIC_START0 = 0x0A324655
UF2_MAGIC_START1 = 0x9E5D5157
UF2_MAGIC_END = 0x0AB16F30
UF2_FLAG_FAMILY_ID_PRESENT = 0x00002000
RP2040_FAMILY_ID = 0xE48BFF56
PAGE = 256

FLASH_START, FLASH_END = 0x10000000, 0x11000000
RAM_START, RAM_END = 0x20000000, 0x20042000
FLASH_SIZE = 2 * 1024 * 1024  # Pico: 2 MiB (memory.x)
RAM_SIZE = 256 * 1024  # memory.x: striped SRAM0-3

PT_LOAD = 1


class ElfError(Exception):
    pass


def load_segments(path):
    """Returns [(paddr, vaddr, filesz, memsz, data)] of PT_LOAD segments."""
    with open(path, "rb") as f:
        elf = f.read()
    if elf[:4] != b"\x7fELF":
        raise ElfError(f"{path}: not an ELF file")
    if elf[4] != 1 or elf[5] != 1:
        raise ElfError(f"{path}: not a 32-bit little-endian ELF (EI_CLASS={elf[4]}, EI_DATA={elf[5]})")
    (e_machine,) = struct.unpack_from("<H", elf, 18)
    if e_machine != 40:
        raise ElfError(f"{path}: not an ARM ELF (e_machine={e_machine})")
    e_phoff, = struct.unpack_from("<I", elf, 28)
    e_phentsize, e_phnum = struct.unpack_from("<HH", elf, 42)
    segments = []
    for i in range(e_phnum):
        p_type, p_offset, p_vaddr, p_paddr, p_filesz, p_memsz, _flags, _align = struct.unpack_from(
            "<IIIIIIII", elf, e_phoff + i * e_phentsize
        )
        if p_type != PT_LOAD or p_memsz == 0:
            continue
        if p_offset + p_filesz > len(elf):
            raise ElfError(f"{path}: segment {i} extends past the end of the file")
        segments.append((p_paddr, p_vaddr, p_filesz, p_memsz, elf[p_offset : p_offset + p_filesz]))
    if not segments:
        raise ElfError(f"{path}: no loadable segments")
    return segments


def flash_pages(segments):
    """Maps page address -> 256-byte page content for every flash-resident byte."""
    pages = {}
    for paddr, _vaddr, filesz, _memsz, data in segments:
        if filesz == 0:
            continue
        if not (FLASH_START <= paddr and paddr + filesz <= FLASH_END):
            raise ElfError(f"segment at 0x{paddr:08x} (+{filesz}) is not in flash: is this an RP2040 flash image?")
        for i, byte in enumerate(data):
            addr = paddr + i
            page = addr & ~(PAGE - 1)
            buf = pages.setdefault(page, bytearray(PAGE))
            buf[addr - page] = byte
    return pages


def uf2_bytes(pages):
    out = bytearray()
    addrs = sorted(pages)
    for n, addr in enumerate(addrs):
        header = struct.pack(
            "<IIIIIIII",
            UF2_MAGIC_START0,
            UF2_MAGIC_START1,
            UF2_FLAG_FAMILY_ID_PRESENT,
            addr,
            PAGE,
            n,
            len(addrs),
            RP2040_FAMILY_ID,
        )
        payload = bytes(pages[addr]) + bytes(476 - PAGE)
        out += header + payload + struct.pack("<I", UF2_MAGIC_END)
    return bytes(out)


def usage(segments):
    flash = sum(filesz for paddr, _v, filesz, _m, _d in segments if FLASH_START <= paddr < FLASH_END)
    ram = sum(memsz for _p, vaddr, _f, memsz, _d in segments if RAM_START <= vaddr < RAM_END)
    return flash, ram


def write_atomic(path, data):
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".uf2-")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    elf_path, uf2_path = argv[1], argv[2]
    try:
        segments = load_segments(elf_path)
        pages = flash_pages(segments)
    except (OSError, ElfError) as e:
        print(f"elf2uf2: {e}", file=sys.stderr)
        return 1
    if FLASH_START not in pages:
        print(f"elf2uf2: {elf_path}: nothing at 0x{FLASH_START:08x} (no boot2): the image would not boot", file=sys.stderr)
        return 1
    data = uf2_bytes(pages)
    write_atomic(uf2_path, data)
    flash, ram = usage(segments)
    print(f"flash: {flash} bytes ({100.0 * flash / FLASH_SIZE:.1f}% of {FLASH_SIZE // 1024} KiB)")
    print(f"ram:   {ram} bytes static ({100.0 * ram / RAM_SIZE:.1f}% of {RAM_SIZE // 1024} KiB; the stack uses the rest)")
    print(f"uf2:   {uf2_path} ({len(pages)} blocks, {len(data)} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
