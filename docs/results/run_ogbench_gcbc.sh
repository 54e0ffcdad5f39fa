#!/usr/bin/env bash
# The GCBC calibration baseline on OGBench pointmaze-medium-navigate-v0 (docs/results/ogbench-gcbc): the dataset
# generated in OGBench's recipe, GCBC at OGBench's settings (lr 3e-4, batch 1024, MLP 512x3, future-state goals)
# for STEPS optimizer steps (OGBench trains 1 M; one CPU core does ~10-18 steps/s), snapshots every
# CHECKPOINT_EVERY steps, each evaluated by OGBench's protocol (5 tasks x 50 episodes). A run already there is
# resumed to STEPS. About an hour on a busy 2-core CPU at STEPS=30000.
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
B=bridgeplan
NAME=pointmaze-medium-navigate-v0
DATA=datasets/ogbench/$NAME.npz
RUN=${RUN:-runs/ogbench/gcbc-medium-navigate-s${SEED:-0}}
STEPS=${STEPS:-30000}
CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-5000}
[ -f $DATA ] || $B ogbench generate $NAME --out datasets/ogbench --no-progress
resume=""; [ -f $RUN/checkpoint.pt ] && resume=--resume
$B ogbench gcbc-train $DATA --maze medium --run-dir $RUN --steps $STEPS --checkpoint-every $CHECKPOINT_EVERY \
  --log-every 500 --seed ${SEED:-0} --device cpu --threads 1 --no-progress $resume
$B ogbench gcbc-eval $RUN --steps all --no-progress
