'use strict';
// Minimal ELF32 (little-endian, ARM) loader: the PT_LOAD segments of the firmware image.

const fs = require('fs');

const PT_LOAD = 1;

/** Returns [{paddr, vaddr, data: Buffer, memsz}] of the loadable segments of `path`. */
function loadSegments(path) {
  const elf = fs.readFileSync(path);
  if (elf.length < 52 || elf.readUInt32BE(0) !== 0x7f454c46) {
    throw new Error(`${path}: not an ELF file`);
  }
  if (elf[4] !== 1 || elf[5] !== 1) throw new Error(`${path}: not a 32-bit little-endian ELF`);
  if (elf.readUInt16LE(18) !== 40) throw new Error(`${path}: not an ARM ELF`);
  const phoff = elf.readUInt32LE(28);
  const phentsize = elf.readUInt16LE(42);
  const phnum = elf.readUInt16LE(44);
  const segments = [];
  for (let i = 0; i < phnum; i++) {
    const o = phoff + i * phentsize;
    const type = elf.readUInt32LE(o);
    const offset = elf.readUInt32LE(o + 4);
    const vaddr = elf.readUInt32LE(o + 8);
    const paddr = elf.readUInt32LE(o + 12);
    const filesz = elf.readUInt32LE(o + 16);
    const memsz = elf.readUInt32LE(o + 20);
    if (type !== PT_LOAD || memsz === 0) continue;
    if (offset + filesz > elf.length) throw new Error(`${path}: segment ${i} extends past the end of the file`);
    segments.push({ paddr, vaddr, memsz, data: elf.subarray(offset, offset + filesz) });
  }
  if (segments.length === 0) throw new Error(`${path}: no loadable segments`);
  return segments;
}

const FLASH_BASE = 0x10000000;

/** Copies every flash-resident byte of the image into `flash` (a Uint8Array at 0x10000000). */
function loadIntoFlash(path, flash) {
  for (const seg of loadSegments(path)) {
    if (seg.data.length === 0) continue;
    const off = seg.paddr - FLASH_BASE;
    if (off < 0 || off + seg.data.length > flash.length) {
      throw new Error(`${path}: segment at 0x${seg.paddr.toString(16)} is not in flash`);
    }
    flash.set(seg.data, off);
  }
}

const SHT_SYMTAB = 2;

/**
 * Address of the first symbol in the ELF's symbol table named `name` (a string, or a predicate
 * on the name: Rust's v0 mangling decorates even `rust_begin_unwind`), or null.
 */
function symbolAddress(path, name) {
  const matches = typeof name === 'function' ? name : (n) => n === name;
  const elf = fs.readFileSync(path);
  const shoff = elf.readUInt32LE(32);
  const shentsize = elf.readUInt16LE(46);
  const shnum = elf.readUInt16LE(48);
  const section = (i) => {
    const o = shoff + i * shentsize;
    return {
      type: elf.readUInt32LE(o + 4),
      offset: elf.readUInt32LE(o + 16),
      size: elf.readUInt32LE(o + 20),
      link: elf.readUInt32LE(o + 24),
      entsize: elf.readUInt32LE(o + 36),
    };
  };
  for (let i = 0; i < shnum; i++) {
    const sym = section(i);
    if (sym.type !== SHT_SYMTAB) continue;
    const str = section(sym.link);
    for (let o = sym.offset; o + 16 <= sym.offset + sym.size; o += sym.entsize || 16) {
      const nameOff = elf.readUInt32LE(o);
      let end = str.offset + nameOff;
      while (elf[end] !== 0) end++;
      if (matches(elf.toString('latin1', str.offset + nameOff, end))) return elf.readUInt32LE(o + 4);
    }
  }
  return null;
}

module.exports = { loadSegments, loadIntoFlash, symbolAddress, FLASH_BASE };
