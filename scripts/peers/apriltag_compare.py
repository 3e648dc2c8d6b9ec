#!/usr/bin/env python3
"""Peer comparison: skinbrdf-targets vs the AprilTag reference C library (pupil-apriltags).

Renders synthetic images with tag36h11 tags at known poses (anti-aliased, blurred, noisy,
uneven lighting), runs both detectors and reports RMS / median / max corner error against the
truth, detection rate and time. Corner convention: the project's (integer = pixel centre); the
C library's corners are converted by subtracting 0.5 px.

    pip install pupil-apriltags numpy opencv-python-headless
    cargo build --release -p skinbrdf-targets --example detect_json
    python3 scripts/peers/apriltag_compare.py [--images 20] [--seed 1]

Scene options (docs/benchmarks-poses.md, "Which estimator is right"): --sides A B (black-square
side range, px), --bg L (level beyond the tag's white ring), --white L (level of the white
cells), --jpeg Q (JPEG quality); --binary-boundary runs ours with CornerModel::BinaryBoundary,
--profile with the small-tag edge-profile fit (DetectorConfig::profile_small_tags).
Rows: the C library with and without refine_edges, and ours; the mean outward column is the
mean radial offset of the corners from the truth (+ = too far out).

Also checks the real photos of shared/data/apriltag against their reference .txt files
(skip with --no-real).
"""
import argparse, json, os, subprocess, sys, tempfile, time
import numpy as np
import cv2
import pupil_apriltags

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TAGRS = os.path.join(ROOT, "host", "targets", "src", "tag36h11.rs")
BX = [1,2,3,4,5,2,3,4,3,6,6,6,6,6,5,5,5,4,6,5,4,3,2,5,4,3,4,1,1,1,1,1,2,2,2,3]
BY = [1,1,1,1,1,2,2,2,3,1,2,3,4,5,2,3,4,3,6,6,6,6,6,5,5,5,4,6,5,4,3,2,5,4,3,4]


def codes():
    import re
    src = open(TAGRS).read()
    body = src[src.index("pub const CODES"):]
    body = body[: body.index("];")]
    return [int(c, 16) for c in re.findall(r"0x([0-9a-f]+)", body)]


def bits(code):
    g = np.zeros((10, 10), bool)
    g[0, :] = g[9, :] = g[:, 0] = g[:, 9] = True
    for i in range(36):
        if (code >> (35 - i)) & 1:
            g[BY[i] + 1, BX[i] + 1] = True
    return g


def homography(c, s, ang, g, h):
    cs, sn = np.cos(ang), np.sin(ang)
    return np.array([[s * cs + c[0] * g, -s * sn + c[0] * h, c[0]],
                     [s * sn + c[1] * g, s * cs + c[1] * h, c[1]],
                     [g, h, 1.0]])


def paint(img, H, grid, ss=4, white=1.0):
    """Anti-aliased tag through H (tag frame -> pixels, pixel-centre convention)."""
    Hi = np.linalg.inv(H)
    pts = np.array([[-1.25, -1.25, 1], [1.25, -1.25, 1], [1.25, 1.25, 1], [-1.25, 1.25, 1]]).T
    p = H @ pts
    p = p[:2] / p[2]
    x0, y0 = np.floor(p.min(1)).astype(int) - 1
    x1, y1 = np.ceil(p.max(1)).astype(int) + 1
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, img.shape[1] - 1), min(y1, img.shape[0] - 1)
    xs = np.arange(x0, x1 + 1)
    ys = np.arange(y0, y1 + 1)
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    X = (xs[None, :, None, None] + sub[None, None, None, :]) + 0 * sub[None, None, :, None]
    Y = (ys[:, None, None, None] + sub[None, None, :, None]) + 0 * sub[None, None, None, :]
    X = np.broadcast_to(X, (len(ys), len(xs), ss, ss))
    Y = np.broadcast_to(Y, (len(ys), len(xs), ss, ss))
    u = Hi[0, 0] * X + Hi[0, 1] * Y + Hi[0, 2]
    v = Hi[1, 0] * X + Hi[1, 1] * Y + Hi[1, 2]
    w = Hi[2, 0] * X + Hi[2, 1] * Y + Hi[2, 2]
    u, v = u / w, v / w
    col = np.floor((u + 1) / 0.25 + 1).astype(int)
    row = np.floor((v + 1) / 0.25 + 1).astype(int)
    inside = (col >= 0) & (col < 10) & (row >= 0) & (row < 10)
    val = np.where(grid[np.clip(row, 0, 9), np.clip(col, 0, 9)], white, 0.0)
    region = img[y0:y1 + 1, x0:x1 + 1]
    frac = inside.mean(axis=(2, 3))
    tagval = np.where(inside, val, 0).sum(axis=(2, 3)) / (ss * ss)
    img[y0:y1 + 1, x0:x1 + 1] = region * (1 - frac) + tagval


