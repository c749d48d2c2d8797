#!/usr/bin/env bash
# Fuzzes every parser a user's bytes reach, each for MINUTES (default 10), JOBS targets at once
# (default: one per core), then writes OUT/summary.md (execs, time, crashes, hangs per target).
#
#   bash fuzz/run.sh [MINUTES]        # needs cargo-afl: cargo install cargo-afl && cargo afl config --build
#
# Targets: the AFL++ binaries of fuzz/src/bin (PCD, NPY, KITTI .bin, labels_3d JSON, calibration
# YAML, KITTI-style txt), and the service's query string, which lives in the Burn-linked `train`
# crate and is driven by a seeded random harness instead (crates/train/tests/query_fuzz.rs).
# A crash is a panic, an abort, or holding more than the target's bound of memory (fuzz/src/lib.rs);
# a hang is an input taking over 1 s. Each one found becomes a regression test
# (crates/data-jrdb/tests/fuzz_regressions/).
set -euo pipefail
cd "$(dirname "$0")"
minutes=${1:-10}
jobs=${JOBS:-$(nproc)}
out=${OUT:-out}
# TARGETS="pcd npy" runs some of them; QUERY=0 leaves the query-string harness out.
read -r -a targets <<<"${TARGETS:-pcd npy kitti_bin labels_json calibration_yaml kitti_txt pointcloud2 pointcloud2_ros1}"
query=${QUERY:-1}

if ! cargo afl --version >/dev/null 2>&1; then
    echo "cargo-afl is missing: cargo install cargo-afl && cargo afl config --build" >&2
    exit 2
fi
[ -d seeds ] || python3 make_seeds.py
cargo afl build --release 2>&1 | tail -1
mkdir -p "$out"

export AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1 AFL_NO_UI=1 AFL_NO_AFFINITY=1
export minutes out
fuzz_one() {
    local t=$1
    # -V: stop after the time; -t: a hang is over 1000 ms; -m none: the targets bound memory themselves.
    cargo afl fuzz -i "seeds/$t" -o "$out/$t" -V $((minutes * 60)) -t 1000 -m none "target/release/$t" >"$out/$t.log" 2>&1 || true
}
export -f fuzz_one
printf '%s\n' "${targets[@]}" | xargs -P "$jobs" -I{} bash -c 'fuzz_one {}'

# The query string: its harness runs as long, on one core.
query_start=$(date +%s)
if [ "$query" = 1 ]; then
    (cd .. && PMUNET_FUZZ_SECONDS=$((minutes * 60)) cargo test -q -p train --test query_fuzz -- --ignored --nocapture) >"$out/query_string.log" 2>&1 || true
fi
query_secs=$(( $(date +%s) - query_start ))

{
    echo "| target | run time (s) | execs | execs/s | corpus | crashes | hangs |"
    echo "|---|---|---|---|---|---|---|"
    for t in "${targets[@]}"; do
        s="$out/$t/default/fuzzer_stats"
        if [ -f "$s" ]; then
            v() { awk -F' *: *' -v k="$1" '$1 == k { print $2 }' "$s"; }
            rt=$(v run_time); ex=$(v execs_done)
            echo "| $t | $rt | $ex | $(( ex / (rt > 0 ? rt : 1) )) | $(v corpus_count) | $(v saved_crashes) | $(v saved_hangs) |"
        else
            echo "| $t | did not run: see $out/$t.log | | | | | |"
        fi
    done
    if [ "$query" = 1 ]; then
        q=$(grep -o 'query strings: [0-9]* in [0-9.]* s' "$out/query_string.log" || echo "see $out/query_string.log")
        fails=$(grep -c 'panicked' "$out/query_string.log" || true)
        echo "| query_string (seeded random harness) | $query_secs | $q | | | $fails | |"
    fi
} | tee "$out/summary.md"
