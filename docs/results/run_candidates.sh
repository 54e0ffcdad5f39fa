#!/usr/bin/env bash
# Issue 13, item 4 on medium: choosing among M candidate plans. For DDPM and the bridge from the line prior
# (run_maze_curves.sh's runs, and run_hold.sh's trained on windows that wait), at the final snapshot, NFE 2 (at
# NFE 1 the bridge's candidates from the deterministic line prior would be identical), 200 episodes of each
# training seed's task seed, single-task, open loop: one plan as sampled (open), one plan truncated at its
# arrival (truncate), and 8 candidates per episode picked by earliest arrival, by agreement with the others, or
# by fewest planned positions in walls (the maze's wall map: an oracle variant, not a deployable criterion).
# Usage: MAZE=medium bash docs/results/run_candidates.sh (after run_maze_curves.sh and run_hold.sh)
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
MAZE=${MAZE:?set MAZE=umaze, medium or large}
OUT=docs/results/$MAZE-v2-candidates
mkdir -p "$OUT"
settings=("open:" "truncate:--arrival truncate" "cand8arrival:--candidates 8 --select arrival"
          "cand8agreement:--candidates 8 --select agreement" "cand8walls:--candidates 8 --select walls")
for store in curves hold; do
  for run in results/$MAZE-v2-$store/runs/$MAZE-{ddpm-N16,bridge-line-N16}-{H,hold0.5-H}*-s[0-9]; do
    [ -d "$run" ] || continue
    seed=${run##*-s}
    for setting in "${settings[@]}"; do
      tag=${setting%%:*}
      read -ra flags <<< "${setting#*:}"
      json="$OUT/$(basename "$run")-$tag.json"
      [ -f "$json" ] || bridgeplan eval "$run" --nfe 2 --episodes 200 --seed "$seed" "${flags[@]}" --out "$json" \
        > /dev/null
    done
  done
done
python3 docs/results/summarize_closed_loop.py "$OUT" > "$OUT/summary.md"
cat "$OUT/summary.md"
