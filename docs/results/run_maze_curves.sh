#!/usr/bin/env bash
# Issues 12 and 15 on medium and large (data version 2): score against training steps at NFE 1, 2, 4 and full
# for DDPM and, from the straight-line prior, the I2SB bridge and flow matching; cpu-small at its per-maze
# plan shape (medium: 32 states 8 steps apart, large: 48 states 8 apart), 3 training seeds (evaluation seed =
# training seed), 200 episodes per evaluation, two jobs at a time with one torch thread each.
# Usage: MAZE=medium bash docs/results/run_maze_curves.sh. The store skips finished work: rerun to resume.
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment nfe-curves "${common[@]}"
bridgeplan experiment nfe-curves "${common[@]}" --process flow
mkdir -p "$OUT"
bridgeplan data info "$D" --json > "$OUT/dataset.json"
campaign_report
