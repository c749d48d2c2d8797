#!/usr/bin/env python3
"""Moves every detection of a pmunet detection-JSON folder outward along the sensor's ray by
DELTA metres: the diagnostic of docs/recipe.md §6 (what the centre's radial bias costs).

    python3 tools/shift_boxes.py RUN/detections/val/json /tmp/shifted 0.08
    cargo run -p eval -- --gt LABELS_3D_OF_THE_SAME_SEQUENCES --det /tmp/shifted
"""
import glob
import json
import math
import os
import sys

if len(sys.argv) != 4:
    sys.exit(__doc__)
src, dst, delta = sys.argv[1], sys.argv[2], float(sys.argv[3])
os.makedirs(dst, exist_ok=True)
for f in glob.glob(os.path.join(src, "*.json")):
    d = json.load(open(f))
    for dets in d["detections"].values():
        for x in dets:
            b = x["box"]
            r = math.hypot(b["cx"], b["cy"])
            if r > 1e-6:
                b["cx"] += delta * b["cx"] / r
                b["cy"] += delta * b["cy"] / r
    json.dump(d, open(os.path.join(dst, os.path.basename(f)), "w"))
