#!/usr/bin/env python3
"""Writes OUT (default /tmp/rec1000.mcap): the nuScenes frame of real-scans/ (34,688 points) as a
sensor_msgs/msg/PointCloud2 on /points, N times (default 1,000) 50 ms apart, with Python's
mcap-ros2-support (its default zstd chunks): the recording docs/detect.md's speed figure uses.
An OUT ending in .bag is a ROS 1 bag written by rosbags instead (bz2 chunks), the same messages.
    python3 tools/make_long_recording.py [OUT] [N]
"""
import os
import sys

import numpy as np
from mcap_ros2.writer import Writer

sys.path.insert(0, os.path.dirname(__file__))
from make_recording_fixtures import POINTCLOUD2, ROOT, field, message  # noqa: E402


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "/tmp/rec1000.mcap"
    count = int(sys.argv[2]) if len(sys.argv) > 2 else 1000
    pts = np.load(os.path.join(ROOT, "real-scans/nuscenes/1532402927647951.npy"))[:, :3].astype(np.float32)
    rec = np.zeros(len(pts), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"), ("pad", "<u2")])
    rec["x"], rec["y"], rec["z"] = pts.T
    fields = [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7), field("intensity", 12, 7), field("ring", 16, 4)]
    if out.endswith(".bag"):
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.typesys import Stores, get_typestore
        ts = get_typestore(Stores.ROS1_NOETIC)
        PC2, PF = ts.types["sensor_msgs/msg/PointCloud2"], ts.types["sensor_msgs/msg/PointField"]
        Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
        if os.path.exists(out):
            os.remove(out)
        w = Writer1(out)
        w.set_compression(Writer1.CompressionFormat.BZ2)
        with w:
            conn = w.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
            for k in range(count):
                t = 1_600_000_000 * 10**9 + k * 50_000_000
                m = PC2(header=Header(seq=k, stamp=Time(sec=1_600_000_000 + k // 20, nanosec=0), frame_id="lidar"), height=1, width=len(pts),
                        fields=[PF(**f) for f in fields], is_bigendian=False, point_step=20, row_step=20 * len(pts),
                        data=np.frombuffer(rec.tobytes(), np.uint8), is_dense=True)
                w.write(conn, t, ts.serialize_ros1(m, "sensor_msgs/msg/PointCloud2"))
        print(f"wrote {out}: {count} messages of {len(pts)} points, {os.path.getsize(out)} bytes")
        return
    with open(out, "wb") as f:
        w = Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINTCLOUD2)
        for k in range(count):
            t = 1_600_000_000 * 10**9 + k * 50_000_000
            w.write_message("/points", schema, message("lidar", 1_600_000_000 + k // 20, 1, len(pts), fields, False, 20, rec.tobytes(), True), log_time=t, publish_time=t)
        w.finish()
    print(f"wrote {out}: {count} messages of {len(pts)} points, {os.path.getsize(out)} bytes")


if __name__ == "__main__":
    main()
