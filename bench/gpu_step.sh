#!/usr/bin/env bash
# Where a full-width Person-MinkUNet's step goes on a GPU, for wgpu and CUDA in one run (issue 48's
# yardstick): the batch-2 training step and one-frame inference on the standard scene with the
# host's parts of the op (kernel maps, tile plans, uploads, dispatch), with the levels, maps and
# tile plans made on the host (`--gpu-maps host`, the path before) and on the device, the batch-16 step's frames
# per second against batch 2's, then one profiled batch-2 step whose kernels CubeCL times one by
# one (each synchronised, so that run is slower; it gives the device time by kernel family, and
# against the unprofiled step how busy the GPU is).
#
#   bash bench/gpu_step.sh [BACKENDS]      (default: "wgpu cuda"; MODEL_BENCH=path/to/model-bench)
#
# For a trial of the script itself on a small machine: RUNS (timed runs, default 10), LARGE_BATCH
# (default 16) and MODEL_BENCH_ARGS (added to every call, e.g. "--width 0.125").
#
# Build the binary where Cargo is (nothing large is built here):
#   cargo build -p bench --bin model-bench --features cuda
# and carry target/debug/model-bench and bench/scene_jrdb_like.npy to the GPU machine. A backend
# the machine cannot run prints its error and the script goes on.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
backends=${1:-wgpu cuda}
bench=${MODEL_BENCH:-$root/target/debug/model-bench}
runs=${RUNS:-10}
large=${LARGE_BATCH:-16}
read -r -a extra <<< "${MODEL_BENCH_ARGS:-}"
scene=$root/bench/scene_jrdb_like.npy
[ -x "$bench" ] || { echo "no model-bench at $bench (MODEL_BENCH=…, or build it as above)" >&2; exit 2; }
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
for backend in $backends; do
    echo "== $backend"
    "$bench" --backend "$backend" --coords "$scene" --batch 1 --only infer --runs "$runs" --warmup 3 "${extra[@]}" || continue
    # Before device maps, for the same run's ratio: levels, maps and tile plans made on the host
    # and uploaded.
    echo "-- maps and plans made on the host (--gpu-maps host):"
    "$bench" --backend "$backend" --coords "$scene" --batch 1 --only infer --runs "$runs" --warmup 3 --gpu-maps host "${extra[@]}"
    "$bench" --backend "$backend" --coords "$scene" --batch 2 --only train --runs "$runs" --warmup 3 --gpu-maps host "${extra[@]}"
    echo "-- made on the device (the default):"
    "$bench" --backend "$backend" --coords "$scene" --batch 2 --only train --runs "$runs" --warmup 3 "${extra[@]}" | tee "$dir/b2.txt"
    "$bench" --backend "$backend" --coords "$scene" --batch "$large" --only train --runs $(( (runs + 1) / 2 )) --warmup 2 "${extra[@]}" | tee "$dir/b16.txt"
    b2=$(grep -o 'training step *[0-9.]*' "$dir/b2.txt" | awk '{print $3}')
    b16=$(grep -o 'training step *[0-9.]*' "$dir/b16.txt" | awk '{print $3}')
    awk -v a="$b2" -v b="$b16" -v n="$large" 'BEGIN { if (a > 0 && b > 0) printf "  frames/s: batch 2 %.1f, batch %d %.1f (%.2fx)\n", 2000 / a, n, 1000 * n / b, (1000 * n / b) / (2000 / a) }'
    # CubeCL reads cubecl.toml from the working directory.
    printf '[profiling]\nlogger = { level = "basic", file = "%s/prof-%s.log", append = false }\n' "$dir" "$backend" > "$dir/cubecl.toml"
    profiled=3
    (cd "$dir" && "$bench" --backend "$backend" --coords "$scene" --batch 2 --only train --runs $profiled --warmup 0 "${extra[@]}" > /dev/null)
    grep "^| [0-9]" "$dir/prof-$backend.log" | awk -F'|' -v runs=$profiled -v step="$b2" '
        { name = $3; gsub(/^ +| +$/, "", name); d = $2; gsub(/ /, "", d); v = d + 0
          if (d ~ /µs/) v /= 1000; else if (d ~ /ns/) v /= 1e6; else if (d !~ /ms/ && d ~ /s$/) v *= 1000
          family = (name ~ /GatherConv|DirectGather/) ? "op: gather (fwd, feature grad)" \
                 : (name ~ /WeightGrad|SumSlices/) ? "op: weight grad" \
                 : (name ~ /Adam/) ? "Adam" \
                 : (name ~ /FillKernel|HashInsert|SubmanifoldTable|Pair(Count|Scan|Scatter)|ParentInsert|OwnerCount|NumberKernel|DownTable|RowMask|Digit(Count|Scatter)|Tile(Mask|Offsets)/) ? "op: levels, maps, tile plans" \
                 : (name ~ /[Mm]atmul/) ? "Burn: matmul" : "Burn: the rest (elementwise, reductions, fused)"
          total[family] += v; all += v }
        END { printf "  device time per step by kernel family (%d profiled steps incl. the first, each kernel synchronised):\n", runs
              for (f in total) printf "    %-48s %8.2f ms\n", f, total[f] / runs
              printf "    %-48s %8.2f ms = %.0f %% of the unprofiled step (%.1f ms)\n", "all kernels", all / runs, 100 * all / runs / step, step }'
done
