#!/usr/bin/env bash
# Issue 15 on umaze, data version 2: score against training steps at NFE 1, 2, 4 and full for DDPM and,
# from the straight-line prior, the I2SB bridge, the consistent bridge and flow matching; 3 training
# seeds (evaluation seed = training seed), 200 episodes per evaluation, cpu-small, two jobs at a time
# with one torch thread each. The store skips finished work: rerun to resume.
MAZE=umaze STEPS=${STEPS:-4000} CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-1000}
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment nfe-curves "${common[@]}"
bridgeplan experiment nfe-curves "${common[@]}" --consistent
bridgeplan experiment nfe-curves "${common[@]}" --process flow
mkdir -p "$OUT"
bridgeplan data info "$D" --json > "$OUT/dataset.json"
campaign_report
