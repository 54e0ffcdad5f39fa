#!/usr/bin/env bash
# Issue 12 on umaze, data version 2: the thesis's experiments (each prior vs DDPM at NFE 1, bridge vs DDPM from
# Gaussian noise, the bridge across NFE, the priors at NFE 4) in the store of run_umaze_v2_curves.sh (its DDPM
# and line-bridge runs are shared); cpu-small, 4000 steps, snapshots every 1000, 200 episodes, 3 training seeds,
# two jobs at a time with one torch thread each. The store skips finished work: rerun to resume.
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
R=${RESULTS:-results/umaze-v2-curves}
D=${DATASET:-datasets/umaze-1000000-v2}
OUT=docs/results/umaze-v2-curves
[ -d "$D" ] || bridgeplan data generate --maze umaze --steps 1000000 --seed 123 --out "$D" --no-progress
common=(--maze umaze --dataset "$D" --preset cpu-small --results "$R" --train-steps 4000 --checkpoint-every 1000
        --episodes 200 --seeds 0,1,2 --workers 2 --no-progress)
for name in nfe1 bridge-vs-ddpm bridge-nfe priors; do
  bridgeplan experiment "$name" "${common[@]}"
done
mkdir -p "$OUT"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
