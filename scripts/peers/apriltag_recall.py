#!/usr/bin/env python3
"""Detection recall of skinbrdf-targets against the AprilTag reference C library (pupil-apriltags)
on hard synthetic images with truth: small tags (black-square sides 6..48 px), strong
foreshortening (tilts up to 78 deg), soft-edged shadows across tags, and tightly packed grids
(white rings touching), plus the real photos of shared/data/apriltag (the C library run here on
the same pixels, not the shipped .txt).

    pip install pupil-apriltags numpy opencv-python-headless
    cargo build --release -p skinbrdf-targets --example detect_json
    python3 scripts/peers/apriltag_recall.py [--images 24] [--seed 3] [--misses] [--exe BIN]

Per tag-size bin (mean side of the black square in the image, px): tags in truth, found by ours,
found by the C library, and the tags the C library finds that ours misses (listed with
--misses). False positives: detections matching no true tag (id and centre within a quarter
side). Times: ms per image, ours from the example's own clock, the C library's through its
Python binding (1 thread, quad_decimate = 1, refine_edges = 1, decode_sharpening = 0.25).
Corner convention: the project's (integer = pixel centre); C library corners - 0.5 px.
"""
import argparse, json, os, subprocess, sys, tempfile, time
import numpy as np
import cv2
import pupil_apriltags

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from apriltag_compare import ROOT, codes, bits, paint  # noqa: E402

BINS = [(0, 10), (10, 13), (13, 18), (18, 25), (25, 40), (40, 1e9)]


def bin_name(lo, hi):
    return f"<{hi:g}" if lo == 0 else (f">{lo:g}" if hi > 1e8 else f"{lo:g}-{hi:g}")


def rot(axis, ang):
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(ang) * k + (1 - np.cos(ang)) * k @ k


def plane_h(c, half_px, tilt, tilt_dir, spin, f=1500.0, w=1200, h=900):
    """Homography tag frame -> pixels for a square of half-side `half_px` (as seen face-on at the
    same distance) centred at pixel c, tilted by `tilt` about an in-plane axis at `tilt_dir`."""
    z = 1.0
    L = half_px * z / f
    R = rot(np.array([np.cos(tilt_dir), np.sin(tilt_dir), 0.0]), tilt) @ rot(np.array([0, 0, 1.0]), spin)
    t = np.array([(c[0] - w / 2) * z / f, (c[1] - h / 2) * z / f, z])
    K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]])
    return K @ np.column_stack([L * R[:, 0], L * R[:, 1], t])


def corners_of(H):
    cs = np.array([[-1, 1, 1], [1, 1, 1], [1, -1, 1], [-1, -1, 1]]).T
    p = H @ cs
    return (p[:2] / p[2]).T


def ring_of(H):
    cs = np.array([[-1.25, 1.25, 1], [1.25, 1.25, 1], [1.25, -1.25, 1], [-1.25, -1.25, 1]]).T
    p = H @ cs
    return (p[:2] / p[2]).T


def side_of(c):
    return float(np.mean([np.linalg.norm(c[k] - c[(k + 1) % 4]) for k in range(4)]))


