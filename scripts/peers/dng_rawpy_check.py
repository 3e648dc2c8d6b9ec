#!/usr/bin/env python3
"""Reads the DNGs our writer made with LibRaw (rawpy) and checks them bit for bit.

    cargo run --release -p skinbrdf-raw --example write_test_dngs -- DIR [--big]
    python3 scripts/peers/dng_rawpy_check.py DIR [--time FILE.dng ...]

For every file in DIR/manifest.json: the raw photosites (`raw_image`, full sensor) equal
NAME.u16; the visible area is the manifest's active area (`sizes.top_margin`,
`sizes.left_margin`, `raw_image_visible.shape`; LibRaw rounds an odd origin up to even, which
is accepted); the CFA pattern (`raw_pattern` with `color_desc`) at LibRaw's origin is ours
shifted there; `black_level_per_channel` mapped through `raw_pattern` gives our black level per
CFA position; `white_level` is ours. Any mismatch is printed and the exit status is 1. One
difference is reported as a known deviation, not a failure: with an odd ActiveArea origin,
LibRaw anchors a 2x2 BlackLevel pattern at its even-rounded origin, where the DNG
specification (and rawler) anchor it at the ActiveArea origin.

With --time, times LibRaw's unpack of each file (open + unpack, the raw values in memory;
best and median of 5) and prints one JSON line per file.
"""
import json
import sys
import time
from pathlib import Path

import numpy as np
import rawpy


deviations: list[str] = []


def check(dir_: Path, case: dict) -> list[str]:
    name = case["name"]
    problems = []

    def bad(what):
        problems.append(f"{name}.dng: {what}")

    expected = np.fromfile(dir_ / f"{name}.u16", dtype="<u2").reshape(case["height"], case["width"])
    with rawpy.imread(str(dir_ / f"{name}.dng")) as raw:
        img = raw.raw_image.copy()
        if img.shape != expected.shape:
            bad(f"raw_image shape {img.shape}, expected {expected.shape}")
        elif not np.array_equal(img, expected):
            n = int(np.count_nonzero(img != expected))
            bad(f"raw_image differs in {n} photosites")
        top, left, bottom, right = case["active_area"]
        s = raw.sizes
        tm, lm = s.top_margin, s.left_margin
        vis = raw.raw_image_visible.shape
        # LibRaw rounds an odd ActiveArea origin up to even (its CFA description is aligned
        # to 2x2): accept that, and compare the pattern at its origin with ours shifted there.
        if (tm, lm) != (top, left) and (tm - top not in (0, 1) or lm - left not in (0, 1)):
            bad(f"margins (top {tm}, left {lm}), expected ({top}, {left})")
        if vis[0] > bottom - top or vis[1] > right - left or vis[0] < bottom - top - 1 or vis[1] < right - left - 1:
            bad(f"visible area {vis}, expected {(bottom - top, right - left)}")
        dy, dx = (tm - top) % 2, (lm - left) % 2
        ours = case["pattern"]
        ours_at = "".join(ours[((y + dy) % 2) * 2 + (x + dx) % 2] for y in range(2) for x in range(2))
        desc = raw.color_desc.decode()
        pat = raw.raw_pattern
        got = "".join(desc[pat[y][x]] for y in range(2) for x in range(2)).replace("G", "G")
        if got.replace("G", "g") != ours_at.replace("G", "g"):
            bad(f"CFA pattern at LibRaw's origin {got} (color_desc {desc}), expected {ours_at}")
        blc = raw.black_level_per_channel
        got_bl = [int(blc[pat[y][x]]) for y in range(2) for x in range(2)]
        bl = case["black_levels"]
        want = [bl[((y + dy) % 2) * 2 + (x + dx) % 2] for y in range(2) for x in range(2)]
        if got_bl != want:
            if (dy, dx) != (0, 0) and got_bl == bl:
                deviations.append(
                    f"{name}.dng: LibRaw anchors the 2x2 BlackLevel pattern at its even-rounded "
                    f"origin ({tm}, {lm}), not at the DNG ActiveArea origin ({top}, {left}): "
                    f"black by CFA position at its origin {got_bl}, DNG rule {want}")
            else:
                bad(f"black levels by CFA position {got_bl} (per channel {list(blc)}), expected {want}")
        if int(raw.white_level) != case["white_level"]:
            bad(f"white level {raw.white_level}, expected {case['white_level']}")
    return problems


def timing(path: str, runs: int = 5) -> dict:
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        with rawpy.imread(path) as raw:
            _ = raw.raw_image.sum()  # touch the data so it is really unpacked
        times.append(time.perf_counter() - t)
    times.sort()
    return {"file": path, "best_s": round(times[0], 4), "median_s": round(times[len(times) // 2], 4), "runs": runs}


def main() -> int:
    args = sys.argv[1:]
    if not args:
        print(__doc__, file=sys.stderr)
        return 2
    if "--time" in args:
        i = args.index("--time")
        for f in args[i + 1:]:
            print(json.dumps(timing(f)))
        args = args[:i]
        if not args:
            return 0
    dir_ = Path(args[0])
    cases = json.loads((dir_ / "manifest.json").read_text())
    problems = []
    for case in cases:
        p = check(dir_, case)
        problems += p
        print(f"{case['name']}.dng: {'ok' if not p else 'MISMATCH'}")
    print(f"{len(cases) - len({p.split(':')[0] for p in problems})} passed, "
          f"{len({p.split(':')[0] for p in problems})} failed")
    for p in problems:
        print(p, file=sys.stderr)
    for d in deviations:
        print(f"known deviation (not a failure): {d}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
