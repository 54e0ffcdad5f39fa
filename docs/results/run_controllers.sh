#!/usr/bin/env bash
# Issue 13: how plans are executed. The runs of run_maze_curves.sh (DDPM and the bridge from the line prior; umaze:
# run_umaze_v2_curves.sh's) at their final snapshot, open loop at NFE 1 and full with Diffuser's tracking controller
# and with pursuit (the plan's path at the expert's pace; lookahead 0.5, 1, 1.5), and replanned every 32 steps
# with pursuit; single-task and Multi2D, 3 training seeds, 200 episodes (`experiment controllers`). Then the same on
# validation episodes (`--validation`), where the findings report picks the lookahead it reports on the test episodes.
# Evaluation only (the runs exist). Usage: MAZE=medium bash docs/results/run_controllers.sh (umaze: STEPS=4000
# CHECKPOINT_EVERY=1000; large: STEPS=16000), with DATASET as the runs were trained; PROCESS=flow for flow matching
# from the line prior in place of the bridge (its DDPM rows are shared).
source "$(dirname "$0")/maze_campaign.sh"
process=(--process "${PROCESS:-bridge}")
bridgeplan experiment controllers "${common[@]}" "${process[@]}"
bridgeplan experiment controllers "${common[@]}" "${process[@]}" --validation
campaign_report