def make_image(rng, cds, kind, w=1200, h=900):
    bg = rng.uniform(0.3, 0.8)
    img = np.full((h, w), bg)
    truth = []
    mask = np.zeros((h, w), bool)

    def free(H):
        r = ring_of(H)
        x0, y0 = np.floor(r.min(0)).astype(int) - 2
        x1, y1 = np.ceil(r.max(0)).astype(int) + 2
        if x0 < 2 or y0 < 2 or x1 >= w - 2 or y1 >= h - 2:
            return False
        if mask[y0:y1, x0:x1].any():
            return False
        mask[y0:y1, x0:x1] = True
        return True

    if kind == "packed":
        # Grids of tags whose white rings touch (pitch 2.5 tag units), each grid one tilted plane.
        for _ in range(3):
            half = np.exp(rng.uniform(np.log(4), np.log(14)))
            n, m = int(rng.integers(3, 6)), int(rng.integers(2, 5))
            tilt, tdir, spin = rng.uniform(0, np.radians(70)), rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi)
            c0 = rng.uniform([150, 150], [w - 150, h - 150])
            G = plane_h(c0, half, tilt, tdir, spin)
            hs = []
            for i in range(n):
                for j in range(m):
                    T = np.array([[1, 0, 2.5 * (i - (n - 1) / 2)], [0, 1, 2.5 * (j - (m - 1) / 2)], [0, 0, 1.0]])
                    hs.append(G @ T)
            rr = np.concatenate([ring_of(H) for H in hs])
            x0, y0 = np.floor(rr.min(0)).astype(int) - 2
            x1, y1 = np.ceil(rr.max(0)).astype(int) + 2
            if x0 < 2 or y0 < 2 or x1 >= w - 2 or y1 >= h - 2 or mask[y0:y1, x0:x1].any():
                continue
            mask[y0:y1, x0:x1] = True
            for H in hs:
                tid = int(rng.integers(0, 587))
                paint(img, H, bits(cds[tid]))
                truth.append((tid, corners_of(H)))
    else:
        for _ in range(400):
            half = np.exp(rng.uniform(np.log(3.0), np.log(24.0)))
            tilt = rng.uniform(0, np.radians(78))
            H = plane_h(rng.uniform([40, 40], [w - 40, h - 40]), half, tilt, rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi))
            if not free(H):
                continue
            tid = int(rng.integers(0, 587))
            paint(img, H, bits(cds[tid]))
            truth.append((tid, corners_of(H)))
            if len(truth) >= 40:
                break
    img = 0.06 + 0.86 * img
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(0.5, 1.0))
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    light = 0.55 + 0.45 * np.exp(-(((xx - rng.uniform(0, w)) ** 2 + (yy - rng.uniform(0, h)) ** 2) / (0.9 * w) ** 2))
    if kind == "shadow":
        # Soft-edged shadows (cast by the head or the band): half-planes and discs at 30..45 %.
        for _ in range(6):
            a = rng.uniform(0, 2 * np.pi)
            d = (xx - rng.uniform(0, w)) * np.cos(a) + (yy - rng.uniform(0, h)) * np.sin(a)
            if rng.random() < 0.5:
                d = np.hypot(xx - rng.uniform(0, w), yy - rng.uniform(0, h)) - rng.uniform(40, 160)
            depth = rng.uniform(0.55, 0.7)
            light = light * (1 - depth / (1 + np.exp(np.clip(d / rng.uniform(1.0, 4.0), -50, 50))))
    img = img * light + rng.normal(0, rng.uniform(0.004, 0.012), img.shape)
    return np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8), truth


