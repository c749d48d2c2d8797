#!/usr/bin/env bash
# The facing stage's variants (docs/recipe.md §15): for a run folder, fits each on its training
# split and prints its validation line, without writing anything. About 2.5–5 minutes each on 2
# cores. §15's table was measured on round eleven's seed 0, the weights shipped before
# 2026-12-03 evening (`git worktree add /tmp/r11 af77b18` has them in /tmp/r11/weights/
# person_minkunet); its slice-moments rows on today's weights.
#   tools/facing_variants.sh weights/person_minkunet
set -euo pipefail
cd "$(dirname "$0")/.."
run=${1:?usage: tools/facing_variants.sh RUN_DIR}
variants=(
    "--cell 0.2 --profile-cell 0 --no-detector-direction --no-slice-moments"
    "--cell 0.2 --profile-cell 0 --no-detector-direction --no-slice-moments --boxes labels"
    "--cell 0.2 --profile-cell 0 --no-detector-direction --no-slice-moments --l2 0.1"
    "--cell 0.2 --profile-cell 0 --no-detector-direction --no-slice-moments --l2 0.001"
    "--cell 0.15 --profile-cell 0 --no-detector-direction --no-slice-moments"
    "--cell 0.3 --profile-cell 0.1 --no-detector-direction --no-slice-moments"
    "--cell 0.2 --profile-cell 0.1 --no-detector-direction --no-slice-moments"
    "--cell 0.2 --profile-cell 0.08 --no-detector-direction --no-slice-moments"
    "--cell 0.15 --profile-cell 0.1 --no-detector-direction --no-slice-moments"
    "--no-slice-moments"
    ""
)
for v in "${variants[@]}"; do
    echo "== ${v:-the defaults}"
    # shellcheck disable=SC2086
    cargo run -q -p train -- facing --run "$run" $v 2>/dev/null | grep -E "^(facing|validation)" || echo "failed: cargo run -p train -- facing --run $run $v"
done
