#!/usr/bin/env bash
# Scores `train detect` on the real scans of real-scans/ (docs/real-scans.md): detects in every
# source's clouds with every box kept (--score-threshold 0), then `eval` pools them: the official
# AP3D table and the bird's-eye-centre AP (a detection within 0.5 m of a pedestrian's centre), both
# over pedestrians within 25 m holding at least 5 points, with recall and false boxes per frame at
# the default threshold 0.5.
#
#   bash tools/score_real_scans.sh [OUT] [detect options, e.g. --run DIR]
#
# FRAME picks how each cloud is placed in the base frame:
#   default  detect's defaults: the height and tilt found from each scan's ground (`--transform
#            auto`), nothing told about the sources (what a new user gets);
#   auto     the same, told only what the ground cannot say: nuScenes' y axis points forward and
#            Argoverse's vehicle frame has its origin 1.35 m behind the LiDAR;
#   given    each sensor's measured pose written below.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/real-scans}
shift || true
declare -A pose=(
    [sustechpoints]="z=0.8"            # 40-beam spinning LiDAR about 1.5 m up, x forward
    [nuscenes]="yaw=-90,z=1.14"        # HDL-32E 1.84 m up, x right and y forward
    [argoverse2]="x=-1.35,z=-0.33"     # the vehicle frame: rear axle, road at z = -0.37, LiDAR 1.35 m ahead
)
case "${FRAME:-default}" in
    default) pose=([sustechpoints]="auto" [nuscenes]="auto" [argoverse2]="auto") ;;
    auto) pose=([sustechpoints]="auto" [nuscenes]="auto,yaw=-90" [argoverse2]="auto,x=-1.35") ;;
    given) ;;
    *) echo "FRAME must be default, auto or given" >&2; exit 2 ;;
esac
rm -rf "$out"
for source in sustechpoints nuscenes argoverse2; do
    cargo run -q -p train -- detect "real-scans/$source" --transform "${pose[$source]}" --score-threshold 0 --out "$out/$source" "$@" >/dev/null
    mkdir -p "$out/det/$source"
    cp "$out/$source"/kitti/*.txt "$out/det/$source/"
done
cargo run -q -p eval -- --gt real-scans/gt --det "$out/det" --min-points 5 --centre-radius 0.5 --at-score 0.5
