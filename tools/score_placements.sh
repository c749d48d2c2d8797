#!/usr/bin/env bash
# Scores weights on the real scans over many placements of the same clouds on the voxel lattice:
# detect's defaults (FRAME=default) at the four quarter turns, each with the cloud moved by every
# shift of a 4 × 4 grid of 0, 0.1, 0.2 and 0.3 m in x and y (64 placements). A shift of a few
# decimetres is below what anyone knows of a sensor's position, yet it moves one set of weights by
# several people (docs/results/real_scans_turns/shifts/), so a comparison of weights on these 23
# people is made on the placements' mean and spread, not on one placement.
#
#   bash tools/score_placements.sh OUT [detect options, e.g. --run DIR]
#
# OUT/placements.txt: one line per placement (bird's-eye-centre AP, people found at 0.5, false
# boxes a frame, boxes on the platform); OUT/per-person.txt: each pedestrian's best score at every
# placement (tools/real_scans_per_person.py); OUT/summary.txt: mean, standard deviation and range
# over the placements, and how often each pedestrian is found. About 2 s a placement on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: score_placements.sh OUT [detect options]}
shift
mkdir -p "$out"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
: > "$out/placements.txt"
columns=()
for turn in 0 90 180 270; do
    for x in 0 0.1 0.2 0.3; do
        for y in 0 0.1 0.2 0.3; do
            name="turn-$turn-x-$x-y-$y"
            FRAME=default TURN=$turn SHIFT="$x,$y" bash tools/score_real_scans.sh "$work/$name" "$@" > "$work/$name.txt" 2>&1 \
                || { echo "score_placements: $name failed:" >&2; tail -5 "$work/$name.txt" >&2; exit 1; }
            pooled=$(grep "^bird's-eye centre" "$work/$name.txt")
            platform=$(grep "^boxes on the platform" "$work/$name.txt")
            echo "turn $turn x $x y $y: ${pooled#*metric): }; ${platform#boxes }" >> "$out/placements.txt"
            columns+=("$turn/$x/$y=$work/$name")
        done
    done
done
python3 tools/real_scans_per_person.py "${columns[@]}" > "$out/per-person.txt"
python3 tools/placements.py summary "$out" > "$out/summary.txt"
cat "$out/summary.txt"
