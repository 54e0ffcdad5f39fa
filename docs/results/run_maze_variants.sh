#!/usr/bin/env bash
# Issues 12 and 15 on medium and large (data version 2), in the store of run_maze_curves.sh: the bridge with
# the thesis's beta_max 0.3 against the default 1.0, and the consistent bridge (line prior, NFE 1, 2, 4, full;
# 3 training seeds); then DDPM across diffusion steps (1, 4, 7, 10) on seed 0 alone. cpu-small at its per-maze
# plan shape, 200 episodes per evaluation, two jobs at a time with one torch thread each.
# Usage: MAZE=medium bash docs/results/run_maze_variants.sh (after run_maze_curves.sh, or on its own).
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" MUJOCO_GL=${MUJOCO_GL:-egl}
MAZE=${MAZE:?set MAZE=medium or MAZE=large}
STEPS=${STEPS:-8000}
R=${RESULTS:-results/$MAZE-v2-curves}
D=${DATASET:-datasets/$MAZE-1000000-v2}
OUT=docs/results/$MAZE-v2-curves
[ -d "$D" ] || bridgeplan data generate --maze "$MAZE" --steps 1000000 --seed 123 --out "$D" --no-progress
common=(--maze "$MAZE" --dataset "$D" --preset cpu-small --results "$R" --train-steps "$STEPS"
        --checkpoint-every 2000 --episodes 200 --workers 2 --no-progress)
bridgeplan experiment nfe-curves "${common[@]}" --seeds 0,1,2 --beta-max 0.3
bridgeplan experiment nfe-curves "${common[@]}" --seeds 0,1,2 --consistent
bridgeplan experiment ddpm-steps "${common[@]}" --seeds 0
mkdir -p "$OUT"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