def exe_path():
    return os.path.join(os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release", "examples", "detect_json")


def run_ours(files, exe):
    out = subprocess.run([exe] + files, capture_output=True, text=True, check=True).stdout
    return [json.loads(l) for l in out.splitlines()]


def matches(dets, tid, c, side):
    return [k for k, (i, dc) in enumerate(dets) if i == tid and np.linalg.norm(np.mean(dc, 0) - c) < 0.25 * side]


class Tally:
    def __init__(self):
        self.n = {b: 0 for b in BINS}
        self.ours = {b: 0 for b in BINS}
        self.clib = {b: 0 for b in BINS}
        self.c_not_ours = []
        self.fp_ours = 0
        self.fp_c = 0
        self.ms_ours = []
        self.ms_c = []
        self.images = 0

    def add(self, name, truth, ours, clib, ms_o, ms_c):
        self.images += 1
        self.ms_ours.append(ms_o)
        self.ms_c.append(ms_c)
        used_o, used_c = set(), set()
        for tid, corners in truth:
            side = side_of(corners)
            b = next(b for b in BINS if b[0] <= side < b[1])
            c = corners.mean(0)
            mo, mc = matches(ours, tid, c, side), matches(clib, tid, c, side)
            used_o.update(mo)
            used_c.update(mc)
            self.n[b] += 1
            self.ours[b] += bool(mo)
            self.clib[b] += bool(mc)
            if mc and not mo:
                sides = [np.linalg.norm(corners[k] - corners[(k + 1) % 4]) for k in range(4)]
                self.c_not_ours.append((name, tid, c.round(1).tolist(), round(side, 1), round(min(sides), 1)))
        self.fp_ours += len(ours) - len(used_o)
        self.fp_c += len(clib) - len(used_c)

    def table(self, title):
        print(f"\n{title}: {self.images} images")
        print("| black-square side px | tags | ours found | C library found | C finds, ours misses |")
        print("|---|---:|---:|---:|---:|")
        miss = {b: 0 for b in BINS}
        for m in self.c_not_ours:
            miss[next(b for b in BINS if b[0] <= m[3] < b[1])] += 1
        for b in BINS:
            if self.n[b]:
                print(f"| {bin_name(*b)} | {self.n[b]} | {self.ours[b]} ({100 * self.ours[b] / self.n[b]:.0f} %) | "
                      f"{self.clib[b]} ({100 * self.clib[b] / self.n[b]:.0f} %) | {miss[b]} |")
        tn, to, tc = sum(self.n.values()), sum(self.ours.values()), sum(self.clib.values())
        print(f"| all | {tn} | {to} ({100 * to / max(tn, 1):.1f} %) | {tc} ({100 * tc / max(tn, 1):.1f} %) | {len(self.c_not_ours)} |")
        print(f"false positives: ours {self.fp_ours}, C library {self.fp_c}; ms/image median: ours "
              f"{np.median(self.ms_ours):.0f}, C library {np.median(self.ms_c):.0f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--images", type=int, default=24, help="synthetic images per kind")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--kinds", nargs="+", default=["sparse", "shadow", "packed"])
    ap.add_argument("--misses", action="store_true", help="list the tags the C library finds and ours misses")
    ap.add_argument("--keep", help="write the synthetic images (PNG) and truth (JSON) here")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--exe", help="our detect_json binary (default: the release example)")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    cds = codes()
    det = pupil_apriltags.Detector(families="tag36h11", quad_decimate=1.0, refine_edges=1, decode_sharpening=0.25, nthreads=1)
    exe = args.exe or exe_path()
    tmp = args.keep or tempfile.mkdtemp()
    os.makedirs(tmp, exist_ok=True)
    for kind in args.kinds:
        t = Tally()
        cases = []
        for k in range(args.images):
            img, truth = make_image(rng, cds, kind)
            f = os.path.join(tmp, f"{kind}{k:03}.png")
            cv2.imwrite(f, img)
            if args.keep:
                json.dump([{"id": i, "corners": c.tolist()} for i, c in truth], open(f[:-4] + ".json", "w"))
            cases.append((f, img, truth))
        ours = run_ours([c[0] for c in cases], exe)
        for (f, img, truth), o in zip(cases, ours):
            t0 = time.perf_counter()
            cd = det.detect(img)
            ms_c = (time.perf_counter() - t0) * 1e3
            clib = [(d.tag_id, np.array(d.corners) - 0.5) for d in cd]
            mine = [(d["id"], np.array(d["corners"])) for d in o["detections"]]
            t.add(os.path.basename(f), truth, mine, clib, o["ms"], ms_c)
        t.table(f"synthetic, {kind}")
        if args.misses:
            for m in t.c_not_ours:
                print("  C finds, ours misses:", m)
    if args.no_real:
        return 0
    d = os.path.join(ROOT, "..", "shared", "data", "apriltag")
    if not os.path.isdir(d):
        d = "/work/shared/data/apriltag"
    t = Tally()
    stems = sorted(f[:-4] for f in os.listdir(d) if f.endswith(".jpg"))
    ours = run_ours([os.path.join(d, s + ".jpg") for s in stems], exe)
    for stem, o in zip(stems, ours):
        img = cv2.imread(os.path.join(d, stem + ".jpg"), cv2.IMREAD_GRAYSCALE)
        t0 = time.perf_counter()
        cd = det.detect(img)
        ms_c = (time.perf_counter() - t0) * 1e3
        clib = [(x.tag_id, np.array(x.corners) - 0.5) for x in cd]
        mine = [(x["id"], np.array(x["corners"])) for x in o["detections"]]
        # No truth on real photos: the union of both detectors' tags (checked by eye) is the set.
        truth = list(clib)
        for i, c in mine:
            if not matches(clib, i, c.mean(0), side_of(c)):
                truth.append((i, c))
        t.add(stem, truth, mine, clib, o["ms"], ms_c)
    t.table("real photos (truth: the union of both detectors' tags)")
    for m in t.c_not_ours:
        print("  C finds, ours misses:", m)
    return 0


if __name__ == "__main__":
    sys.exit(main())
