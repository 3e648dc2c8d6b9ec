#!/usr/bin/env python3
"""Writes host/targets/tests/data/apriltag_c_refined.json: the AprilTag reference C library
(pupil-apriltags, quad_decimate=1, refine_edges=1) run on shared/data/apriltag/*.jpg decoded to
their luma (Y) channel, corners converted to the project's convention (C corners - 0.5 px).

The .txt files shipped with the photos were made with refine_edges=0 (this library reproduces
them to a median of 0.000 px with refine_edges=0): unrefined quad corners. This fixture is the
same library with edge refinement, for comparing sub-pixel corners.

    pip install pupil-apriltags opencv-python-headless
    python3 scripts/peers/apriltag_reference_fixture.py
"""
import json, os
import cv2, numpy as np, pupil_apriltags as pa

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
D = os.path.join(ROOT, "..", "shared", "data", "apriltag")
if not os.path.isdir(D):
    D = "/work/shared/data/apriltag"
det = pa.Detector(families="tag36h11", quad_decimate=1.0, refine_edges=1)
out = {}
for f in sorted(os.listdir(D)):
    if not f.endswith(".jpg"):
        continue
    g = cv2.imread(os.path.join(D, f), cv2.IMREAD_GRAYSCALE)
    out[f[:-4]] = [
        {"id": int(d.tag_id), "hamming": int(d.hamming),
         "corners": (np.array(d.corners) - 0.5).round(4).tolist()}
        for d in det.detect(g)
    ]
path = os.path.join(ROOT, "host", "targets", "tests", "data", "apriltag_c_refined.json")
with open(path, "w") as fh:
    json.dump(out, fh, indent=1)
print(path, {k: len(v) for k, v in out.items()})
