#!/usr/bin/env python3
"""Writes the cargo-fuzz corpus for the decoder target from the golden frames.

The frames are the byte-for-byte examples of docs/protocol.md section 5 (pinned by
protocol/tests/golden.rs); each becomes corpus/decoder/golden-<name>.bin, preceded by the
split-size byte the target reads first. Standard library only:

    python3 protocol/fuzz/seed_corpus.py
"""
import pathlib

GOLDEN = {
    "ping": "07 01 07 1d b6 a6 c6 00",
    "hello": "01 01 06 01 84 e9 46 88 00",
    "read-clock": "08 ac 02 01 02 2f 12 6a 00",
    "hello-response": "01 01 01 01 18 01 05 30 2e 31 2e 30 08 53 49 4d 2d 30 30 30 31 01 d2 09 31 db c3 7d 00",
    "version-mismatch": "01 01 02 01 07 01 02 ab 96 6b fe 00",
    "record": "02 01 04 05 01 02 01 1c 80 e4 97 d0 12 01 a0 f1 9d d0 12 01 a0 e2 a2 d0 12 "
    "01 d2 e2 a2 d0 12 01 e0 c6 5b 05 72 55 ff 15 00",
    "flash-ready": "11 01 01 87 80 80 80 10 01 01 e0 c6 5b 85 4c ae d6 00",
    "load-plan": "06 02 02 01 01 6d 1e 1e 80 89 7a e0 a7 12 a0 8d 06 a0 c2 1e c0 96 b1 02 a0 9c 01 "
    "01 02 01 e8 07 7f 9b dc ff 00",
}


def main() -> None:
    out = pathlib.Path(__file__).resolve().parent / "corpus" / "decoder"
    out.mkdir(parents=True, exist_ok=True)
    for name, text in GOLDEN.items():
        frame = bytes.fromhex(text)
        # First byte: the target's split size (63 -> chunks of 64, whole frames).
        (out / f"golden-{name}.bin").write_bytes(bytes([63]) + frame)
    # All frames back to back, fed byte by byte (split byte 0 -> chunks of 1).
    (out / "golden-all-bytewise.bin").write_bytes(
        bytes([0]) + b"".join(bytes.fromhex(t) for t in GOLDEN.values())
    )
    print(f"wrote {len(GOLDEN) + 1} files to {out}")


if __name__ == "__main__":
    main()