def make_image(rng, cds, w=1200, h=900, blur=0.8, noise=0.01, sides=(24, 140), bg=0.55, white=1.0):
    img = np.full((h, w), bg)
    truth = []
    placed = []
    for _ in range(60):
        s = rng.uniform(sides[0] / 2, sides[1] / 2)  # half side of the black square, px
        c = rng.uniform([s * 1.6 + 5, s * 1.6 + 5], [w - s * 1.6 - 5, h - s * 1.6 - 5])
        if any(np.hypot(*(c - q)) < 1.7 * (s + r) for q, r in placed):
            continue
        placed.append((c, s))
        tid = int(rng.integers(0, 587))
        H = homography(c, s, rng.uniform(0, 2 * np.pi), rng.uniform(-0.6, 0.6) / (w), rng.uniform(-0.6, 0.6) / w)
        paint(img, H, bits(cds[tid]), white=white)
        cs = np.array([[-1, 1, 1], [1, 1, 1], [1, -1, 1], [-1, -1, 1]]).T
        p = H @ cs
        truth.append((tid, (p[:2] / p[2]).T))
        if len(truth) >= 14:
            break
    img = 0.08 + 0.84 * img
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    yy, xx = np.mgrid[0:h, 0:w]
    light = 0.45 + 0.55 * np.exp(-(((xx - 0.3 * w) ** 2 + (yy - 0.4 * h) ** 2) / (0.8 * w) ** 2))
    img = img * light + rng.normal(0, noise, img.shape)
    return np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8), truth


OURS_ARGS = []


def run_ours(files):
    exe = os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release", "examples", "detect_json")
    out = subprocess.run([exe] + OURS_ARGS + files, capture_output=True, text=True, check=True).stdout
    return [json.loads(l) for l in out.splitlines()]


def errors(dets, truth, radial=None):
    errs, found = [], 0
    for tid, corners in truth:
        c = corners.mean(0)
        best = None
        for d in dets:
            dc = np.array(d[1])
            if d[0] == tid and np.hypot(*(dc.mean(0) - c)) < 5:
                best = dc
        if best is not None:
            found += 1
            errs.extend(np.hypot(*(best - corners).T))
            if radial is not None:
                u = (corners - c) / np.linalg.norm(corners - c, axis=1)[:, None]
                radial.extend(((best - corners) * u).sum(1))
    return errs, found


