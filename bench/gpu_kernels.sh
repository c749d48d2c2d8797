#!/usr/bin/env bash
# Device time of each GPU kernel of the sparse conv on the standard scene, with its TFLOP/s, from
# CubeCL's profiler (which synchronises and times every kernel launch, so the figures are each
# kernel alone, without Burn's host work between launches).
#
#   bash bench/gpu_kernels.sh [CHANNELS] [SCALE] [COORDS]     (defaults: 128 1 bench/scene_jrdb_like.npy)
#
# Needs a GPU on a native graphics API (Vulkan, Metal, DX12). Extra arguments after the three go
# to the benchmark binary: `--gpu-tiled-min-cubes 0` times the tiled gather at every size.
set -euo pipefail
channels=${1:-128}
scale=${2:-1}
root=$(cd "$(dirname "$0")/.." && pwd)
coords=$(realpath "${3:-$root/bench/scene_jrdb_like.npy}")
shift $(( $# < 3 ? $# : 3 ))
bench=${SPARSE_CONV_BENCH:-}   # a prebuilt benchmark binary, else it is built here
if [ -z "$bench" ]; then
    (cd "$root" && cargo build -q -p bench --bin sparse-conv-bench)
    bench=$root/target/debug/sparse-conv-bench
fi
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
printf '[profiling]\nlogger = { level = "basic", file = "%s/prof.log", append = false }\n' "$dir" > "$dir/cubecl.toml"
# CubeCL reads cubecl.toml from the working directory.
(cd "$dir" && "$bench" --backend wgpu --coords "$coords" --channels "$channels" \
    --scale "$scale" --runs 5 --warmup 2 --queue 5 --matmul-size 256 --skip-strided "$@" > bench.txt)
pairs=$(grep -o '[0-9]* pairs' "$dir/bench.txt" | head -1 | cut -d' ' -f1)
echo "C_in = C_out = $channels, scene x$scale: $pairs pairs; 2·pairs·C² = $(awk -v p="$pairs" -v c="$channels" 'BEGIN{printf "%.2f", 2*p*c*c/1e9}') GFLOP per conv kernel"
grep "^| [0-9]" "$dir/prof.log" | awk -F'|' -v p="$pairs" -v c="$channels" '
    { name = $3; gsub(/^ +| +$/, "", name); d = $2; gsub(/ /, "", d); v = d + 0
      if (d ~ /µs/) v /= 1000; else if (d ~ /ns/) v /= 1e6; else if (d !~ /ms/ && d ~ /s$/) v *= 1000
      total[name] += v; calls[name]++ }
    END { for (n in total) {
            ms = total[n] / calls[n]
            conv = (n ~ /GatherConvKernel|DirectGatherKernel|WeightGradKernel/)
            printf "%-32s %5d calls %9.4f ms/call %s\n", substr(n, 1, 32), calls[n], ms, conv ? sprintf("%6.1f TFLOP/s", 2 * p * c * c / ms / 1e9) : ""
          } }' | sort -k4 -rn | grep -v Throughput | head -8
