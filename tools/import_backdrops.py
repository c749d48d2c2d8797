#!/usr/bin/env python3
"""Real backdrops for training: real scans, their people taken out, each in its sensor's frame.

Writes OUT/<name>.npy (N x 3 float32) and OUT/backdrops.csv (file, sensor, source) for
`[data.simulate] backdrops = "OUT"` / `data-jrdb synth --backdrops OUT`, from checkouts of:

  --aimotive DIR   aimotive/aimotive-dataset-loader (its 50-keyframe sample: a motorway at night
                   seen by a Hesai Pandar64; every road user labelled, none a person). LAZ body-
                   frame points are moved into the LiDAR's frame with calibration.json's
                   M_LIDAR_M `RT_sensor_from_body`. Needs `pip install 'laspy[lazrs]'`.
  --kitti DIR      a KITTI object folder with training/{velodyne,label_2,calib} (e.g.
                   kuixu/kitti_object_vis's data/object: three frames, HDL-64E). Points within
                   0.3 m of a Pedestrian, Person_sitting or Cyclist box are removed; KITTI labels
                   only the front camera's view, so a person elsewhere would stay (none seen).

Never use the scans `real-scans/` scores on: they are the yardstick.
    python3 tools/import_backdrops.py OUT --aimotive A --kitti K
"""
import argparse
import glob
import json
import os
import subprocess

import numpy as np


def commit(d):
    try:
        return subprocess.run(["git", "-C", d, "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except Exception:
        p = os.path.join(d, "COMMIT")
        return open(p).read().strip() if os.path.exists(p) else "unknown"


def aimotive(root, out, rows):
    import laspy

    seqs = sorted(glob.glob(os.path.join(root, "data", "*", "*", "*")))
    for seq in seqs:
        calib = json.load(open(os.path.join(seq, "sensor", "calibration", "calibration.json")))
        t = np.array(calib["M_LIDAR_M"]["RT_sensor_from_body"])
        for f in sorted(glob.glob(os.path.join(seq, "dynamic", "raw-revolutions", "*.laz"))):
            las = laspy.read(f)
            body = np.stack([las.x, las.y, las.z], 1)
            pts = body @ t[:3, :3].T + t[:3, 3]
            for g in glob.glob(os.path.join(seq, "dynamic", "box", "3d_body", os.path.basename(f)[:-4] + ".json")):
                kinds = {o["ObjectType"] for o in json.load(open(g))["CapturedObjects"]}
                if kinds & {"PEDESTRIAN", "PERSON", "BICYCLE", "MOTORCYCLE", "CYCLIST"}:
                    raise SystemExit(f"{g}: has people ({kinds}); this importer does not remove them")
            name = "aimotive-" + os.path.basename(f)[:-4]
            np.save(os.path.join(out, name + ".npy"), pts.astype(np.float32))
            rows.append((name + ".npy", "pandar64", f"aimotive-dataset-loader@{commit(root)[:12]}:{os.path.relpath(f, root)}"))


def kitti_calib(path):
    c = {}
    for line in open(path):
        if ":" in line:
            k, v = line.split(":", 1)
            c[k] = np.array([float(x) for x in v.split()])
    r0 = c["R0_rect"].reshape(3, 3)
    tr = c["Tr_velo_to_cam"].reshape(3, 4)
    return r0, tr


def kitti(root, out, rows, margin=0.3):
    base = os.path.join(root, "training")
    for f in sorted(glob.glob(os.path.join(base, "velodyne", "*.bin"))):
        stem = os.path.basename(f)[:-4]
        pts = np.fromfile(f, dtype=np.float32).reshape(-1, 4)[:, :3]
        r0, tr = kitti_calib(os.path.join(base, "calib", stem + ".txt"))
        rect = (pts @ tr[:, :3].T + tr[:, 3]) @ r0.T
        keep = np.ones(len(pts), bool)
        removed = 0
        for line in open(os.path.join(base, "label_2", stem + ".txt")):
            v = line.split()
            if v[0] not in ("Pedestrian", "Person_sitting", "Cyclist"):
                continue
            h, w, l, x, y, z, ry = map(float, v[8:15])
            d = rect - np.array([x, y - h / 2, z])
            c, s = np.cos(ry), np.sin(ry)
            lx, lz = c * d[:, 0] - s * d[:, 2], s * d[:, 0] + c * d[:, 2]
            inside = (abs(lx) < l / 2 + margin) & (abs(d[:, 1]) < h / 2 + margin) & (abs(lz) < w / 2 + margin)
            removed += int((inside & keep).sum())
            keep &= ~inside
        name = "kitti-" + stem
        np.save(os.path.join(out, name + ".npy"), pts[keep].astype(np.float32))
        rows.append((name + ".npy", "hdl64e", f"kitti_object_vis@{commit(root)[:12]}:{os.path.relpath(f, root)} ({removed} people's points removed)"))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--aimotive")
    ap.add_argument("--kitti")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    if a.aimotive:
        aimotive(a.aimotive, a.out, rows)
    if a.kitti:
        kitti(a.kitti, a.out, rows)
    if not rows:
        raise SystemExit("nothing to import: give --aimotive and/or --kitti")
    with open(os.path.join(a.out, "backdrops.csv"), "w") as f:
        f.write("file,sensor,source\n")
        for r in rows:
            f.write(",".join(r) + "\n")
    print(f"wrote {len(rows)} backdrops to {a.out}")


if __name__ == "__main__":
    main()
