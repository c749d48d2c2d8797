#!/usr/bin/env bash
# Scores `train detect` on the real scans of real-scans/ (docs/real-scans.md): detects in every
# source's clouds with every box kept (--score-threshold 0), then `eval` pools them: the official
# AP3D table and the bird's-eye-centre AP (a detection within 0.5 m of a pedestrian's centre), both
# over pedestrians within 25 m holding at least 5 points, with recall and false boxes per frame at
# the default threshold 0.5 (AT_SCORE sets another: the threshold a run's fused scores are read at).
#
#   bash tools/score_real_scans.sh [OUT] [detect options, e.g. --run DIR]
#
# FRAME picks how each cloud is placed in the base frame:
#   default  detect's defaults: the height and tilt found from each scan's ground (`--transform
#            auto`), nothing told about the sources (what a new user gets);
#   auto     the same, told only what the ground cannot say: nuScenes' y axis points forward and
#            Argoverse's vehicle frame has its origin 1.35 m behind the LiDAR;
#   given    each sensor's measured pose written below.
#
# TURN (degrees, default 0; only with FRAME=default) turns every cloud about the vertical axis
# before detect sees it (`--transform auto,yaw=TURN`); the boxes come back in the cloud's own
# frame, so the same ground truth scores them. A quarter turn maps the voxel grid onto itself: the
# figures under the four quarter turns are the yardstick's spread for one set of weights
# (docs/results/real_scans_turns/).
#
# SHIFT ("x,y" in metres, default none; only with FRAME=default) moves every cloud after the turn
# (`--transform auto,yaw=TURN,x=…,y=…`), so it falls elsewhere on the voxel lattice; the boxes come
# back in the cloud's own frame. tools/score_placements.sh averages over turns and shifts.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/real-scans}
shift || true
declare -A pose=(
    [sustechpoints]="z=0.8"            # 40-beam spinning LiDAR about 1.5 m up, x forward
    [nuscenes]="yaw=-90,z=1.14"        # HDL-32E 1.84 m up, x right and y forward
    [argoverse2]="x=-1.35,z=-0.33"     # the vehicle frame: rear axle, road at z = -0.37, LiDAR 1.35 m ahead
)
turn=${TURN:-0}
at_score=${AT_SCORE:-0.5}
if [[ $turn != 0 && ${FRAME:-default} != default ]]; then
    echo "TURN is only given with FRAME=default" >&2
    exit 2
fi
shift_xy=""
if [[ -n ${SHIFT:-} ]]; then
    if [[ ${FRAME:-default} != default || ! $SHIFT =~ ^-?[0-9.]+,-?[0-9.]+$ ]]; then
        echo "SHIFT is \"x,y\" in metres, only with FRAME=default" >&2
        exit 2
    fi
    shift_xy=",x=${SHIFT%,*},y=${SHIFT#*,}"
fi
case "${FRAME:-default}" in
    default) pose=([sustechpoints]="auto,yaw=$turn$shift_xy" [nuscenes]="auto,yaw=$turn$shift_xy" [argoverse2]="auto,yaw=$turn$shift_xy") ;;
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
cargo run -q -p eval -- --gt real-scans/gt --det "$out/det" --min-points 5 --centre-radius 0.5 --at-score "$at_score"
# The same bird's-eye-centre figures per source.
for source in sustechpoints nuscenes argoverse2; do
    mkdir -p "$out/one/$source/gt" "$out/one/$source/det"
    cp -r "real-scans/gt/$source" "$out/one/$source/gt/"
    cp -r "$out/det/$source" "$out/one/$source/det/"
    line=$(cargo run -q -p eval -- --gt "$out/one/$source/gt" --det "$out/one/$source/det" --min-points 5 --centre-radius 0.5 --at-score "$at_score" | tail -1)
    echo "$source: ${line#*metric): }"
done
# Boxes on the platform: detections at the threshold (AT_SCORE) whose centre lies within the car
# carrying the sensor (all three sources are cars), taken as 2.6 m ahead and behind the LiDAR and
# 1.1 m to either side (Argoverse's clouds are in the vehicle frame, the LiDAR 1.35 m ahead of
# its origin; nuScenes' y axis points forward).
python3 - "$out" "$at_score" <<'PY'
import glob, json, math, sys
lidar = {"sustechpoints": (0.0, 0.0, 0.0), "nuscenes": (0.0, 0.0, math.pi / 2), "argoverse2": (1.35, 0.0, 0.0)}
on = []
for source, (lx, ly, fwd) in lidar.items():
    for f in sorted(glob.glob(f"{sys.argv[1]}/{source}/json/*.json")):
        for d in json.load(open(f))["detections"]:
            if d["score"] < float(sys.argv[2]):
                continue
            dx, dy = d["x"] - lx, d["y"] - ly
            along, across = dx * math.cos(fwd) + dy * math.sin(fwd), -dx * math.sin(fwd) + dy * math.cos(fwd)
            if abs(along) <= 2.6 and abs(across) <= 1.1:
                on.append(f"{source}/{f.rsplit('/', 1)[1]} ({d['x']:.1f}, {d['y']:.1f}) score {d['score']:.2f}")
print(f"boxes on the platform at score >= {sys.argv[2]}: {len(on)}" + "".join(f"\n  {o}" for o in on))
PY
