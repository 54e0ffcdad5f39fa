#!/usr/bin/env bash
# Pictures for issues 12 and 13: per maze, the seed-0 runs of run_maze_curves.sh (umaze: run_umaze_v2_curves.sh)
# at their final snapshot, 8 episodes (eval seed 0): DDPM at its full NFE and the bridge (line prior) at NFE 1
# open loop, then the same bridge replanned every 32 steps from the warm prior with the arrival kept.
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" MUJOCO_GL=${MUJOCO_GL:-egl}
for spec in umaze:H128:4000 medium:H32k8:8000 large:H48k8:8000; do
  IFS=: read -r maze shape step <<< "$spec"
  R=${RESULTS_ROOT:-results}/$maze-v2-curves/runs
  OUT=docs/results/$maze-v2-curves/pictures
  [ -d "$R/$maze-ddpm-N16-$shape-cpu-small-s0" ] || { echo "skip $maze: no runs"; continue; }
  mkdir -p "$OUT"
  bridge="$R/$maze-bridge-line-N16-$shape-cpu-small-s0"
  bridgeplan render "$R/$maze-ddpm-N16-$shape-cpu-small-s0" --episodes 8 --out "$OUT/ddpm-open.png" > /dev/null
  bridgeplan render "$bridge" --episodes 8 --nfe 1 --out "$OUT/bridge-line-open.png" > /dev/null
  bridgeplan render "$bridge" --episodes 8 --nfe 1 --replan-every 32 --prior warm --arrival keep \
    --out "$OUT/bridge-line-replan32-keep.png" > /dev/null
  echo "$maze: $(ls "$OUT" | tr '\n' ' ')"
done
