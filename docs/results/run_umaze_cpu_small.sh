#!/usr/bin/env bash
# The measurements committed in docs/results/umaze-cpu-small/ (2-core CPU, one job at a time).
# Run from the repository root after `bash scripts/setup.sh`. The committed results were made at commit
# 3157514 (whose bridge default was beta_max 0.3 and cpu-small default 20 diffusion steps, overridden to 16
# here); at later commits the sweep's bridges use the new default beta_max 1.0.
set -euo pipefail
export MUJOCO_GL=egl
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}  # leaves a core free; recorded as cpu_threads in every JSON
B=.venv/bin/bridgeplan
R=results/umaze-cpu-small
DATA=datasets/umaze-1000000
[ -d $DATA ] || $B data generate --maze umaze --no-progress
COMMON="--maze umaze --dataset $DATA --results $R --train-steps 4000 --prior-steps 1500 --checkpoint-every 1000 --episodes 200 --no-progress"
# the four runs (DDPM; bridge from gaussian, line, learned; N=16) are trained once and shared
for exp in nfe1 priors bridge-vs-ddpm bridge-nfe; do
  $B experiment $exp $COMMON
done
$B report --results $R --csv $R/results.csv
# every run at NFE 1, 2, 4 and the full count, final snapshot, 200 episodes (issue: bridge vs DDPM table)
for run in $R/runs/umaze-*-N16-*; do
  for nfe in 1 2 4 full; do
    if [ $nfe = full ]; then $B eval $run --episodes 200 --json > $run/eval-full.json
    else $B eval $run --episodes 200 --nfe $nfe --json > $run/eval-nfe$nfe.json; fi
  done
done
# beta_max 1.0 for the bridge from the line prior (the default above is 0.3)
$B train --maze umaze --dataset $DATA --preset cpu-small --process bridge --prior line --diffusion-steps 16 \
  --beta-max 1.0 --steps 4000 --run-dir $R/runs/umaze-bridge-line-N16-beta1 --no-progress
for nfe in 1 2 4 15; do
  $B eval $R/runs/umaze-bridge-line-N16-beta1 --episodes 200 --nfe $nfe --json > $R/runs/umaze-bridge-line-N16-beta1/eval-nfe$nfe.json
done
# NFE 8 and DDIM for the score-per-budget table (step-4000 snapshots)
for run in $R/runs/umaze-*-N16-H128-*; do
  $B eval $run --snapshot 4000 --episodes 200 --nfe 8 --json > $run/eval-nfe8.json
done
D=$R/runs/umaze-ddpm-N16-H128-cpu-small-s0
for nfe in 1 2 4 8; do $B eval $D --snapshot 4000 --episodes 200 --nfe $nfe --sampler ddim --eta 0 --json > $D/eval-ddim-nfe$nfe.json; done
# longer training: DDPM to 30 minutes, the Gaussian-prior bridge to 7000 steps (same configs, resumed)
$B train --maze umaze --dataset $DATA --preset cpu-small --process ddpm --diffusion-steps 16 --steps 1000000 \
  --minutes 30 --checkpoint-every 1000 --run-dir $D --resume --no-progress
G=$R/runs/umaze-bridge-gaussian-N16-H128-cpu-small-s0
$B train --maze umaze --dataset $DATA --preset cpu-small --process bridge --prior gaussian --diffusion-steps 16 \
  --beta-max 0.3 --steps 7000 --checkpoint-every 1000 --run-dir $G --resume --no-progress
for nfe in 1 4 16; do $B eval $D --snapshot 7000 --episodes 200 --nfe $nfe --out $D/eval-10min-step7000-nfe$nfe.json; done
for nfe in 1 16; do $B eval $D --episodes 200 --nfe $nfe --out $D/eval-30min-nfe$nfe.json; done
for nfe in 1 4 15; do $B eval $G --snapshot 7000 --episodes 200 --nfe $nfe --out $G/eval-step7000-nfe$nfe.json; done
# pictures
for p in learned line; do
  $B render $R/runs/umaze-bridge-$p-N16-H128-cpu-small-s0 --episodes 8 --nfe 1 --pairs --out $R/render-$p.png
done
