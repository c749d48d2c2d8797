#!/usr/bin/env python3
"""Writes fuzz/seeds/<target>/ from files in this repository that other tools wrote (pypcd4's and
NumPy's fixtures, the official evaluator's KITTI-style fixtures) and from a small simulated
JRDB-format tree (labels_3d JSON, calibration YAML), cut down to a few points where a seed would
otherwise be hundreds of kilobytes (AFL++ mutates small inputs far faster).

    python3 fuzz/make_seeds.py [--tree DIR]   # DIR: a tree from `data-jrdb synth` (made if absent)
"""
import argparse
import glob
import json
import os
import shutil
import struct
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SEEDS = os.path.join(ROOT, "fuzz", "seeds")
OTHER = os.path.join(ROOT, "crates/train/tests/fixtures/other_tools")


def put(target, name, data):
    os.makedirs(os.path.join(SEEDS, target), exist_ok=True)
    with open(os.path.join(SEEDS, target, name), "wb") as f:
        f.write(data)


def pcd_head_and_data(path):
    raw = open(path, "rb").read()
    at = raw.index(b"\nDATA ") + 1
    end = raw.index(b"\n", at) + 1
    return raw[:end], raw[end:]


def with_points(head, n):
    lines = []
    for line in head.decode().splitlines():
        key = line.split(" ", 1)[0]
        lines.append(f"{key} {n}" if key in ("WIDTH", "POINTS") else line)
    return ("\n".join(lines) + "\n").encode()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tree", default=os.path.join(ROOT, "target", "fuzz-seed-tree"))
    args = ap.parse_args()
    shutil.rmtree(SEEDS, ignore_errors=True)

    # PCD: pypcd4's three encodings (the compressed one whole, the others cut to 16 points).
    head, data = pcd_head_and_data(os.path.join(OTHER, "ascii.pcd"))
    put("pcd", "pypcd4_ascii_16.pcd", with_points(head, 16) + b"".join(data.splitlines(keepends=True)[:16]))
    head, data = pcd_head_and_data(os.path.join(OTHER, "binary.pcd"))
    put("pcd", "pypcd4_binary_16.pcd", with_points(head, 16) + data[: 16 * 18])
    # The compressed one cut to 16 points and compressed again by liblzf itself (`pip install
    # python-lzf`): a 121 kB seed held AFL++ near 200 executions a second.
    head, data = pcd_head_and_data(os.path.join(OTHER, "binary_compressed.pcd"))
    csize, usize = struct.unpack("<II", data[:8])
    try:
        import lzf
        raw = lzf.decompress(data[8:8 + csize], usize)
        n = int(next(l.split()[1] for l in head.decode().splitlines() if l.startswith("POINTS")))
        sizes = [int(v) for v in next(l for l in head.decode().splitlines() if l.startswith("SIZE")).split()[1:]]
        cols, at = [], 0
        for size in sizes:
            cols.append(raw[at:at + 16 * size])
            at += n * size
        small = b"".join(cols)
        block = lzf.compress(small, len(small) + len(small) // 16 + 64)
        put("pcd", "pypcd4_binary_compressed_16.pcd", with_points(head, 16) + struct.pack("<II", len(block), len(small)) + block)
    except ImportError:
        shutil.copy(os.path.join(OTHER, "binary_compressed.pcd"), os.path.join(SEEDS, "pcd", "pypcd4_binary_compressed.pcd"))
    # PCL's organised layout with padding fields, one of COUNT 0, and a NaN point.
    pad = (b"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z _ rgb _\nSIZE 4 4 4 1 4 1\nTYPE F F F U F U\n"
           b"COUNT 1 1 1 4 1 0\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA binary\n")
    for p in [(1.0, 2.0, 3.0), (float("nan"),) * 3, (4.0, 5.0, 6.0), (-1.0, 0.5, 0.25)]:
        pad += struct.pack("<3f", *p) + bytes(4) + struct.pack("<f", 7.0)
    put("pcd", "pcl_organised_padding.pcd", pad)

    # NPY: NumPy's fixtures (float32 N x 4, float64 N x 3) and pypcd4's frame cut to 16 rows.
    for f in glob.glob(os.path.join(ROOT, "crates/data-jrdb/tests/fixtures/*.npy")):
        put("npy", os.path.basename(f), open(f, "rb").read())
    raw = open(os.path.join(OTHER, "frame.npy"), "rb").read()
    hlen = struct.unpack("<H", raw[8:10])[0]
    header = raw[10:10 + hlen].decode()
    rows_at = header.index("'shape': (") + len("'shape': (")
    n = header[rows_at:header.index(",", rows_at)]
    cols = int(header[header.index(",", rows_at) + 1:header.index(")", rows_at)])
    small = header.replace(f"({n},", "(16,", 1)
    small = small.rstrip("\n").rstrip(" ")
    small += " " * ((64 - (10 + len(small) + 1) % 64) % 64) + "\n"
    put("npy", "numpy_frame_16.npy", raw[:8] + struct.pack("<H", len(small)) + small.encode() + raw[10 + hlen:10 + hlen + 16 * cols * 4])

    # KITTI .bin: the fixture.
    put("kitti_bin", "cloud_kitti.bin", open(os.path.join(ROOT, "crates/data-jrdb/tests/fixtures/cloud_kitti.bin"), "rb").read())

    # KITTI-style txt: the official evaluator's ground truth and detections.
    fx = os.path.join(ROOT, "crates/eval/tests/fixtures/seed2002")
    put("kitti_txt", "gt.txt", open(os.path.join(fx, "gt/seq-2002-0/000000.txt"), "rb").read())
    put("kitti_txt", "det.txt", open(os.path.join(fx, "det/seq-2002-0/000000.txt"), "rb").read())

    # labels_3d JSON and defaults.yaml from a simulated tree (the layout JRDB's files have).
    if not os.path.isdir(args.tree):
        subprocess.run(["cargo", "run", "-q", "-p", "data-jrdb", "--", "synth", "--out", args.tree, "--sequences", "1", "--frames", "2", "--seed", "3"], cwd=ROOT, check=True)
    labels = glob.glob(os.path.join(args.tree, "**", "labels_3d", "*.json"), recursive=True)[0]
    doc = json.load(open(labels))
    doc["labels"] = {k: v[:3] for k, v in list(doc["labels"].items())[:2]}
    put("labels_json", "labels_3d.json", json.dumps(doc).encode())
    cal = glob.glob(os.path.join(args.tree, "**", "calibration", "defaults.yaml"), recursive=True)[0]
    put("calibration_yaml", "defaults.yaml", open(cal, "rb").read())
    for t in sorted(os.listdir(SEEDS)):
        print(t, sorted(os.listdir(os.path.join(SEEDS, t))))

    # ROS 2 PointCloud2 in CDR, serialized by rosbags (`pip install rosbags`): 16 points in a
    # Velodyne driver's layout, an organised 4 x 4 one with a NaN, and float64 big-endian.
    try:
        import numpy as np
        from rosbags.typesys import Stores, get_typestore
        ts = get_typestore(Stores.ROS2_HUMBLE)
        PC2, PF = ts.types["sensor_msgs/msg/PointCloud2"], ts.types["sensor_msgs/msg/PointField"]
        Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
        def cloud(fields, step, h, w, big, data):
            m = PC2(header=Header(stamp=Time(sec=1, nanosec=2), frame_id="lidar"), height=h, width=w,
                    fields=[PF(name=n, offset=o, datatype=t, count=1) for n, o, t in fields],
                    is_bigendian=big, point_step=step, row_step=step * w, data=np.frombuffer(data, np.uint8), is_dense=False)
            return bytes(ts.serialize_cdr(m, PC2.__msgtype__))
        pts = np.arange(48, dtype=np.float32).reshape(16, 3)
        rec = np.zeros(16, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "<f4"), ("ring", "<u2"), ("p", "<u2")])
        rec["x"], rec["y"], rec["z"] = pts.T
        put("pointcloud2", "velodyne_16.cdr", cloud([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4)], 20, 1, 16, False, rec.tobytes()))
        org = pts.copy(); org[5] = np.nan
        put("pointcloud2", "organised_4x4.cdr", cloud([("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], 12, 4, 4, False, org.tobytes()))
        be = pts.astype(">f8")[:, [2, 0, 1]]
        put("pointcloud2", "float64_be_16.cdr", cloud([("z", 0, 8), ("x", 8, 8), ("y", 16, 8)], 24, 1, 16, True, be.tobytes()))
        # The same three in ROS 1's serialization (a .bag's messages).
        ts1 = get_typestore(Stores.ROS1_NOETIC)
        PC1, PF1 = ts1.types["sensor_msgs/msg/PointCloud2"], ts1.types["sensor_msgs/msg/PointField"]
        Header1, Time1 = ts1.types["std_msgs/msg/Header"], ts1.types["builtin_interfaces/msg/Time"]
        def cloud1(fields, step, h, w, big, data):
            m = PC1(header=Header1(seq=3, stamp=Time1(sec=1, nanosec=2), frame_id="lidar"), height=h, width=w,
                    fields=[PF1(name=n, offset=o, datatype=t, count=1) for n, o, t in fields],
                    is_bigendian=big, point_step=step, row_step=step * w, data=np.frombuffer(data, np.uint8), is_dense=False)
            return bytes(ts1.serialize_ros1(m, PC1.__msgtype__))
        put("pointcloud2_ros1", "velodyne_16.ros1", cloud1([("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7), ("ring", 16, 4)], 20, 1, 16, False, rec.tobytes()))
        put("pointcloud2_ros1", "organised_4x4.ros1", cloud1([("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], 12, 4, 4, False, org.tobytes()))
        put("pointcloud2_ros1", "float64_be_16.ros1", cloud1([("z", 0, 8), ("x", 8, 8), ("y", 16, 8)], 24, 1, 16, True, be.tobytes()))
    except ImportError:
        print("rosbags or numpy missing: no pointcloud2 seeds (pip install rosbags numpy)")


if __name__ == "__main__":
    main()
