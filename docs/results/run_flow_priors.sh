#!/usr/bin/env bash
# Issue 15 on medium (or large): flow matching from each prior (Gaussian, line, learned) against DDPM at NFE 1
# (`experiment nfe1 --process flow`) and at NFE 4 (`priors`), in the store of run_maze_curves.sh (its DDPM
# and flow-line runs are shared); 3 training seeds, 200 episodes, cpu-small at the maze's plan shape.
# Usage: MAZE=medium bash docs/results/run_flow_priors.sh. The store skips finished work.
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
        --checkpoint-every 2000 --episodes 200 --seeds 0,1,2 --workers 2 --no-progress --process flow)
bridgeplan experiment nfe1 "${common[@]}"
bridgeplan experiment priors "${common[@]}"
mkdir -p "$OUT"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
