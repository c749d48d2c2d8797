#!/usr/bin/env bash
# AP3D on the validation sequences of a bench-v2 tree seen by its sparse rigs (VLP-16, two VLP-16,
# HDL-32E; `rigs.csv`), from what `train infer --split val --out DIR` wrote: the sim-side check
# that weights find people as sparse as a 16- or 32-beam sensor's.
#
#   bash tools/eval_sparse_rigs.sh INFER_OUT [BENCH_V2_ROOT (default data/sim-bench-v2-seed7)]
set -euo pipefail
cd "$(dirname "$0")/.."
infer=$1
root=${2:-data/sim-bench-v2-seed7}
sub=$(mktemp -d)
trap 'rm -rf "$sub"' EXIT
mkdir -p "$sub/gt" "$sub/det"
n=0
for seq in $(awk -F, '$1 ~ /^sim-val/ && ($2 == "hdl32e" || $2 == "vlp16" || $2 == "2x vlp16") {print $1}' "$root/rigs.csv"); do
    [[ -d $infer/kitti_gt/$seq && -d $infer/kitti/$seq ]] || { echo "$infer has no $seq: infer on $root first" >&2; exit 1; }
    cp -r "$infer/kitti_gt/$seq" "$sub/gt/"
    cp -r "$infer/kitti/$seq" "$sub/det/"
    n=$((n + 1))
done
echo "$n sequences of 16- and 32-beam rigs in $root"
cargo run -q -p eval -- --gt "$sub/gt" --det "$sub/det"
