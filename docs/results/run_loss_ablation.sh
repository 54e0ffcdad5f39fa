#!/usr/bin/env bash
# Issue 15, item 3 on medium (data version 2), in the store of run_maze_curves.sh: the bridge's loss taken apart.
# I2SB's bridge differs from Diffuser's DDPM in its output (the scaled difference, not x0) and in its per-step
# weight of the x0 error (1 / std_fwd^2, not 1). One ablation each, from the line prior, across training steps at
# NFE 1, 2, 4 and full, 3 training seeds: predict=x0 (same objective, x0 output) and weighting=uniform (Diffuser's
# weight, I2SB's output). The default bridge and DDPM runs are shared with run_maze_curves.sh.
# Usage: MAZE=medium bash docs/results/run_loss_ablation.sh
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment nfe-curves "${common[@]}" --process-param predict=x0
bridgeplan experiment nfe-curves "${common[@]}" --process-param weighting=uniform
campaign_report
