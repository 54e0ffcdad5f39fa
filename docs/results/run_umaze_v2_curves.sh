#!/usr/bin/env bash
# Issue 15 on umaze, data version 2: score against training steps at NFE 1, 2, 4 and full for DDPM and,
# from the straight-line prior, the I2SB bridge, the consistent bridge and flow matching; 3 training
# seeds (evaluation seed = training seed), 200 episodes per evaluation, cpu-small, two jobs at a time
# with one torch thread each. The store skips finished work: rerun to resume.
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
R=${RESULTS:-results/umaze-v2-curves}
D=${DATASET:-datasets/umaze-1000000-v2}
OUT=docs/results/umaze-v2-curves
[ -d "$D" ] || bridgeplan data generate --maze umaze --steps 1000000 --seed 123 --out "$D" --no-progress
common=(--maze umaze --dataset "$D" --preset cpu-small --results "$R" --train-steps 4000 --checkpoint-every 1000
        --episodes 200 --seeds 0,1,2 --workers 2 --no-progress)
bridgeplan experiment nfe-curves "${common[@]}"
bridgeplan experiment nfe-curves "${common[@]}" --consistent
bridgeplan experiment nfe-curves "${common[@]}" --process flow
mkdir -p "$OUT"
bridgeplan data info "$D" --json > "$OUT/dataset.json"
bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
