#!/usr/bin/env bash
# Issues 12 and 15 on medium and large (data version 2): score against training steps at NFE 1, 2, 4 and full
# for DDPM and, from the straight-line prior, the I2SB bridge and flow matching; cpu-small at its per-maze
# plan shape (medium: 32 states 8 steps apart, large: 48 states 8 apart), 3 training seeds (evaluation seed =
# training seed), 200 episodes per evaluation, two jobs at a time with one torch thread each.
# Usage: MAZE=medium bash docs/results/run_maze_curves.sh. The store skips finished work: rerun to resume.
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
        --checkpoint-every 2000 --episodes 200 --seeds 0,1,2 --workers 2 --no-progress)
bridgeplan experiment nfe-curves "${common[@]}"
bridgeplan experiment nfe-curves "${common[@]}" --process flow
mkdir -p "$OUT"
bridgeplan data info "$D" --json > "$OUT/dataset.json"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
