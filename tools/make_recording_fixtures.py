#!/usr/bin/env python3
"""Writes crates/train/tests/fixtures/recordings/clouds.mcap with the reference tools (Python's
`mcap` and `mcap-ros2-support`), and the same messages as a ROS 1 bag (`clouds.bag`, bz2 chunks)
and a ROS 2 bag in its SQLite storage (`clouds_db3/clouds_db3.db3`) with Python's `rosbags`: a real scan (every 4th point of real-scans/nuscenes/, a nuScenes
keyframe) as sensor_msgs/msg/PointCloud2 in the layouts drivers publish, one topic each:

  /velodyne_points   x y z intensity (float32) ring (uint16), little-endian, unorganised, 2 messages
  /ouster/points     organised 64 rows: x y z (float32) at 0/4/8, padding, t (uint32),
                     reflectivity (uint16); a NaN point after every 8th (a missing return)
  /be64/points       x y z as float64, big-endian, z first
  /camera/info       a std_msgs/msg/String, not a cloud

`crates/train/tests/recordings.rs` decodes it with `detect` and compares every message's boxes
with `detect` on the same points written as .npy.
    pip install mcap mcap-ros2-support rosbags numpy && python3 tools/make_recording_fixtures.py
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


def clouds(pts):
    """The messages: (topic, log time in ns, message as a dict) in writing order."""
    n = len(pts)
    out = []
    # A Velodyne driver's layout.
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("pad", "<u2")])
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    rec["intensity"] = 10.0
    rec["ring"] = np.arange(n) % 32
    fields = [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("intensity", 12, 7), field("ring", 16, 4)]
    for k in range(2):
        out.append(("/velodyne_points", (1_532_402_927 + k) * 10**9, message("lidar_top", 1_532_402_927 + k, 1, n, fields, False, 20, rec.tobytes(), True)))
    # An organised cloud with missing returns (NaN) after every 8th point.
    slots = []
    for i in range(n):
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
    out.append(("/ouster/points", 1_532_402_930 * 10**9, message("os_sensor", 1_532_402_930, rows, width, fields, False, 24, rec.tobytes(), False)))
    # float64, big-endian, z first.
    rec = np.zeros(n, dtype=[("z", ">f8"), ("x", ">f8"), ("y", ">f8")])
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    fields = [field("z", 0, 8), field("x", 8, 8), field("y", 16, 8)]
    out.append(("/be64/points", 1_532_402_931 * 10**9, message("lidar_top", 1_532_402_931, 1, n, fields, True, 24, rec.tobytes(), True)))
    return out


def write_bags(pts):
    """The same messages with rosbags: a ROS 1 bag and a ROS 2 bag in SQLite."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    def typed(ts, d, ros1):
        PC2, PF = ts.types["sensor_msgs/msg/PointCloud2"], ts.types["sensor_msgs/msg/PointField"]
        Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
        h = d["header"]
        stamp = Time(sec=h["stamp"]["sec"], nanosec=h["stamp"]["nanosec"])
        header = Header(seq=7, stamp=stamp, frame_id=h["frame_id"]) if ros1 else Header(stamp=stamp, frame_id=h["frame_id"])
        return PC2(header=header, height=d["height"], width=d["width"], fields=[PF(**f) for f in d["fields"]], is_bigendian=d["is_bigendian"],
                   point_step=d["point_step"], row_step=d["row_step"], data=np.frombuffer(d["data"], np.uint8), is_dense=d["is_dense"])

    bag = os.path.join(os.path.dirname(OUT), "clouds.bag")
    if os.path.exists(bag):
        os.remove(bag)
    ts1 = get_typestore(Stores.ROS1_NOETIC)
    w = Writer1(bag)
    w.set_compression(Writer1.CompressionFormat.BZ2)
    with w:
        conns = {}
        for topic, t, d in clouds(pts):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, "sensor_msgs/msg/PointCloud2", typestore=ts1)
            w.write(conns[topic], t, ts1.serialize_ros1(typed(ts1, d, True), "sensor_msgs/msg/PointCloud2"))
        s = w.add_connection("/camera/info", "std_msgs/msg/String", typestore=ts1)
        w.write(s, 1_532_402_931 * 10**9, ts1.serialize_ros1(ts1.types["std_msgs/msg/String"](data="not a cloud"), "std_msgs/msg/String"))
    print(f"wrote {bag}: {os.path.getsize(bag)} bytes")

    folder = os.path.join(os.path.dirname(OUT), "clouds_db3")
    if os.path.exists(folder):
        import shutil
        shutil.rmtree(folder)
    ts2 = get_typestore(Stores.ROS2_HUMBLE)
    with Writer2(folder, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        conns = {}
        for topic, t, d in clouds(pts):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, "sensor_msgs/msg/PointCloud2", typestore=ts2)
            w.write(conns[topic], t, ts2.serialize_cdr(typed(ts2, d, False), "sensor_msgs/msg/PointCloud2"))
        s = w.add_connection("/camera/info", "std_msgs/msg/String", typestore=ts2)
        w.write(s, 1_532_402_931 * 10**9, ts2.serialize_cdr(ts2.types["std_msgs/msg/String"](data="not a cloud"), "std_msgs/msg/String"))
    print(f"wrote {folder}: {sorted(os.listdir(folder))}")


def main():
    pts = np.load(os.path.join(ROOT, "real-scans/nuscenes/1532402927647951.npy"))[::4, :3].astype(np.float32)
    n = len(pts)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "wb") as f:
        w = Writer(f)
        cloud = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINTCLOUD2)
        text = w.register_msgdef("std_msgs/msg/String", "string data")

        for topic, t, d in clouds(pts):
            w.write_message(topic, cloud, d, log_time=t, publish_time=t)
        t = 1_532_402_931 * 10**9
        w.write_message("/camera/info", text, {"data": "not a cloud"}, log_time=t, publish_time=t)
        w.finish()
    print(f"wrote {OUT}: {n} points a cloud, {os.path.getsize(OUT)} bytes")
    write_bags(pts)


if __name__ == "__main__":
    main()
