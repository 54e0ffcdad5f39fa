#!/usr/bin/env bash
# Issue 13 on umaze, data version 2: open-loop vs closed-loop execution of the step-4000 runs that
# run_umaze_v2_curves.sh trained (DDPM, I2SB bridge and flow matching from the line prior; 3 training
# seeds), 200 episodes each (eval seed = training seed), single-task and Multi2D. One JSON per
# evaluation under docs/results/umaze-v2-closed-loop/, then a summary table (summarize_closed_loop.py).
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" MUJOCO_GL=${MUJOCO_GL:-egl}
R=${RESULTS:-results/umaze-v2-curves}/runs
OUT=docs/results/umaze-v2-closed-loop
mkdir -p "$OUT"
for seed in 0 1 2; do
  for run in ddpm-N16 bridge-line-N16 flow-line-N16; do
    dir="$R/umaze-$run-H128-cpu-small-s$seed"
    nfe=1
    warm=(--prior warm)
    [ "$run" = ddpm-N16 ] && warm=()  # DDPM starts every plan from noise
    for task in single multi; do
      multi=(); [ $task = multi ] && multi=(--multi-task)
      tag="$run-s$seed-$task"
      bridgeplan eval "$dir" --snapshot 4000 --nfe $nfe --episodes 200 --seed $seed "${multi[@]}" \
        --out "$OUT/$tag-open.json" > /dev/null
      for k in 8 32; do
        bridgeplan eval "$dir" --snapshot 4000 --nfe $nfe --episodes 200 --seed $seed "${multi[@]}" \
          --replan-every $k "${warm[@]}" --out "$OUT/$tag-replan$k.json" > /dev/null
      done
    done
  done
done
python3 docs/results/summarize_closed_loop.py "$OUT" > "$OUT/summary.md"
cat "$OUT/summary.md"
