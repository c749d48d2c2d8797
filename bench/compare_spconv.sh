#!/usr/bin/env bash
# Side-by-side CPU benchmark: spconv 2.3.8 (the peer) against pmunet's flex and ndarray backends, on
# one voxel scene, at one thread count, back to back; then one markdown table.
#
#   bash bench/compare_spconv.sh [--install] [--threads 2] [--runs 10] [--warmup 2]
#                                [--model-runs 3] [--model-warmup 1] [--backends flex,ndarray]
#                                [--rounds 1] [--scene FILE.npy] [--out DIR] [--quick] [--isa avx2]
#
#   --install       create the peer's venv ($PMUNET_PEER_VENV, default ~/.cache/spconv-peer) with
#                   torch 2.5.1, numpy 1.26.4 and spconv 2.3.8 if it is absent (~2.5 min, ~5 GB).
#   --threads N     threads of every process (torch/OpenMP for the peer, rayon for pmunet); default 2.
#   --runs N        timed runs of each conv figure (default 10; 2 with --quick); --warmup N (default 2; 1).
#   --model-runs N  timed runs of each MinkUNet figure (default 3), --model-warmup N (default 1).
#   --backends L    pmunet backends, comma-separated (default flex,ndarray).
#   --rounds N      run every step N times, interleaved (round r in DIR/round<r>/, the peer first in
#                   odd rounds and last in even ones); the table gives each figure's median over the
#                   rounds and each ratio's median and range over the rounds' own ratios, so both
#                   sides of a ratio are measured in the same minutes (default 1).
#   --scene FILE    int32 N×4 .npy (default bench/scene_jrdb_like.npy from the repo root).
#   --out DIR       results folder (default bench/results/<date-time>/).
#   --quick         few runs and no MinkUNet: a test of the scripts, not a measurement.
#   --isa avx2      cap both sides at AVX2 + FMA on a CPU that has AVX-512 (an AVX2 machine's code
#                   paths, not its speed): pmunet with --cpu-kernels avx2, the peer with
#                   ATEN_CPU_CAPABILITY=avx2, MKL_ENABLE_INSTRUCTIONS=AVX2, ONEDNN_MAX_CPU_ISA=AVX2.
#                   Default: each side's widest (`native`).
#
# Steps (each writes <name>.json, <name>.log = stderr, <name>.rc = exit status into the results folder,
# or into its round<r>/ folder with --rounds):
#   spconv                 bench/peer_spconv.py (parts gemm,convs,crosscheck[,minkunet])
#   pmunet_conv_<b>        cargo run -p bench --bin sparse-conv-bench -- --coords S --backend b ... --json
#   pmunet_model_<b>_b1    cargo run -p bench --bin model-bench -- --model person_minkunet ... --batch 1 --only infer
#                          --json (its forward_ms = inference of one frame)
#   pmunet_model_<b>_b2    the same with --batch 2 --only train (train_step_ms, peak_train_mib)
# then bench/compare_table.py prints the table and writes table.md.
# cargo runs with the default (dev) profile and no extra features, so the build in target/ is reused.
set -uo pipefail

usage() { sed -n '2,31p' "$0" | sed 's/^# \{0,1\}//'; }
die() { echo "compare_spconv.sh: $*" >&2; exit 2; }

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT" || die "cannot cd to $ROOT"

INSTALL=0 QUICK=0 THREADS=2 RUNS="" WARMUP="" MODEL_RUNS=3 MODEL_WARMUP=1 BACKENDS=flex,ndarray ROUNDS=1
SCENE=bench/scene_jrdb_like.npy OUT="" ISA=native
VENV=${PMUNET_PEER_VENV:-$HOME/.cache/spconv-peer}

need() { [[ $# -ge 2 && -n $2 ]] || die "$1 needs a value"; }
posint() { [[ $2 =~ ^[0-9]+$ ]] || die "$1 wants a whole number, got '$2'"; }
while [[ $# -gt 0 ]]; do
    case $1 in
        --install) INSTALL=1; shift ;;
        --quick) QUICK=1; shift ;;
        --threads) need "$@"; posint "$1" "$2"; THREADS=$2; shift 2 ;;
        --runs) need "$@"; posint "$1" "$2"; RUNS=$2; shift 2 ;;
        --warmup) need "$@"; posint "$1" "$2"; WARMUP=$2; shift 2 ;;
        --model-runs) need "$@"; posint "$1" "$2"; MODEL_RUNS=$2; shift 2 ;;
        --model-warmup) need "$@"; posint "$1" "$2"; MODEL_WARMUP=$2; shift 2 ;;
        --backends) need "$@"; BACKENDS=$2; shift 2 ;;
        --rounds) need "$@"; posint "$1" "$2"; ROUNDS=$2; shift 2 ;;
        --scene) need "$@"; SCENE=$2; shift 2 ;;
        --isa) need "$@"; [[ $2 == avx2 || $2 == native ]] || die "--isa takes avx2 or native, got '$2'"; ISA=$2; shift 2 ;;
        --out) need "$@"; OUT=$2; shift 2 ;;
        -h|--help) usage; exit 0 ;;
        *) die "unknown argument '$1' (see --help)" ;;
    esac
