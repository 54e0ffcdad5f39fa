#!/usr/bin/env bash
# Issue 12, item 5 (honest selection): the runs of the nfe-curves experiment (DDPM and the bridge from the line
# prior) at their final snapshot on validation episodes (`experiment --validation`: tasks of another seed), into
# nfe-curves-validation. The findings report (studies/findings.toml) chooses each method's "best NFE" there and reports it on the test episodes.
# Evaluation only (the runs exist). Usage: MAZE=medium bash docs/results/run_validation.sh (umaze: STEPS=4000
# CHECKPOINT_EVERY=1000; large: STEPS=16000), with DATASET as the runs were trained.
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment nfe-curves "${common[@]}" --validation
campaign_report
