#!/usr/bin/env python3
"""Statistics of a bench-v2 tree by sensor (docs/simulated-benchmark.md, "bench-v2").

    python3 tools/bench_v2_stats.py data/sim-bench-v2 [--split val]

Reads the tree's rigs.csv (each sequence's sensor, platform, height, tilt and clutter, written by
`data-jrdb synth --preset bench-v2`), the labels' point counts and the clouds' PCD headers, and
prints a Markdown table: per sensor, its sequences and frames, points per frame, people per frame
within 25 m, the median points on a person and the share holding at least 10 points by
bird's-eye range, and objects other than people (and passing vehicles) within 25 m per scene.
Only the standard library is used.
"""
import argparse
import csv
import json
import math
import statistics
from collections import defaultdict
from pathlib import Path

BANDS = [(0, 10), (10, 20), (20, 25)]


def pcd_points(path: Path) -> int:
    with open(path, "rb") as f:
        for line in f:
            if line.startswith(b"POINTS"):
                return int(line.split()[1])
            if line.startswith(b"DATA"):
                break
    raise ValueError(f"{path}: no POINTS line")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("root", type=Path)
    ap.add_argument("--split", choices=["all", "train", "val"], default="all")
    a = ap.parse_args()
    rigs = list(csv.DictReader(open(a.root / "rigs.csv")))
    if a.split != "all":
        rigs = [r for r in rigs if r["sequence"].startswith(f"sim-{a.split}-")]
    groups = defaultdict(list)
    for r in rigs:
        groups[r["sensor"]].append(r)
    groups["all"] = rigs
    print("| sensor | sequences | frames | points / frame | people ≤ 25 m / frame | median points on a person 0–10 / 10–20 / 20–25 m | ≥ 10 points 0–10 / 10–20 / 20–25 m | objects (passing vehicles) ≤ 25 m / scene | heights (m) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for sensor in sorted(groups, key=lambda s: (s == "all", s)):
        rows = groups[sensor]
        frames, points, people = 0, [], 0
        by_band = defaultdict(list)
        for r in rows:
            seq = r["sequence"]
            labels = json.load(open(a.root / "labels" / "labels_3d" / f"{seq}.json"))["labels"]
            for name, boxes in labels.items():
                frames += 1
                n = sum(pcd_points(a.root / "pointclouds" / lidar / seq / name) for lidar in ("upper_velodyne", "lower_velodyne"))
                points.append(n)
                for b in boxes:
                    rng = math.hypot(b["box"]["cx"], b["box"]["cy"])
                    for lo, hi in BANDS:
                        if lo <= rng < hi:
                            by_band[(lo, hi)].append(b["attributes"]["num_points"] if "attributes" in b else b["num_points"])
                    people += rng <= 25
        med = " / ".join(f"{statistics.median(by_band[b]):.0f}" if by_band[b] else "–" for b in BANDS)
        share = " / ".join(f"{100 * sum(p >= 10 for p in by_band[b]) / len(by_band[b]):.0f} %" if by_band[b] else "–" for b in BANDS)
        clutter = statistics.mean(int(r["clutter_25m"]) for r in rows)
        moving = statistics.mean(int(r["vehicles_moving_25m"]) for r in rows)
        heights = [float(r["height_m"]) for r in rows]
        print(
            f"| {sensor} | {len(rows)} | {frames} | {statistics.mean(points):,.0f} | {people / frames:.1f} | {med} | {share} | "
            f"{clutter:.1f} ({moving:.1f}) | {min(heights):.2f}–{max(heights):.2f} |"
        )


if __name__ == "__main__":
    main()