def stats(e):
    e = np.array(e)
    return dict(rms=float(np.sqrt((e ** 2).mean())), median=float(np.median(e)), max=float(e.max()))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--images", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sides", type=float, nargs=2, default=(24, 140), help="black-square side range, px")
    ap.add_argument("--bg", type=float, default=0.55, help="background level outside the white ring (0..1)")
    ap.add_argument("--white", type=float, default=1.0, help="level of the tag's white cells (0..1)")
    ap.add_argument("--jpeg", type=int, default=0, help="save as JPEG of this quality (0: PNG)")
    ap.add_argument("--no-real", action="store_true", help="skip the real photos")
    ap.add_argument("--profile", action="store_true", help="ours with the small-tag profile fit")
    ap.add_argument("--binary-boundary", action="store_true",
                    help="ours with CornerModel::BinaryBoundary (the reference's unrefined quad fit)")
    args = ap.parse_args()
    if args.binary_boundary:
        OURS_ARGS.append("--binary-boundary")
    if args.profile:
        OURS_ARGS.append("--profile")
    rng = np.random.default_rng(args.seed)
    cds = codes()
    det = pupil_apriltags.Detector(families="tag36h11", quad_decimate=1.0, refine_edges=1, decode_sharpening=0.25)
    det0 = pupil_apriltags.Detector(families="tag36h11", quad_decimate=1.0, refine_edges=0, decode_sharpening=0.25)
    tmp = tempfile.mkdtemp()
    cases = []
    for k in range(args.images):
        cfg = [(0.6, 0.005), (1.0, 0.01), (1.5, 0.02)][k % 3]
        img, truth = make_image(rng, cds, blur=cfg[0], noise=cfg[1], sides=args.sides, bg=args.bg, white=args.white)
        if args.jpeg:
            f = os.path.join(tmp, f"img{k:03}.jpg")
            cv2.imwrite(f, img, [cv2.IMWRITE_JPEG_QUALITY, args.jpeg])
            img = cv2.imread(f, cv2.IMREAD_GRAYSCALE)
        else:
            f = os.path.join(tmp, f"img{k:03}.png")
            cv2.imwrite(f, img)
        cases.append((f, img, truth, cfg))
    ours = run_ours([c[0] for c in cases])
    res = {}
    for (f, img, truth, cfg), o in zip(cases, ours):
        t0 = time.perf_counter()
        c_dets = det.detect(img)
        c_ms = (time.perf_counter() - t0) * 1e3
        c = [(d.tag_id, (np.array(d.corners) - 0.5).tolist()) for d in c_dets]
        t0 = time.perf_counter()
        c0_dets = det0.detect(img)
        c0_ms = (time.perf_counter() - t0) * 1e3
        c0 = [(d.tag_id, (np.array(d.corners) - 0.5).tolist()) for d in c0_dets]
        m = [(d["id"], d["corners"]) for d in o["detections"]]
        for name, dets, ms in [("apriltag-C", c, c_ms), ("apriltag-C unrefined", c0, c0_ms), ("skinbrdf-targets", m, o["ms"])]:
            r = res.setdefault((name, cfg), dict(err=[], found=0, total=0, ms=[], extra=0, rad=[]))
            e, found = errors(dets, truth, r["rad"])
            r["err"] += e
            r["found"] += found
            r["total"] += len(truth)
            r["ms"].append(ms)
            r["extra"] += len(dets) - found
    print("| detector | blur sigma px | noise | tags found | false pos. | RMS px | median px | max px | mean outward px | ms/image (1200x900) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for (name, cfg), r in sorted(res.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        s = stats(r["err"])
        print(f"| {name} | {cfg[0]} | {cfg[1]} | {r['found']}/{r['total']} | {r['extra']} | {s['rms']:.3f} | {s['median']:.3f} | {s['max']:.3f} | {np.mean(r['rad']):+.3f} | {np.median(r['ms']):.1f} |")
    if args.no_real:
        return 0
    # Real photos: ours vs the reference .txt.
    d = os.path.join(ROOT, "..", "shared", "data", "apriltag")
    if not os.path.isdir(d):
        d = "/work/shared/data/apriltag"
    for stem in sorted(f[:-4] for f in os.listdir(d) if f.endswith(".jpg")):
        ref = []
        for line in open(os.path.join(d, stem + ".txt")):
            n = [float(t) for t in line.replace("(", " ").replace(")", " ").replace(",", " ").split()]
            ref.append((int(n[0]), np.array(n[1:]).reshape(4, 2) - 0.5))
        o = run_ours([os.path.join(d, stem + ".jpg")])[0]
        m = [(x["id"], x["corners"]) for x in o["detections"]]
        e, found = errors(m, ref)
        s = stats(e)
        print(f"real {stem}: found {found}/{len(ref)}, extra {len(m) - found}, vs reference: median {s['median']:.3f} px, max {s['max']:.3f} px, {o['ms']:.1f} ms")


if __name__ == "__main__":
    sys.exit(main())
