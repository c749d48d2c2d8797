#!/usr/bin/env python3
"""Builds real-scans/ from upstream sample files (the yardstick of docs/real-scans.md): each
source's clouds (byte-exact where pmunet reads the upstream format, else converted as said below)
and its boxes as KITTI-style ground truth in the cloud's own frame, `real-scans/gt/<source>/<frame>.txt`.

    python3 tools/import_real_scans.py STAGING

STAGING holds, per source, the upstream files and a `labels_lidar.json` with every box in one
convention (geometric centre in the cloud's frame, l/w/h, yaw of l from +x counter-clockwise);
the sources' PROVENANCE.md files say where each came from and how their labels were converted.
"""
import json
import math
import os
import shutil
import struct
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "real-scans")

# source -> (staging folder, how the cloud is stored here)
SOURCES = {
    "sustechpoints": "sustechpoints_example",
    "nuscenes": "nuscenes_mmdet3d_demo",
    "argoverse2": "av2_api_testdata",
}
PEDESTRIAN = {"pedestrian", "PEDESTRIAN", "Pedestrian"}
# People on or in something: not counted either way (a detection on them is neither found nor false).
RIDER = {"Rider", "BICYCLIST", "MOTORCYCLIST", "WHEELCHAIR"}


def rot_z_to_ry(rot_z):
    # eval::kitti::rot_z_to_ry, the official converter's angle.
    return -rot_z if rot_z < math.pi else 2 * math.pi - rot_z


def kitti_line(kind, centre, lwh, yaw, num_points):
    # eval::kitti::KittiObject::ground_truth, written as to_line writes it.
    cx, cy, cz = centre
    l, w, h = lwh
    return f"{kind} -1 -1 {num_points} -1 -1 -1 -1 -1 {h!r} {l!r} {w!r} {-cy!r} {(-cz + h / 2)!r} {cx!r} {rot_z_to_ry(yaw)!r} 1"


def npy(points, cols):
    header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': ({len(points)}, {cols}), }}"
    header += " " * ((64 - (10 + len(header) + 1) % 64) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + b"".join(struct.pack(f"<{cols}f", *p[:cols]) for p in points)


def main():
    staging = sys.argv[1]
    for name, folder in SOURCES.items():
        src = os.path.join(staging, folder)
        labels = json.load(open(os.path.join(src, "labels_lidar.json")))
        os.makedirs(os.path.join(OUT, name), exist_ok=True)
        os.makedirs(os.path.join(OUT, "gt", name), exist_ok=True)
        for frame, f in labels["frames"].items():
            stem = frame.replace("/", "-") if name != "argoverse2" else frame.split("/")[0][:8] + "-" + frame.split("/")[1]
            stem = stem.replace("LIDAR_TOP__", "")
            cloud = os.path.join(src, f["points_file"])
            if name == "sustechpoints":
                # Byte-exact: PCL-style padding fields, a COUNT 0 field, zeros after the last point.
                shutil.copy(cloud, os.path.join(OUT, name, stem + ".pcd"))
            elif name == "nuscenes":
                # nuScenes .pcd.bin rows are 5 float32 (x, y, z, intensity, ring): as N x 4 .npy.
                raw = open(cloud, "rb").read()
                pts = [struct.unpack_from("<5f", raw, k) for k in range(0, len(raw), 20)]
                open(os.path.join(OUT, name, stem + ".npy"), "wb").write(npy(pts, 4))
            else:
                # Argoverse 2 stores float16 x, y, z in Arrow feather; float32 copies as N x 3 .npy.
                raw = open(cloud, "rb").read()
                pts = [struct.unpack_from("<4f", raw, k) for k in range(0, len(raw), 16)]
                open(os.path.join(OUT, name, stem + ".npy"), "wb").write(npy(pts, 3))
            lines = []
            for b in f["boxes"]:
                kind = "Pedestrian" if b["cls"] in PEDESTRIAN else "Cyclist" if b["cls"] in RIDER else None
                if kind:
                    lines.append(kitti_line(kind, b["center"], b["lwh"], b["yaw"], b["n_points"]))
            with open(os.path.join(OUT, "gt", name, stem + ".txt"), "w") as g:
                g.write("".join(l + "\n" for l in lines))
        for extra in os.listdir(src):
            if extra.startswith(("LICENSE", "PROVENANCE")):
                shutil.copy(os.path.join(src, extra), os.path.join(OUT, name, extra))
        print(name, sorted(os.listdir(os.path.join(OUT, name))))


if __name__ == "__main__":
    main()
