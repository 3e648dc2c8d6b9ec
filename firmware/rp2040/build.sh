#!/usr/bin/env bash
# Builds the RP2040 firmware image: release ELF, UF2, flash/RAM report.
# Fails (non-zero exit) if the image does not compile or link, or the UF2 cannot be made.
#
#   bash firmware/rp2040/build.sh          # from anywhere
#
# Outputs: $TARGET_DIR/thumbv6m-none-eabi/release/skinbrdf-rp2040      (ELF, for probe-rs)
#          $TARGET_DIR/thumbv6m-none-eabi/release/skinbrdf-rp2040.uf2  (BOOTSEL drag-and-drop)
# where TARGET_DIR is $CARGO_TARGET_DIR or firmware/rp2040/target.
set -euo pipefail
cd "$(dirname "$0")"

rustup target add thumbv6m-none-eabi

# The UF2 converter and size report are a standard-library Python script (tools/elf2uf2.py).
if ! command -v python3 >/dev/null 2>&1; then
  echo "python3 not found: installing it from Debian"
  apt-get update -qq && apt-get install -y -qq python3
fi

# Not --locked: Cargo.lock pins every version, but a new dependency of the path crates
# (../sequencer, ../../protocol, owned by others) must not break this build; cargo then only
# adds the missing entries.
cargo build --release

TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
ELF="$TARGET_DIR/thumbv6m-none-eabi/release/skinbrdf-rp2040"
UF2="$ELF.uf2"
echo "elf:   $ELF"
python3 tools/elf2uf2.py "$ELF" "$UF2"
