#!/usr/bin/env bash
# Issue 12 on umaze, data version 2: the thesis's experiments (each prior vs DDPM at NFE 1, bridge vs DDPM from
# Gaussian noise, the bridge across NFE, the priors at NFE 4) in the store of run_umaze_v2_curves.sh (its DDPM
# and line-bridge runs are shared); cpu-small, 4000 steps, snapshots every 1000, 200 episodes, 3 training seeds,
# two jobs at a time with one torch thread each. The store skips finished work: rerun to resume.
MAZE=umaze STEPS=${STEPS:-4000} CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-1000}
source "$(dirname "$0")/maze_campaign.sh"
for name in nfe1 bridge-vs-ddpm bridge-nfe priors; do
  bridgeplan experiment "$name" "${common[@]}"
done
campaign_report
