#!/usr/bin/env bash
# Copies a sweep's tables and its finished runs' small files from runs/NAME into docs/results/NAME
# (results.md, results.csv, curves.png; per run config.toml, summary.json, epochs.csv; no
# checkpoints), so that the figures live in the repository and `train sweep` can skip those runs
# after they are copied back (docs/results/README.md).
#   tools/sync_results.sh compare
set -euo pipefail
cd "$(dirname "$0")/.."
name=${1:?usage: tools/sync_results.sh SWEEP_NAME}
src=runs/$name
dst=docs/results/$name
[ -d "$src" ] || { echo "no sweep folder $src" >&2; exit 1; }
mkdir -p "$dst"
for f in results.md results.csv curves.png; do
    [ -f "$src/$f" ] && cp "$src/$f" "$dst/"
done
for run in "$src"/*/seed-*; do
    [ -f "$run/summary.json" ] || continue
    grep -q '"finished": *true' "$run/summary.json" || continue
    out=$dst/${run#"$src"/}
    mkdir -p "$out"
    for f in config.toml summary.json epochs.csv; do
        [ -f "$run/$f" ] && cp "$run/$f" "$out/"
    done
    echo "copied $run"
done
