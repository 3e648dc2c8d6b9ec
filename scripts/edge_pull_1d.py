#!/usr/bin/env python3
"""A 1-D model of the detector's outer-edge estimator (host/targets/src/detect.rs, step 4).

    python3 scripts/edge_pull_1d.py

The grey profile across a tag's side, outward = +x: a data cell (white or black), the black
border one cell wide, the white ring and paper beyond. Pixels integrate the profile over their
width (box, 16 sub-samples), a Gaussian blur follows, and the estimator reads the pixels
bilinearly: the centroid of the squared positive central difference (half span 0.5 px for
cells under 3 px, else 1 px) over a window of ±(0.4 cell, within 0.75..2 px) on a 0.25 px
grid, re-centred three times. Prints, per cell and blur:

* the pull of the border's inner edge: the edge's mean error where the data cell behind the
  border is white, and where it is black (the next edge two cells in), over 8 sub-pixel phases;
* the phase error: the standard deviation over 16 phases of the edge's error with no inner
  edge within reach, which a nearly axis-aligned side shares along its length.
"""
import numpy as np


def profile(edges, levels, blur, ss=16):
    xs = np.arange(-20, 21)

    def val(u):
        v = levels[0]
        for e, lv in zip(edges, levels[1:]):
            if u >= e:
                v = lv
        return v

    pix = np.array([np.mean([val(x - 0.5 + (k + 0.5) / ss) for k in range(ss)]) for x in xs])
    r = int(np.ceil(3 * blur))
    k = np.exp(-np.arange(-r, r + 1) ** 2 / (2 * blur * blur))
    k /= k.sum()
    return xs, np.convolve(np.pad(pix, r, mode='edge'), k, mode='valid')


def estimate(xs, v, start, gspan, rng):
    c = start
    for _ in range(3):
        offs = np.arange(-rng, rng + 1e-9, 0.25)
        g = np.array([np.interp(c + o + gspan, xs, v) - np.interp(c + o - gspan, xs, v)
                      for o in offs])
        w = np.where(g > 0, g * g, 0)
        c = c + (w * offs).sum() / w.sum()
    return c


def settings(cell):
    return (0.5 if cell < 3 else 1.0), min(max(0.4 * cell, 0.75), 2.0)


BLACK, WHITE = 0.05, 1.0
print('pull of the inner edge (mean edge error, px; + = outward)')
for cell in [1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0]:
    gspan, rng = settings(cell)
    for blur in [0.5, 0.7, 1.0]:
        rows = []
        for e in np.linspace(0, 1, 8, endpoint=False):
            xw, vw = profile([e - cell, e], [WHITE, BLACK, WHITE], blur)
            xb, vb = profile([e - 2 * cell, e - cell, e], [WHITE, BLACK, BLACK, WHITE], blur)
            rows.append((estimate(xw, vw, e + 0.3, gspan, rng) - e,
                         estimate(xb, vb, e + 0.3, gspan, rng) - e))
        r = np.array(rows)
        print(f'  cell {cell} px, blur {blur} px, half span {gspan}: white behind '
              f'{r[:, 0].mean():+.3f}, black behind {r[:, 1].mean():+.3f}')
print('phase error (no inner edge within reach)')
for cell in [1.5, 2.0, 2.5, 3.0, 4.0, 6.0]:
    gspan, rng = settings(cell)
    for blur in [0.3, 0.5, 0.7]:
        errs = []
        for e in np.linspace(0, 1, 16, endpoint=False):
            x, v = profile([e - 3 * cell, e], [WHITE, BLACK, WHITE], blur)
            errs.append(estimate(x, v, e + 0.3, gspan, rng) - e)
        errs = np.array(errs)
        print(f'  cell {cell} px, blur {blur} px, half span {gspan}: mean {errs.mean():+.3f}, '
              f'sd over phase {errs.std():.3f}')
