#!/usr/bin/env bash
# Issue 13 on medium (data version 2): plans that may arrive early. The expert's windows never stop, so a plan
# conditioned to reach the goal at its last state spends the whole horizon getting there. Here half of the
# training windows wait still from a random index on (--hold-share 0.5, data.windows.hold_tails). DDPM and the
# bridge from the line prior across training steps at NFE 1, 2, 4 and full (open loop), then the closed-loop
# experiment (open loop and replanned every 32 steps, single-task and Multi2D) at the final snapshot; 3 training
# seeds. Its own store (results/$MAZE-v2-hold; the runs' names carry hold0.5), report under
# docs/results/$MAZE-v2-hold; the runs without holds are run_maze_curves.sh's and run_closed_loop.sh's.
# Usage: MAZE=medium bash docs/results/run_hold.sh
RESULTS=${RESULTS:-results/${MAZE:?set MAZE}-v2-hold}
source "$(dirname "$0")/maze_campaign.sh"
OUT=docs/results/$MAZE-v2-hold
bridgeplan experiment nfe-curves "${common[@]}" --hold-share 0.5
bridgeplan experiment closed-loop "${common[@]}" --hold-share 0.5
campaign_report
# when the plans arrive, with and without holds (the runs of run_maze_curves.sh's store where present)
python docs/results/planned_arrival.py "$OUT/planned-arrival.json" \
  results/$MAZE-v2-curves/runs/$MAZE-{ddpm-N16,bridge-line-N16}-H*-s[0-9] "$R"/runs/$MAZE-*-hold0.5-*
