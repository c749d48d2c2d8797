#!/usr/bin/env python3
"""Writes OUT (default /tmp/rec1000.mcap): the nuScenes frame of real-scans/ (34,688 points) as a
sensor_msgs/msg/PointCloud2 on /points, N times (default 1,000) 50 ms apart, with Python's
mcap-ros2-support (its default zstd chunks): the recording docs/detect.md's speed figure uses.
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
