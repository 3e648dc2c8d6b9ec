#!/usr/bin/env python3
"""Per-corner breakdown of skinbrdf-targets against the AprilTag reference on the real photos of
shared/data/apriltag: each corner's distance from the shipped .txt (the C library's unrefined
quad, refine_edges=0) and from the C library with edge refinement
(host/targets/tests/data/apriltag_c_refined.json), by tag size, by corner, by side direction,
and the worst corners. Corners in the project's convention (C library corners - 0.5 px).

    cargo build --release -p skinbrdf-targets --example detect_json
    python3 scripts/peers/apriltag_real_photos.py [--binary-boundary | --profile] [--worst 15]

Needs numpy only (the refined reference comes from the fixture).
"""
import argparse, json, os, subprocess
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
D = os.path.join(ROOT, "..", "shared", "data", "apriltag")
if not os.path.isdir(D):
    D = "/work/shared/data/apriltag"
FIXTURE = os.path.join(ROOT, "host", "targets", "tests", "data", "apriltag_c_refined.json")


def parse_txt(path):
    out = []
    for line in open(path):
        if line.strip():
            n = [float(t) for t in line.replace("(", " ").replace(")", " ").replace(",", " ").split()]
            out.append((int(n[0]), np.array(n[1:]).reshape(4, 2) - 0.5))
    return out


def match(cands, c, side):
    m = [x for x in cands if np.linalg.norm(x.mean(0) - c) < 0.25 * side]
    return m[0] if m else None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--binary-boundary", action="store_true", help="ours with CornerModel::BinaryBoundary")
    ap.add_argument("--profile", action="store_true", help="ours with the small-tag profile fit")
    ap.add_argument("--worst", type=int, default=15)
    args = ap.parse_args()
    exe = os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release", "examples", "detect_json")
    stems = sorted(f[:-4] for f in os.listdir(D) if f.endswith(".jpg"))
    flags = (["--binary-boundary"] if args.binary_boundary else []) + (["--profile"] if args.profile else [])
    out = subprocess.run([exe] + flags + [os.path.join(D, s + ".jpg") for s in stems],
                         capture_output=True, text=True, check=True).stdout.splitlines()
    fixture = json.load(open(FIXTURE))
    rows, sides = [], {}
    for stem, line in zip(stems, out):
        ours = [np.array(d["corners"]) for d in json.loads(line)["detections"]]
        refc = [np.array(d["corners"]) for d in fixture.get(stem, [])]
        for tid, t in parse_txt(os.path.join(D, stem + ".txt")):
            c = t.mean(0)
            side = np.mean([np.linalg.norm(t[k] - t[(k + 1) % 4]) for k in range(4)])
            o, r = match(ours, c, side), match(refc, c, side)
            if o is None:
                print(f"MISSED {stem} tag {tid} at {c.round(1)}")
                continue
            for k in range(4):
                u = (t[k] - c) / np.linalg.norm(t[k] - c)
                e = o[k] - t[k]
                rows.append(dict(stem=stem[:5], side=side, k=k, c=c, e=e, n=np.linalg.norm(e), out=e @ u,
                                 vr=np.linalg.norm(o[k] - r[k]) if r is not None else np.nan,
                                 rt=np.linalg.norm(r[k] - t[k]) if r is not None else np.nan))
                a, b = t[k], t[(k + 1) % 4]
                mid = (a + b) / 2
                nrm = np.array([b[1] - a[1], a[0] - b[0]])
                nrm /= np.linalg.norm(nrm)
                if nrm @ (mid - c) < 0:
                    nrm = -nrm
                name = ["right", "down", "left", "up"][int(np.round(np.arctan2(nrm[1], nrm[0]) / (np.pi / 2))) % 4]
                sides.setdefault(name, []).append(((o[k] + o[(k + 1) % 4]) / 2 - mid) @ nrm)
    n = np.array([r["n"] for r in rows])
    vr = np.array([r["vr"] for r in rows])
    vr = vr[~np.isnan(vr)]
    print(f"vs .txt: {len(n)} corners, median {np.median(n):.3f} px, p90 {np.percentile(n, 90):.3f}, "
          f"max {n.max():.3f}, {np.sum(n >= 0.5)} at or over 0.5 px, mean outward {np.mean([r['out'] for r in rows]):+.3f}")
    print(f"vs C refined: {len(vr)} corners, median {np.median(vr):.3f} px, p90 {np.percentile(vr, 90):.3f}, max {vr.max():.3f}")
    print("by black-square side (px):")
    for lo, hi in [(0, 15), (15, 18), (18, 22), (22, 40)]:
        sel = [r for r in rows if lo <= r["side"] < hi]
        if sel:
            v = np.array([r["n"] for r in sel])
            print(f"  {lo:2d}..{hi:2d}: {len(sel):3d} corners, median {np.median(v):.3f}, max {v.max():.3f}, "
                  f"over 0.5: {np.sum(v >= 0.5)}, mean outward {np.mean([r['out'] for r in sel]):+.3f}")
    print("by corner (reference order):")
    for k in range(4):
        sel = [r for r in rows if r["k"] == k]
        v = np.array([r["n"] for r in sel])
        print(f"  corner {k}: median {np.median(v):.3f}, max {v.max():.3f}, mean offset (x, y) {np.mean([r['e'] for r in sel], 0).round(3)}")
    print("mean outward offset of each side vs .txt, by the side's outward direction in the image:")
    for name in ["up", "left", "down", "right"]:
        print(f"  {name:5s}: {np.mean(sides[name]):+.3f} px ({len(sides[name])} sides)")
    print(f"worst {args.worst} corners vs .txt:")
    for r in sorted(rows, key=lambda r: -r["n"])[: args.worst]:
        print(f"  {r['stem']} tag at {r['c'].round(0)} side {r['side']:4.1f} px corner {r['k']}: "
              f"{r['n']:.2f} px (dx {r['e'][0]:+.2f}, dy {r['e'][1]:+.2f}, outward {r['out']:+.2f}); "
              f"vs C refined {r['vr']:.2f}; C refined vs .txt {r['rt']:.2f}")


if __name__ == "__main__":
    main()
