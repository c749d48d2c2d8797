#!/usr/bin/env python3
"""Writes crates/train/tests/fixtures/recordings/clouds.mcap with the reference tools (Python's
`mcap` and `mcap-ros2-support`): a real scan (every 4th point of real-scans/nuscenes/, a nuScenes
keyframe) as sensor_msgs/msg/PointCloud2 in the layouts drivers publish, one topic each:

  /velodyne_points   x y z intensity (float32) ring (uint16), little-endian, unorganised, 2 messages
  /ouster/points     organised 64 rows: x y z (float32) at 0/4/8, padding, t (uint32),
                     reflectivity (uint16); a NaN point after every 8th (a missing return)
  /be64/points       x y z as float64, big-endian, z first
  /camera/info       a std_msgs/msg/String, not a cloud

`crates/train/tests/recordings.rs` decodes it with `detect` and compares every message's boxes
with `detect` on the same points written as .npy.
    pip install mcap mcap-ros2-support numpy && python3 tools/make_recording_fixtures.py
"""
import os

import numpy as np
from mcap_ros2.writer import Writer

ROOT = os.path.join(os.path.dirname(__file__), "..")
OUT = os.path.join(ROOT, "crates/train/tests/fixtures/recordings/clouds.mcap")

POINTCLOUD2 = """std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool is_bigendian
uint32 point_step
uint32 row_step
uint8[] data
bool is_dense
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: sensor_msgs/PointField
uint8 INT8=1
uint8 UINT8=2
uint8 INT16=3
uint8 UINT16=4
uint8 INT32=5
uint8 UINT32=6
uint8 FLOAT32=7
uint8 FLOAT64=8
string name
uint32 offset
uint8 datatype
uint32 count"""


def field(name, offset, datatype):
    return {"name": name, "offset": offset, "datatype": datatype, "count": 1}


def message(frame_id, sec, height, width, fields, big, step, data, dense):
    return {
        "header": {"stamp": {"sec": sec, "nanosec": 250_000_000}, "frame_id": frame_id},
        "height": height,
        "width": width,
        "fields": fields,
        "is_bigendian": big,
        "point_step": step,
        "row_step": step * width,
        "data": data,
        "is_dense": dense,
    }


def main():
    pts = np.load(os.path.join(ROOT, "real-scans/nuscenes/1532402927647951.npy"))[::4, :3].astype(np.float32)
    n = len(pts)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "wb") as f:
        w = Writer(f)
        cloud = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINTCLOUD2)
        text = w.register_msgdef("std_msgs/msg/String", "string data")

        # A Velodyne driver's layout.
        rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("pad", "<u2")])
        rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        rec["intensity"] = 10.0
        rec["ring"] = np.arange(n) % 32
        fields = [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("intensity", 12, 7), field("ring", 16, 4)]
        for k in range(2):
            t = (1_532_402_927 + k) * 10**9
            w.write_message("/velodyne_points", cloud, message("lidar_top", 1_532_402_927 + k, 1, n, fields, False, 20, rec.tobytes(), True), log_time=t, publish_time=t)

        # An organised cloud with missing returns (NaN) after every 8th point.
        keep = np.arange(n)
        slots = []
        for i in keep:
            slots.append(pts[i])
            if i % 8 == 7:
                slots.append([np.nan, np.nan, np.nan])
        rows = 64
        while len(slots) % rows:
            slots.append([np.nan, np.nan, np.nan])
        s = np.array(slots, dtype=np.float32)
        width = len(s) // rows
        rec = np.zeros(len(s), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("pad", "<f4"), ("t", "<u4"), ("reflectivity", "<u2"), ("pad2", "<u2")])
        rec["x"], rec["y"], rec["z"] = s[:, 0], s[:, 1], s[:, 2]
        rec["t"] = np.arange(len(s))
        fields = [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("t", 16, 6), field("reflectivity", 20, 4)]
        t = 1_532_402_930 * 10**9
        w.write_message("/ouster/points", cloud, message("os_sensor", 1_532_402_930, rows, width, fields, False, 24, rec.tobytes(), False), log_time=t, publish_time=t)

        # float64, big-endian, z first.
        rec = np.zeros(n, dtype=[("z", ">f8"), ("x", ">f8"), ("y", ">f8")])
        rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        fields = [field("z", 0, 8), field("x", 8, 8), field("y", 16, 8)]
        t = 1_532_402_931 * 10**9
        w.write_message("/be64/points", cloud, message("lidar_top", 1_532_402_931, 1, n, fields, True, 24, rec.tobytes(), True), log_time=t, publish_time=t)

        w.write_message("/camera/info", text, {"data": "not a cloud"}, log_time=t, publish_time=t)
        w.finish()
    print(f"wrote {OUT}: {n} points a cloud, {os.path.getsize(OUT)} bytes")


if __name__ == "__main__":
    main()
