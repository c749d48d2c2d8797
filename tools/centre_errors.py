#!/usr/bin/env python3
"""Signed centre errors of detections against JRDB labels, by range band (docs/recipe.md §6).

    python3 tools/centre_errors.py RUN/detections/val/json data/sim-bench-v1

Each frame's detections scoring at least 0.3 are matched, best first, to the nearest unmatched
label within 0.5 m in BEV (pedestrians with at least 10 points within 25 m, as the official
protocol counts them). The centre error is split along the sensor's ray through the label
(radial, + = beyond it) and across it (tangential); printed per 5 m band as median and median
absolute value, with the median errors of z, l and h, and over all bands (the last row: minus its
radial median is what `model.post.radial_shift` calibrates). Standard library only.
"""
import glob
import json
import math
import os
import statistics as st
import sys


def main(det_dir, root, min_score=0.3):
    rows = []
    for f in sorted(glob.glob(os.path.join(det_dir, "*.json"))):
        seq = os.path.basename(f)[:-5]
        dets = json.load(open(f))["detections"]
        labels = json.load(open(os.path.join(root, "labels/labels_3d", seq + ".json")))["labels"]
        for frame, ds in dets.items():
            gts = [l for l in labels.get(frame + ".pcd", [])
                   if l["label_id"].startswith("pedestrian") and l["attributes"]["num_points"] >= 10
                   and math.hypot(l["box"]["cx"], l["box"]["cy"]) <= 25]
            taken = [False] * len(gts)
            for d in sorted(ds, key=lambda d: -d["score"]):
                if d["score"] < min_score:
                    break
                b, best = d["box"], None
                for i, g in enumerate(gts):
                    if taken[i]:
                        continue
                    dist = math.hypot(b["cx"] - g["box"]["cx"], b["cy"] - g["box"]["cy"])
                    if dist < 0.5 and (best is None or dist < best[0]):
                        best = (dist, i)
                if best is None:
                    continue
                taken[best[1]] = True
                g = gts[best[1]]["box"]
                r = math.hypot(g["cx"], g["cy"])
                ux, uy = g["cx"] / r, g["cy"] / r
                dx, dy = b["cx"] - g["cx"], b["cy"] - g["cy"]
                rows.append((r, dx * ux + dy * uy, -dx * uy + dy * ux, b["cz"] - g["cz"], b["l"] - g["l"], b["h"] - g["h"],
                             gts[best[1]]["attributes"]["num_points"]))
    print(f"matched {len(rows)}")
    print("| range | matches | radial (median, median abs) | tangential | z | l | h | median points |")
    print("|---|---|---|---|---|---|---|---|")
    for lo, hi in [(0, 5), (5, 10), (10, 15), (15, 20), (20, 25), (0, 25)]:
        sel = [x for x in rows if lo <= x[0] < hi]
        if not sel:
            continue
        med = lambda k: st.median(x[k] for x in sel)
        mabs = lambda k: st.median(abs(x[k]) for x in sel)
        label = "all" if (lo, hi) == (0, 25) else f"{lo}–{hi} m"
        print(f"| {label} | {len(sel)} | {med(1):+.3f} ({mabs(1):.3f}) | {med(2):+.3f} ({mabs(2):.3f}) | "
              f"{med(3):+.3f} | {med(4):+.3f} | {med(5):+.3f} | {med(6):.0f} |")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
