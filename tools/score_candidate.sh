#!/usr/bin/env bash
# Scores a trained run as every candidate for the shipped weights is scored (docs/real-scans.md,
# docs/results/real_scans_turns/): fits the run's radial shift on simulated frames it was not
# trained on and its facing stage (both written into the run folder), then the real scans with
# detect's defaults at the four quarter turns (and their mean), with FRAME=auto and FRAME=given,
# each pedestrian's score per turn, both simulated benchmarks' validation splits (seed 7) and
# bench-v2's sparse rigs.
#
#   bash tools/score_candidate.sh RUN OUT
#
# Needs the binaries built (cargo build -p train -p eval -p data-jrdb) and the seed-7 trees:
#   target/debug/data-jrdb synth --preset bench-v1 --seed 7 --out data/sim-bench-v1-seed7
#   target/debug/data-jrdb synth --preset bench-v2 --seed 7 --out data/sim-bench-v2-seed7
# Five to seven minutes on 2 cores. OUT/summary.txt holds the figures the shipping rules compare.
set -euo pipefail
cd "$(dirname "$0")/.."
run=${1:?usage: score_candidate.sh RUN OUT}
out=${2:?usage: score_candidate.sh RUN OUT}
for tree in data/sim-bench-v1-seed7 data/sim-bench-v2-seed7; do
    [[ -d $tree ]] || { echo "score_candidate: $tree is missing (see the header for how to make it)" >&2; exit 2; }
done
mkdir -p "$out"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
FRAME=default bash tools/score_real_scans.sh "$work/before" --run "$run" > "$out/real-scans-default-before-shift-and-facing.txt" 2>&1
target/debug/train calibrate --run "$run" --data-root data/sim-bench-v2-seed7 --write > "$out/calibrate-bench-v2-seed7.txt" 2>&1
target/debug/train facing --run "$run" --write > "$out/facing.txt" 2>&1
for t in 0 90 180 270; do
    TURN=$t bash tools/score_real_scans.sh "$work/turn-$t" --run "$run" > "$out/real-scans-default-turn-$t.txt" 2>&1
done
python3 tools/real_scans_per_person.py "0°=$work/turn-0" "90°=$work/turn-90" "180°=$work/turn-180" "270°=$work/turn-270" > "$out/per-person.txt" 2>&1
FRAME=auto bash tools/score_real_scans.sh "$work/auto" --run "$run" > "$out/real-scans-auto.txt" 2>&1
FRAME=given bash tools/score_real_scans.sh "$work/given" --run "$run" > "$out/real-scans-given.txt" 2>&1
for v in 1 2; do
    target/debug/train infer --run "$run" --data-root "data/sim-bench-v$v-seed7" --split val --out "$work/infer-v$v" > "$work/infer-v$v.log" 2>&1
    mkdir -p "$out/bench-v$v-seed7-val"
    cp "$work/infer-v$v"/eval.* "$out/bench-v$v-seed7-val/"
done
bash tools/eval_sparse_rigs.sh "$work/infer-v2" > "$out/bench-v2-seed7-sparse-rigs.txt" 2>&1
python3 - "$out" > "$out/summary.txt" <<'EOF'
import re, sys
out = sys.argv[1]
pat = re.compile(r"bird's-eye centre.*AP ([\d.]+) % over (\d+) people; at score >= 0.5: recall [\d.]+ % \((\d+) found\), ([\d.]+) false boxes per frame")
def pooled(name):
    text = open(f"{out}/{name}").read()
    m = pat.search(text)
    plat = re.search(r"boxes on the platform at score >= 0.5: (\d+)", text)
    return float(m[1]), int(m[3]), float(m[4]), int(m[2]), int(plat[1]) if plat else None
print("real scans, bird's-eye-centre AP % / people found at 0.5 / false boxes a frame / platform boxes")
turns = []
for t in (0, 90, 180, 270):
    ap, found, fp, people, plat = pooled(f"real-scans-default-turn-{t}.txt")
    turns.append((ap, found, fp))
    print(f"  default, turn {t:>3}°: {ap:.1f} / {found} of {people} / {fp:.2f} / {plat}")
n = len(turns)
print(f"  default, mean of the four turns: {sum(t[0] for t in turns)/n:.1f} / {sum(t[1] for t in turns)/n:.2f} / {sum(t[2] for t in turns)/n:.2f}")
for frame in ("auto", "given"):
    ap, found, fp, people, plat = pooled(f"real-scans-{frame}.txt")
    print(f"  FRAME={frame}: {ap:.1f} / {found} of {people} / {fp:.2f} / {plat}")
for v in (1, 2):
    line = next(l for l in open(f"{out}/bench-v{v}-seed7-val/eval.txt") if l.startswith("0.3"))
    print(f"bench-v{v} seed 7 validation AP3D@0.3: {line.split()[1]}")
line = next(l for l in open(f"{out}/bench-v2-seed7-sparse-rigs.txt") if l.startswith("0.3"))
print(f"bench-v2 seed 7 sparse rigs AP3D@0.3: {line.split()[1]}")
EOF
cat "$out/summary.txt"
