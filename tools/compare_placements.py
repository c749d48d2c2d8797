#!/usr/bin/env python3
"""Paired comparison of two weights over the same placements (tools/score_placements.sh).

Every placement scores both weights on the same clouds moved the same way, so the difference per
placement is free of the placement's own luck; this prints its mean, spread and how many
placements each side wins, for AP, people found at 0.5 and false boxes a frame.

    python3 tools/compare_placements.py A/placements.txt B/placements.txt
"""
import re
import statistics
import sys

LINE = re.compile(r"^turn (\S+) x (\S+) y (\S+): AP ([\d.]+) % .*\((\d+) found\), ([\d.]+) false boxes per frame; on the platform at score >= 0.5: (\d+)")


def read(path):
    rows = {}
    with open(path) as f:
        for line in f:
            m = LINE.match(line)
            if m:
                rows[m.group(1, 2, 3)] = tuple(float(v) for v in m.group(4, 5, 6, 7))
    if not rows:
        sys.exit(f"{path}: no placement lines")
    return rows


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    a, b = read(sys.argv[1]), read(sys.argv[2])
    if a.keys() != b.keys():
        sys.exit(f"the two files score different placements ({len(a)} and {len(b)})")
    print(f"B − A over {len(a)} placements (A = {sys.argv[1]}, B = {sys.argv[2]})")
    for i, name in enumerate(["bird's-eye-centre AP %", "people found at 0.5", "false boxes a frame", "platform boxes"]):
        d = [b[k][i] - a[k][i] for k in a]
        wins, losses = sum(x > 0 for x in d), sum(x < 0 for x in d)
        sd = statistics.stdev(d) if len(d) > 1 else 0.0
        print(f"  {name}: mean {statistics.mean(d):+.2f}, sd {sd:.2f}, range {min(d):+.2f} to {max(d):+.2f}; B higher at {wins}, lower at {losses}, equal at {len(d) - wins - losses}")


if __name__ == "__main__":
    main()
