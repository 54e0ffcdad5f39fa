#!/usr/bin/env bash
# Pictures for issues 12 and 13, 8 episodes each (eval seed 0), seed-0 runs at their final snapshot.
# curves: per maze, the runs of run_maze_curves.sh (umaze: run_umaze_v2_curves.sh): DDPM at its full NFE and the
#   bridge (line prior) at NFE 1 open loop, then the same bridge replanned every 32 steps from the warm prior with
#   the arrival kept.
# hold: the runs trained on windows that wait (run_hold.sh), open loop next to replanned every 32 steps with the
#   arrival kept: umaze's bridge (line prior, warm replans) on Multi2D tasks, medium's DDPM on its single task.
# controllers: medium's DDPM (run_maze_curves.sh, seed 0) at NFE 16, tracked (Diffuser's controller) next to
#   pursued (lookahead 1.5; run_controllers.sh).
# Usage: bash docs/results/run_renders.sh; PARTS picks among "curves hold controllers" (default all).
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}

curves() {
  for spec in umaze:H128 medium:H32k8 large:H48k8; do
    IFS=: read -r maze shape <<< "$spec"
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
}

hold() {
  for spec in "umaze bridge-line-N16-hold0.5-H128 multi warm" "medium ddpm-N16-hold0.5-H32k8 single cold"; do
    read -r maze run tasks start <<< "$spec"
    task=() warm=()
    [ "$tasks" = multi ] && task=(--multi-task)
    [ "$start" = warm ] && warm=(--prior warm)
    dir=${RESULTS_ROOT:-results}/$maze-v2-hold/runs/$maze-$run-cpu-small-s0
    OUT=docs/results/$maze-v2-hold/pictures
    [ -d "$dir" ] || { echo "skip $maze: no run $dir"; continue; }
    mkdir -p "$OUT"
    bridgeplan render "$dir" --episodes 8 --nfe 1 "${task[@]}" --out "$OUT/${run%%-N16*}-open.png"
    bridgeplan render "$dir" --episodes 8 --nfe 1 "${task[@]}" --replan-every 32 "${warm[@]}" --arrival keep \
      --out "$OUT/${run%%-N16*}-replan32-keep.png"
  done
}

controllers() {
  local run=${RESULTS_ROOT:-results}/medium-v2-curves/runs/medium-ddpm-N16-H32k8-cpu-small-s0
  local OUT=docs/results/medium-v2-curves/pictures
  [ -d "$run" ] || { echo "skip controllers: no run $run"; return; }
  mkdir -p "$OUT"
  bridgeplan render "$run" --episodes 8 --nfe 16 --out "$OUT/ddpm-nfe16-track.png"
  bridgeplan render "$run" --episodes 8 --nfe 16 --controller pursuit --lookahead 1.5 \
    --out "$OUT/ddpm-nfe16-pursuit1.5.png"
}

for part in ${PARTS:-curves hold controllers}; do
  case $part in
    curves|hold|controllers) "$part" ;;
    *) echo "unknown part $part (choose from curves hold controllers)" >&2; exit 2 ;;
  esac
done
