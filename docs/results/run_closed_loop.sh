#!/usr/bin/env bash
# Issue 13: `bridgeplan experiment closed-loop` on the runs of run_maze_curves.sh (medium, large) or
# run_umaze_v2_curves.sh (umaze, STEPS=4000): DDPM, the I2SB bridge and flow matching from the line prior,
# open loop at NFE 1 and full, and replanned every 32 steps at NFE 1 (arrival truncated, and kept to the
# first plan's), single-task and Multi2D, at the final snapshot; 3 training seeds, 200 episodes.
# Usage: MAZE=medium bash docs/results/run_closed_loop.sh. The store skips finished work.
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" MUJOCO_GL=${MUJOCO_GL:-egl}
MAZE=${MAZE:?set MAZE=umaze, medium or large}
STEPS=${STEPS:-8000}
R=${RESULTS:-results/$MAZE-v2-curves}
D=${DATASET:-datasets/$MAZE-1000000-v2}
OUT=docs/results/$MAZE-v2-curves
[ -d "$D" ] || bridgeplan data generate --maze "$MAZE" --steps 1000000 --seed 123 --out "$D" --no-progress
common=(--maze "$MAZE" --dataset "$D" --preset cpu-small --results "$R" --train-steps "$STEPS"
        --checkpoint-every 2000 --episodes 200 --seeds 0,1,2 --workers 2 --no-progress)
bridgeplan experiment closed-loop "${common[@]}"
bridgeplan experiment closed-loop "${common[@]}" --process flow
mkdir -p "$OUT"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
