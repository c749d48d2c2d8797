#!/usr/bin/env python3
"""Reads a `data-jrdb export --to nuscenes` folder with the official nuScenes devkit and compares
every box with the JRDB tree it came from.

    pip install nuscenes-devkit   (needs numpy<2 for its pins; --no-deps works with pyquaternion,
                                   opencv-python-headless, shapely, scikit-learn, tqdm,
                                   pycocotools, cachetools, fire, descartes)
    python3 tools/check_nuscenes_export.py --tree TREE --export DIR

The devkit's `get_sample_data` moves each annotation from the global frame into the LIDAR_TOP
frame through its own ego-pose and calibration code; the tree's `labels_3d` boxes (JRDB's base
frame) are moved there by hand with the documented relation p_base = R_cs p_lidar + (0, 0,
t_cs.z - 0.7). Exits non-zero if a box, a size or a heading differs by more than 1e-4.
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np
from nuscenes.nuscenes import NuScenes
from pyquaternion import Quaternion


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tree", required=True, type=Path)
    ap.add_argument("--export", required=True, type=Path)
    ap.add_argument("--version", default="v1.0-export")
    a = ap.parse_args()

    nusc = NuScenes(version=a.version, dataroot=str(a.export), verbose=False)
    worst, boxes = 0.0, 0
    for scene in nusc.scene:
        labels = json.loads((a.tree / "labels/labels_3d" / f"{scene['name']}.json").read_text())["labels"]
        frames = sorted(labels)
        token = scene["first_sample_token"]
        k = 0
        while token:
            sample = nusc.get("sample", token)
            sd_token = sample["data"]["LIDAR_TOP"]
            cs = nusc.get("calibrated_sensor", nusc.get("sample_data", sd_token)["calibrated_sensor_token"])
            r_cs = Quaternion(cs["rotation"]).rotation_matrix
            lift = np.array([0.0, 0.0, cs["translation"][2] - 0.7])
            _, got, _ = nusc.get_sample_data(sd_token)
            want = [l for l in labels.get(frames[k], []) if l["label_id"].startswith("pedestrian:")]
            if len(got) != len(want):
                sys.exit(f"{scene['name']} frame {k}: devkit {len(got)} boxes, tree {len(want)}")
            for g, w in zip(got, want):
                b = w["box"]
                centre = r_cs.T @ (np.array([b["cx"], b["cy"], b["cz"]]) - lift)
                axis = r_cs.T @ np.array([np.cos(b["rot_z"]), np.sin(b["rot_z"]), 0.0])
                g_axis = g.orientation.rotation_matrix @ np.array([1.0, 0.0, 0.0])
                d = max(
                    np.abs(g.center - centre).max(),
                    np.abs(g.wlh - np.array([b["w"], b["l"], b["h"]])).max(),
                    np.abs(g_axis - axis).max(),
                )
                worst = max(worst, d)
                boxes += 1
            token = sample["next"]
            k += 1
    print(f"{len(nusc.scene)} scenes, {len(nusc.sample)} key frames, {boxes} boxes: largest difference {worst:.2e}")
    if worst > 1e-4:
        sys.exit("differs")


if __name__ == "__main__":
    main()
