#!/usr/bin/env python3
"""Peer benchmark: trace the same 1.5 Mpx primary rays as `cargo bench -p skinbrdf-mesh --bench
rays` on the same ~200k-triangle mesh with Embree (PyPI `embreex`).

    pip install embreex numpy
    cargo bench -p skinbrdf-mesh --bench rays          # writes target/skinbrdf-bench/head200k.ply
    python3 scripts/peers/embree_bench.py target/skinbrdf-bench/head200k.ply [--json]

Prints the build time, the closest-hit time (primitive ids only, and with t/u/v output) and the
hit count, which must equal the Rust bench's (same rays, same mesh).
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


def main():
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
