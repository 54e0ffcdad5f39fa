#!/usr/bin/env bash
# Issue 12 on medium and large (data version 2): the thesis's experiments in the store of run_maze_curves.sh
# (its DDPM and line-bridge runs are shared, not retrained): each prior vs DDPM at NFE 1, bridge vs DDPM from
# Gaussian noise, the bridge across NFE, the priors (Gaussian, line, learned) at NFE 4; 3 training seeds.
# cpu-small at its per-maze plan shape, 200 episodes per evaluation, two jobs at a time with one torch thread
# each. run_maze_variants.sh has the rest (beta_max 0.3, the consistent bridge, DDPM's diffusion steps).
# Usage: MAZE=medium bash docs/results/run_maze_thesis.sh (after run_maze_curves.sh, or on its own).
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
for name in nfe1 bridge-vs-ddpm bridge-nfe priors; do
  bridgeplan experiment "$name" "${common[@]}" --seeds 0,1,2
done
mkdir -p "$OUT"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
