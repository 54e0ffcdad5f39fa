#!/usr/bin/env bash
# Training-seed variance at equal budget: the four cpu-small umaze planners of run_bench.sh (same settings,
# same dataset; run that first) trained again with seeds 1 and 2 for 7000 steps, evaluated at every
# 1000-step EMA snapshot over 200 episodes (evaluation seed = training seed), at NFE 1 (nfe1) and NFE 15
# (bridge-vs-ddpm, the same runs). Report: docs/results/umaze-cpu-small-seeds/. About 1 hour on 2 cores.
set -euo pipefail
export MUJOCO_GL=egl
B=.venv/bin/bridgeplan
R=results/seeds
COMMON=(--maze umaze --dataset results/bench/umaze-1000000 --preset cpu-small --results $R --train-steps 7000
        --checkpoint-every 1000 --seeds 1,2 --workers 2 --no-progress)
$B experiment nfe1 "${COMMON[@]}"
$B experiment bridge-vs-ddpm "${COMMON[@]}"
$B report --results $R --out docs/results/umaze-cpu-small-seeds --csv docs/results/umaze-cpu-small-seeds/results.csv
# seed 0: the bench's runs at the same snapshots (evaluation seed 0)
for run in ddpm bridge-gaussian bridge-line bridge-learned; do
  for step in 4000 7000; do
    for nfe in 1 15; do
      case $run:$nfe in bridge-line:15|bridge-learned:15) continue ;; esac
      $B eval results/bench/runs/$run --snapshot $step --nfe $nfe --episodes 200 --seed 0
    done
  done
done
