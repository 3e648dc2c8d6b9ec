#!/usr/bin/env python3
"""Peer benchmark: trace the same 1.5 Mpx primary rays as `cargo bench -p skinbrdf-mesh --bench
rays` on the same ~200k-triangle mesh with Embree (PyPI `embreex`).

    pip install embreex numpy
    cargo bench -p skinbrdf-mesh --bench rays          # writes target/skinbrdf-bench/head200k.ply
    python3 scripts/peers/embree_bench.py target/skinbrdf-bench/head200k.ply [--json]

Prints the build time, the closest-hit time (primitive ids only, and with t/u/v output) and the
hit count, which must equal the Rust bench's (same rays, same mesh).

One command for both, back to back, with the ratio (the machine is shared: compare ratios):

    python3 scripts/peers/embree_bench.py --compare [--reps N]

builds and runs `cargo run --release -p skinbrdf-mesh --example ray_throughput` (which writes
the mesh), then Embree on the same mesh and rays, then prints both and our/Embree speed ratios.
embreex's `scene.run` traces on one thread.
"""
import json
import sys
import time

import numpy as np


def read_ply(path):
    """Reads the binary little-endian PLY that skinbrdf_mesh::write_ply_binary writes."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    nv = nf = 0
    has_normals = False
    for line in header:
        w = line.split()
        if w[:2] == ["element", "vertex"]:
            nv = int(w[2])
        elif w[:2] == ["element", "face"]:
            nf = int(w[2])
        elif w[:3] == ["property", "float", "nx"]:
            has_normals = True
    if "format binary_little_endian 1.0" not in header:
        raise SystemExit(f"{path}: expected binary_little_endian PLY")
    stride = 6 if has_normals else 3
    verts = np.frombuffer(data, dtype="<f4", count=nv * stride, offset=end).reshape(nv, stride)[:, :3]
    off = end + nv * stride * 4
    faces = np.frombuffer(data, dtype=np.dtype([("n", "u1"), ("i", "<i4", 3)]), count=nf, offset=off)
    if not np.all(faces["n"] == 3):
        raise SystemExit(f"{path}: only triangles expected")
    return np.ascontiguousarray(verts, dtype=np.float32), np.ascontiguousarray(faces["i"], dtype=np.int32)


def primary_rays():
    """1500 x 1000 pinhole rays, 30 deg horizontal FOV, from (0, 0, 0.45) looking down -z."""
    w, h = 1500, 1000
    f = 0.5 * w / np.tan(np.radians(15.0))
    cx, cy = (w - 1) * 0.5, (h - 1) * 0.5
    x, y = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d = np.stack([(x - cx) / f, -(y - cy) / f, -np.ones_like(x)], axis=-1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.tile(np.array([0.0, 0.0, 0.45]), (d.shape[0], 1))
    return np.ascontiguousarray(o, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32)


def best_of(fn, n=5):
    times = []
    out = None
    for _ in range(n):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), float(np.median(times)), out


def compare():
    import os
    import subprocess
    import tempfile

    reps = "5"
    if "--reps" in sys.argv:
        reps = sys.argv[sys.argv.index("--reps") + 1]
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ply = os.path.join(tempfile.gettempdir(), "skinbrdf_head200k.ply")
    load = os.getloadavg()
    cmd = ["cargo", "run", "--quiet", "--release", "-p", "skinbrdf-mesh", "--example",
           "ray_throughput", "--", "--ply", ply, "--reps", reps, "--json", "--quality", "medium"]
    ours = json.loads(subprocess.run(cmd, cwd=root, check=True, capture_output=True, text=True).stdout)
    emb = run_embree(ply, int(reps))
    n = ours["rays"]
    rows = [
        ("skinbrdf grid (coherent), %d threads" % ours["threads"], ours["grid_s"]),
        ("skinbrdf grid (coherent), 1 thread", ours["grid_1_thread_s"]),
        ("skinbrdf per ray, %d threads" % ours["threads"], ours["per_ray_s"]),
        ("skinbrdf per ray, 1 thread", ours["per_ray_1_thread_s"]),
        ("Embree (embreex scene.run, 1 thread)", emb["closest_hit_ids_best_s"]),
        ("Embree with t/u/v output", emb["closest_hit_full_best_s"]),
    ]
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; after: "
          + " ".join(f"{x:.2f}" for x in os.getloadavg()))
    print(f"{ours['triangles']} triangles, {n} rays; hits: ours {ours['hits']} (per ray "
          f"{ours['per_ray_hits']}), Embree {emb['hits']}")
    print(f"build: ours (medium) {ours['build_s'].get('medium', float('nan')):.3f} s, Embree "
          f"{emb['build_s']:.3f} s")
    e = emb["closest_hit_ids_best_s"]
    print(f"{'tracer':44} {'best s':>8} {'Mrays/s':>8} {'vs Embree':>9}")
    for name, t in rows:
        print(f"{name:44} {t:8.4f} {n / t / 1e6:8.2f} {e / t:8.2f}x")
    if "--json" in sys.argv:
        print(json.dumps({"ours": ours, "embree": emb, "load_before": load}))


def run_embree(path, reps=5):
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    verts, faces = read_ply(path)
    origins, dirs = primary_rays()
    t = time.perf_counter()
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, verts, faces)
    scene.run(origins[:1], dirs[:1])
    build_s = time.perf_counter() - t
    ids_best, ids_med, ids = best_of(lambda: scene.run(origins, dirs), reps)
    full_best, _, _ = best_of(lambda: scene.run(origins, dirs, output=1), reps)
    return {
        "triangles": int(faces.shape[0]),
        "rays": int(origins.shape[0]),
        "hits": int(np.count_nonzero(np.asarray(ids) >= 0)),
        "build_s": build_s,
        "closest_hit_ids_best_s": ids_best,
        "closest_hit_ids_median_s": ids_med,
        "closest_hit_full_best_s": full_best,
    }


def main():
    if "--compare" in sys.argv:
        return compare()
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if not args:
        raise SystemExit(__doc__)
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    verts, faces = read_ply(args[0])
    origins, dirs = primary_rays()
    t = time.perf_counter()
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, verts, faces)
    # The first query commits (builds) the scene; time it separately on one ray.
    scene.run(origins[:1], dirs[:1])
    build_s = time.perf_counter() - t
    ids_best, ids_med, ids = best_of(lambda: scene.run(origins, dirs))
    full_best, full_med, _ = best_of(lambda: scene.run(origins, dirs, output=1))
    hits = int(np.count_nonzero(np.asarray(ids) >= 0))
    n = origins.shape[0]
    result = {
        "triangles": int(faces.shape[0]),
        "rays": int(n),
        "hits": hits,
        "build_s": build_s,
        "closest_hit_ids_best_s": ids_best,
        "closest_hit_ids_median_s": ids_med,
        "closest_hit_ids_mrays_per_s": n / ids_best / 1e6,
        "closest_hit_full_best_s": full_best,
        "closest_hit_full_mrays_per_s": n / full_best / 1e6,
    }
    if "--json" in sys.argv:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:32} {v:.4f}" if isinstance(v, float) else f"{k:32} {v}")


if __name__ == "__main__":
    main()
