#!/usr/bin/env python3
"""Reads what tools/score_placements.sh writes: one line per placement of the real scans.

    python3 tools/placements.py summary OUT        # OUT/placements.txt and OUT/per-person.txt: mean, sd, range
    python3 tools/placements.py compare A/placements.txt B/placements.txt

`compare` is paired: every placement scores both weights on the same clouds moved the same way,
so the difference per placement is free of the placement's own luck; it prints its mean, spread
and how many placements each side wins, for AP, people found at 0.5, false boxes a frame and
platform boxes.
"""
import os
import re
import statistics
import sys

# The line score_placements.sh writes: "turn T x X y Y: AP … % over N people; … (K found), F false
# boxes per frame; on the platform at score >= 0.5: P" (or at the AT_SCORE it was run with).
LINE = re.compile(r"^turn (\S+) x (\S+) y (\S+): AP ([\d.]+) % over (\d+) people; at score >= [\d.]+: recall [\d.]+ % \((\d+) found\), ([\d.]+) false boxes per frame; on the platform at score >= [\d.]+: (\d+)")
FIGURES = ["bird's-eye-centre AP %", f"people found at {os.environ.get('AT_SCORE', '0.5')}", "false boxes a frame", "platform boxes"]


def read(path):
    """{(turn, x, y): (AP, found, false boxes a frame, platform boxes)} and the number of people."""
    rows, people = {}, None
    with open(path) as f:
        for line in f:
            m = LINE.match(line)
            if m:
                rows[m.group(1, 2, 3)] = tuple(float(v) for v in m.group(4, 6, 7, 8))
                people = int(m[5])
    if not rows:
        sys.exit(f"{path}: no placement lines")
    return rows, people


def summary(out):
    rows, people = read(f"{out}/placements.txt")
    ap, found, fp, plat = zip(*rows.values())

    def line(name, v, fmt):
        return f"{name}: mean {statistics.mean(v):{fmt}}, sd {statistics.stdev(v):{fmt}}, range {min(v):{fmt}}–{max(v):{fmt}}"

    print(f"{len(rows)} placements (4 quarter turns × 16 shifts of 0–0.3 m), {people} people")
    print(line(FIGURES[0], ap, ".1f"))
    print(line(FIGURES[1], found, ".2f"))
    print(line(FIGURES[2], fp, ".2f"))
    print(f"boxes on the platform: {int(sum(plat))} over all placements")
    per = [l for l in open(f"{out}/per-person.txt") if not l.startswith(("source ", "found at"))]
    rates = sorted((l.count("*") / len(rows), "  ".join(l.split()[:4])) for l in per)
    print(f"pedestrians found in at least half the placements: {sum(r >= 0.5 for r, _ in rates)} of {len(rates)}; "
          f"in every one: {sum(r == 1 for r, _ in rates)}; in none: {sum(r == 0 for r, _ in rates)}")
    for r, who in rates:
        print(f"  {r:5.0%}  {who}")
    print("(source, frame, range in m, points)")


def compare(path_a, path_b):
    (a, _), (b, _) = read(path_a), read(path_b)
    if a.keys() != b.keys():
        sys.exit(f"the two files score different placements ({len(a)} and {len(b)})")
    print(f"B − A over {len(a)} placements (A = {path_a}, B = {path_b})")
    for i, name in enumerate(FIGURES):
        d = [b[k][i] - a[k][i] for k in a]
        wins, losses = sum(x > 0 for x in d), sum(x < 0 for x in d)
        sd = statistics.stdev(d) if len(d) > 1 else 0.0
        print(f"  {name}: mean {statistics.mean(d):+.2f}, sd {sd:.2f}, range {min(d):+.2f} to {max(d):+.2f}; B higher at {wins}, lower at {losses}, equal at {len(d) - wins - losses}")


def main():
    match sys.argv[1:]:
        case ["summary", out]:
            summary(out)
        case ["compare", a, b]:
            compare(a, b)
        case _:
            sys.exit(__doc__)


if __name__ == "__main__":
    main()
