#!/usr/bin/env bash
# The benchmark committed in docs/results/bench.{md,json}: four cpu-small planners on umaze trained for the same
# number of optimizer steps (DDPM; the bridge from the Gaussian, line and learned priors), then `bridgeplan bench`
# with the score-per-budget table over their EMA snapshots at 7000 and 14000 steps. Run after
# `bash scripts/setup.sh`. About 1.5 hours on a 2-core CPU: the trainings run two at a time with one thread each
# (a run already there is resumed to STEPS); the bench runs alone.
set -euo pipefail
cd "$(dirname "$0")/../.."
# this checkout's code, whatever the venv has installed (bench.json records this checkout's code version)
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
B=bridgeplan
R=results/bench
STEPS=${STEPS:-14000}
DATA=$R/umaze-1000000
[ -d $DATA ] || $B data generate --maze umaze --out $DATA --no-progress
P=$R/runs/prior-learned
[ -f $P/checkpoint.pt ] || $B train-prior --maze umaze --dataset $DATA --steps 1500 --threads 1 --run-dir $P --no-progress
train() {  # name, then the flags that differ
  local name=$1; shift
  local resume=""; [ -f $R/runs/$name/checkpoint.pt ] && resume=--resume
  $B train --maze umaze --dataset $DATA --preset cpu-small --steps $STEPS --checkpoint-every 1000 --threads 1 \
    --run-dir $R/runs/$name $resume --no-progress "$@"
}
train ddpm --process ddpm & train bridge-gaussian --process bridge --prior gaussian & wait
train bridge-line --process bridge --prior line & train bridge-learned --process bridge --prior learned --prior-run $P & wait
# the bench itself, alone on the machine (torch's default threads)
$B bench --out docs/results --eval-run $R/runs/ddpm \
  --budget-runs $R/runs/ddpm,$R/runs/bridge-gaussian,$R/runs/bridge-line,$R/runs/bridge-learned \
  --budget-steps 7000,$STEPS