done
[[ $THREADS -ge 1 ]] || die "--threads must be at least 1 (pmunet's 0 = all cores has no spconv twin)"
if [[ $QUICK == 1 ]]; then RUNS=${RUNS:-2}; WARMUP=${WARMUP:-1}; else RUNS=${RUNS:-10}; WARMUP=${WARMUP:-2}; fi
[[ $RUNS -ge 1 && $MODEL_RUNS -ge 1 && $ROUNDS -ge 1 ]] || die "--runs, --model-runs and --rounds must be at least 1"
IFS=, read -r -a BACKEND_LIST <<< "$BACKENDS"
for b in "${BACKEND_LIST[@]}"; do
    [[ $b == flex || $b == ndarray ]] || die "--backends: '$b' is not flex or ndarray"
done

# One comparison at a time on a machine: two at once share its cores and skew both sets of figures
# without either noticing. The lock lasts as long as this script (and goes with it if it dies).
LOCK=${TMPDIR:-/tmp}/pmunet-compare-spconv.lock
if command -v flock > /dev/null && { [[ -e $LOCK ]] || : > "$LOCK"; } 2> /dev/null && { exec 9< "$LOCK"; } 2> /dev/null; then
    flock -n 9 || die "another compare_spconv.sh is running on this machine (it holds $LOCK); wait for it to finish: two at once skew each other's figures"
else
    echo "[compare] warning: cannot lock $LOCK (no flock, or no access), so a second comparison started now would not be stopped" >&2
fi

[[ -f $SCENE ]] || die "scene file '$SCENE' not found (give --scene FILE.npy)"
SCENE=$(cd "$(dirname "$SCENE")" && pwd)/$(basename "$SCENE")
command -v cargo > /dev/null || die "cargo not found"

# --- the peer's venv --------------------------------------------------------------------------
PY=$VENV/bin/python
peer_ok() { [[ -x $PY ]] && "$PY" -c 'import torch, numpy, spconv' > /dev/null 2>&1; }
if ! peer_ok; then
    if [[ $INSTALL == 1 ]]; then
        echo "[compare] creating the spconv venv in $VENV (torch 2.5.1, numpy 1.26.4, spconv 2.3.8) ..."
        [[ -x $PY ]] || python3 -m venv "$VENV" || die "python3 -m venv $VENV failed"
        "$VENV/bin/pip" install torch==2.5.1 numpy==1.26.4 spconv==2.3.8 || die "pip install failed"
        peer_ok || die "the venv in $VENV still cannot import torch, numpy and spconv"
    else
        die "no usable spconv venv at $VENV (python with torch, numpy, spconv); run with --install, or set PMUNET_PEER_VENV"
    fi
elif [[ $INSTALL == 1 ]]; then
    echo "[compare] spconv venv already present in $VENV; not reinstalling"
fi
PEER_VERSIONS=$("$PY" -c 'import torch, numpy, spconv; print(f"torch {torch.__version__}, numpy {numpy.__version__}, spconv {spconv.__version__}")' 2> /dev/null)
[[ $PEER_VERSIONS == *"spconv 2.3.8"* ]] || echo "[compare] warning: the peer venv has $PEER_VERSIONS, not spconv 2.3.8" >&2

# --- results folder ---------------------------------------------------------------------------
STAMP=$(date +%Y%m%d-%H%M%S)
RES=${OUT:-bench/results/$STAMP}
mkdir -p "$RES" || die "cannot create $RES"
RES=$(cd "$RES" && pwd)
{
    echo "date=$(date '+%Y-%m-%d %H:%M:%S %Z')"
    echo "scene=$SCENE"
    echo "threads=$THREADS"
    echo "runs=$RUNS"
    echo "warmup=$WARMUP"
    echo "model_runs=$MODEL_RUNS"
    echo "model_warmup=$MODEL_WARMUP"
    echo "backends=$BACKENDS"
    echo "rounds=$ROUNDS"
    echo "quick=$QUICK"
    echo "isa=$ISA"
    echo "cpu_flags=$(grep -o -w 'avx512f\|avx2\|fma' /proc/cpuinfo 2> /dev/null | sort -u | tr '\n' ' ')"
    echo "peer=$PEER_VERSIONS"
    echo "git_head=$(git rev-parse --short HEAD 2> /dev/null || echo '?')"
    echo "load_before=$(cut -d' ' -f1-3 /proc/loadavg 2> /dev/null)"
} > "$RES/meta.txt"
echo "[compare] results in $RES"
echo "[compare] $THREADS threads, $RUNS runs + $WARMUP warm-ups per conv figure$([[ $QUICK == 1 ]] && echo ', quick: no MinkUNet' || echo ", MinkUNet $MODEL_RUNS runs + $MODEL_WARMUP warm-ups")"
read -r LOAD1 _ < /proc/loadavg 2> /dev/null && echo "[compare] load average now: $LOAD1 (on $(nproc) CPUs; other work skews the figures)"

