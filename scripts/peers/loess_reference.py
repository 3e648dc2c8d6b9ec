#!/usr/bin/env python3
"""Reference values of netlib loess (degree 2, family gaussian) for skinbrdf-fit's parity test.

Uses scikit-misc (`pip install scikit-misc`), a wrapper of the original netlib dloess Fortran
that R's `loess` also uses. Writes host/fit/tests/fixtures/loess_reference.json: the data, the
query points and the reference fitted values / standard errors / residual scale, for a 1-D
(incidence-plane curve) and a 2-D (theta_i, theta_e) case.

    python3 scripts/peers/loess_reference.py
"""
import json
import os

import numpy as np
from skmisc.loess import loess

rng = np.random.default_rng(20261122)
cases = []

def brdf(ti, te_signed):
    # A diffuse level plus a forward lobe around the mirror direction, in 1/sr.
    return 0.3 / np.pi + 2.0 * np.exp(-((te_signed - ti) / 0.15) ** 2)

# 1-D: signed exitant angle in the incidence plane at theta_i = 0.5 rad.
n = 400
x1 = np.sort(rng.uniform(-1.4, 1.4, n))
y1 = brdf(0.5, x1) * (1 + 0.05 * rng.standard_normal(n))
q1 = np.linspace(-1.3, 1.3, 27)
# 2-D: (theta_i, signed theta_e).
n2 = 600
x2 = np.column_stack([rng.uniform(0.1, 1.2, n2), rng.uniform(-1.3, 1.3, n2)])
y2 = brdf(x2[:, 0], x2[:, 1]) * (1 + 0.05 * rng.standard_normal(n2))
g = np.linspace(0.2, 1.1, 5)
h = np.linspace(-1.1, 1.1, 9)
q2 = np.array([[a, b] for a in g for b in h])

def column_major(a):
    """scikit-misc 0.5.3 under NumPy 2 reads an (n, d) predictor array as if it were stored
    column-major (a noiseless quadratic then gives a residual scale of 0.67 instead of 1e-15).
    Handing it the column-major bytes under the (n, d) shape makes it read the right values."""
    n, d = a.shape
    return np.ascontiguousarray(a.T).reshape(n, d)


for name, x, y, q, span, norm in [
    ("one_d", x1[:, None], y1, q1[:, None], 0.2, True),
    ("two_d", x2, y2, q2, 0.3, True),
    ("two_d_raw", x2, y2, q2, 0.3, False),
]:
    l = loess(column_major(x), y, span=span, degree=2, family="gaussian", normalize=norm)
    l.control.surface = "direct"
    l.control.statistics = "exact"
    l.fit()
    p = l.predict(column_major(q), stderror=True)
    value, stderr = np.asarray(p.values), np.asarray(p.stderr)
    # Self-check of the layout work-around: predictions at the samples equal the fitted values.
    assert np.allclose(np.asarray(l.predict(column_major(x[:20])).values), np.asarray(l.outputs.fitted_values)[:20])
    cases.append({
        "name": name,
        "span": span,
        "normalize": norm,
        "x": x.tolist(),
        "y": y.tolist(),
        "query": q.tolist(),
        "value": value.tolist(),
        "stderr": stderr.tolist(),
        "residual_scale": float(l.outputs.residual_scale),
        "enp": float(l.outputs.enp),
    })

out = os.path.join(os.path.dirname(__file__), "..", "..", "host", "fit", "tests", "fixtures", "loess_reference.json")
with open(out, "w") as f:
    json.dump({"generator": "scripts/peers/loess_reference.py (scikit-misc netlib loess, surface=direct, statistics=exact)", "cases": cases}, f)
print("wrote", os.path.normpath(out))
for c in cases:
    print(c["name"], "residual_scale", c["residual_scale"], "enp", c["enp"])
