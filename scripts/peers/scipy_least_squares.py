#!/usr/bin/env python3
"""SciPy peer for skinbrdf's Levenberg-Marquardt fit: the same 2-lobe Lafortune model, the same
parametrisation, residual (log space, same floor), start point and data (the red channel of the
1M-sample benchmark set written by `cargo run --release -p skinbrdf-fit --example peer_fit`).

    cargo run --release -p skinbrdf-fit --example peer_fit -- /tmp/bench_1m.skbs > /tmp/ours.json
    python3 scripts/peers/scipy_least_squares.py /tmp/bench_1m.skbs /tmp/ours.json

Runs `scipy.optimize.least_squares` with method='trf' (bounded, the only bounded choice) and
method='lm' (unbounded MINPACK), both with the analytic Jacobian, and prints time and final cost
next to skinbrdf's.
"""
import json
import struct
import sys
import time

import numpy as np
from scipy.optimize import least_squares

path, ours_path = sys.argv[1], sys.argv[2]
ours = json.load(open(ours_path))
with open(path, "rb") as f:
    head = f.read(28)
    assert head[:8] == b"SKBRDFS\0"
    version, rec, count, hlen = struct.unpack("<IIQI", head[8:28])
    f.read(hlen)
    dt = np.dtype([("ang", "<f4", 6), ("rho", "<f4", 3), ("w", "<f4"), ("img", "<u2"), ("px", "<u2", 2)])
    assert dt.itemsize == rec
    data = np.frombuffer(f.read(count * rec), dtype=dt)

ti, te, pd = (data["ang"][:, k].astype(np.float64) for k in range(3))
y = data["rho"][:, 0].astype(np.float64)
dxy = np.sin(ti) * np.sin(te) * np.cos(pd)
dz = np.cos(ti) * np.cos(te)
floor = ours["floor"]
target = np.log(np.maximum(y, 0) + floor)
LOG_NORM = np.log(0.5 / np.pi)


def model(p, jac=False):
    f = p[0] / np.pi * np.ones_like(dz)
    J = np.zeros((dz.size, 7)) if jac else None
    if jac:
        J[:, 0] = 1 / np.pi
    for k in range(2):
        ln_a, t, ln_n = p[1 + 3 * k: 4 + 3 * k]
        n = np.exp(ln_n)
        b = dz + t * dxy
        pos = b > 0
        lb = np.log(np.where(pos, b, 1.0))
        e = ln_a + np.log(n + 2) + LOG_NORM + n * lb
        v = np.where(pos, np.exp(np.minimum(e, 80.0)), 0.0)
        f = f + v
        if jac:
            J[:, 1 + 3 * k] = v
            J[:, 2 + 3 * k] = np.where(pos, n * dxy * np.exp(np.minimum(e - lb, 80.0)), 0.0)
            J[:, 3 + 3 * k] = v * n * (1 / (n + 2) + lb)
    return f, J


def res(p):
    f, _ = model(p)
    return np.log(np.maximum(f, 0) + floor) - target


def jac(p):
    f, J = model(p, True)
    return J / (np.maximum(f, 0) + floor)[:, None]


lo = [0, -18, -3, 0, -18, -3, 0]
hi = [1.5, 3, 3, np.log(20000), 3, 3, np.log(20000)]
p0 = np.array(ours["start"])
out = {"samples": int(count), "skinbrdf": ours}
for method, bounds in [("trf", (lo, hi)), ("lm", (-np.inf, np.inf))]:
    t = time.perf_counter()
    r = least_squares(res, p0, jac=jac, bounds=bounds, method=method, x_scale="jac")
    out["scipy_" + method] = {"seconds": time.perf_counter() - t, "cost": float(r.cost), "nfev": int(r.nfev), "njev": int(r.njev or 0), "status": int(r.status), "params": r.x.tolist()}
print(json.dumps(out, indent=1))