export OMP_NUM_THREADS=$THREADS MKL_NUM_THREADS=$THREADS RAYON_NUM_THREADS=$THREADS
PMUNET_ISA=()
if [[ $ISA == avx2 ]]; then
    export ATEN_CPU_CAPABILITY=avx2 MKL_ENABLE_INSTRUCTIONS=AVX2 ONEDNN_MAX_CPU_ISA=AVX2
    PMUNET_ISA=(--cpu-kernels avx2)
    echo "[compare] both sides capped at AVX2 + FMA"
fi

FAILED=0
DIR=$RES  # where step() writes: the results folder, or the round's folder
step() { # step NAME COMMAND...: stdout -> NAME.json, stderr -> NAME.log, status -> NAME.rc
    local name=$1; shift
    echo "[compare] $name: $*"
    local t0=$SECONDS
    "$@" > "$DIR/$name.json" 2> "$DIR/$name.log"
    local rc=$?
    echo "$rc" > "$DIR/$name.rc"
    if [[ $rc -ne 0 ]]; then
        FAILED=$((FAILED + 1))
        echo "[compare] $name FAILED (exit $rc) after $((SECONDS - t0)) s; last lines of $name.log:" >&2
        tail -n 15 "$DIR/$name.log" >&2
    else
        echo "[compare] $name done in $((SECONDS - t0)) s"
    fi
    if grep -q '^ *Compiling ' "$DIR/$name.log" 2> /dev/null; then
        echo "[compare] warning: cargo compiled something before $name (sources changed since the last build?)" >&2
    fi
}

peer() {
    local parts=gemm,convs,crosscheck
    [[ $QUICK == 1 ]] || parts=$parts,minkunet
    step spconv "$PY" bench/peer_spconv.py "$SCENE" --threads "$THREADS" --runs "$RUNS" --warmup "$WARMUP" \
        --parts "$parts" --mink-runs "$MODEL_RUNS" --mink-warmup "$MODEL_WARMUP"
}

pmunet() {
    for b in "${BACKEND_LIST[@]}"; do
        step "pmunet_conv_$b" cargo run -p bench --bin sparse-conv-bench -- \
            --coords "$SCENE" --backend "$b" --threads "$THREADS" --runs "$RUNS" --warmup "$WARMUP" --json ${PMUNET_ISA[@]+"${PMUNET_ISA[@]}"}
    done
    if [[ $QUICK != 1 ]]; then
        for b in "${BACKEND_LIST[@]}"; do
            # The peer's rows: inference at batch 1, the training step (and its peak) at batch 2, each
            # in a process of its own so the peak is that figure's alone.
            for spec in "1 infer" "2 train"; do
                read -r batch only <<< "$spec"
                step "pmunet_model_${b}_b$batch" cargo run -p bench --bin model-bench -- \
                    --model person_minkunet --coords "$SCENE" --backend "$b" --batch "$batch" --only "$only" \
                    --threads "$THREADS" --runs "$MODEL_RUNS" --warmup "$MODEL_WARMUP" --json ${PMUNET_ISA[@]+"${PMUNET_ISA[@]}"}
            done
        done
    fi
}

if [[ $ROUNDS == 1 ]]; then
    peer
    pmunet
else
    for ((r = 1; r <= ROUNDS; r++)); do
        DIR=$RES/round$r
        mkdir -p "$DIR" || die "cannot create $DIR"
        echo "[compare] round $r of $ROUNDS"
        # Alternate which side runs first, so neither always gets the quieter minutes.
        if ((r % 2)); then peer; pmunet; else pmunet; peer; fi
    done
fi
echo "load_after=$(cut -d' ' -f1-3 /proc/loadavg 2> /dev/null)" >> "$RES/meta.txt"

# --- the table --------------------------------------------------------------------------------
TABLE_PY=python3
command -v python3 > /dev/null || TABLE_PY=$PY
echo
"$TABLE_PY" bench/compare_table.py "$RES" || die "compare_table.py failed"
echo
echo "[compare] table written to $RES/table.md"
[[ $FAILED -eq 0 ]] || { echo "[compare] $FAILED step(s) failed; see the .log files in $RES" >&2; exit 1; }
