# Sourced by the run_*.sh campaign scripts (medium, large and umaze): the settings they share. MAZE (required),
# STEPS (default 8000), CHECKPOINT_EVERY (default 2000), RESULTS (the store; default results/$MAZE-v2-curves),
# DATASET (default datasets/$MAZE-1000000-v2, generated with seed 123 if absent), OUT (the report's folder; default
# docs/results/$MAZE-v2-curves; a store's report holds that store's rows alone). Defines `common` (the sweep
# flags: cpu-small at the maze's plan shape, a snapshot every CHECKPOINT_EVERY steps, 200 episodes, seeds 0-2,
# two jobs at a time) and `campaign_report` (the store's report and CSV under OUT).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
# this checkout's code, whatever the venv has installed (its rows record this checkout's code version)
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
MAZE=${MAZE:?set MAZE=umaze, medium or large}
STEPS=${STEPS:-8000}
CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-2000}
R=${RESULTS:-results/$MAZE-v2-curves}
D=${DATASET:-datasets/$MAZE-1000000-v2}
OUT=${OUT:-docs/results/$MAZE-v2-curves}
[ -d "$D" ] || bridgeplan data generate --maze "$MAZE" --steps 1000000 --seed 123 --out "$D" --no-progress
common=(--maze "$MAZE" --dataset "$D" --preset cpu-small --results "$R" --train-steps "$STEPS"
        --checkpoint-every "$CHECKPOINT_EVERY" --episodes 200 --seeds 0,1,2 --workers 2 --no-progress)

campaign_report() {
  mkdir -p "$OUT"
  bridgeplan report --results "$R" --out "$OUT" --csv "$OUT/results.csv"
}
