#!/usr/bin/env bash
# Issue 13: `bridgeplan experiment closed-loop` on the runs of run_maze_curves.sh (medium, large) or
# run_umaze_v2_curves.sh (umaze, STEPS=4000): DDPM, the I2SB bridge and flow matching from the line prior,
# open loop at NFE 1 and full, and replanned every 32 steps at NFE 1 (arrival truncated, and kept to the
# first plan's), single-task and Multi2D, at the final snapshot; 3 training seeds, 200 episodes.
# Usage: MAZE=medium bash docs/results/run_closed_loop.sh. The store skips finished work.
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment closed-loop "${common[@]}"
bridgeplan experiment closed-loop "${common[@]}" --process flow
campaign_report
