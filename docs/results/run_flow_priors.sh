#!/usr/bin/env bash
# Issue 15 on medium, umaze (or large): flow matching from each prior (Gaussian, line, learned) against DDPM at NFE 1
# (`experiment nfe1 --process flow`) and at NFE 4 (`priors`), then the flow process and the I2SB bridge from each
# prior at NFE 1, 2, 4 and full across training (`prior-curves`; DDPM's curves are nfe-curves'), in the store of
# run_maze_curves.sh (its DDPM, bridge and flow-line runs are shared; umaze: run_umaze_v2_curves.sh's); 3 training
# seeds, 200 episodes, cpu-small at the maze's plan shape. Usage: MAZE=medium bash docs/results/run_flow_priors.sh, or
# MAZE=umaze STEPS=4000 CHECKPOINT_EVERY=1000 bash docs/results/run_flow_priors.sh. The store skips finished work.
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment nfe1 "${common[@]}" --process flow
bridgeplan experiment priors "${common[@]}" --process flow
for process in flow bridge; do
  bridgeplan experiment prior-curves "${common[@]}" --process "$process"
done
campaign_report
