#!/usr/bin/env bash
# Issues 12 and 15 on medium and large (data version 2), in the store of run_maze_curves.sh: the bridge with
# the thesis's beta_max 0.3 against the default 1.0, and the consistent bridge (line prior, NFE 1, 2, 4, full;
# 3 training seeds); then DDPM across diffusion steps (1, 4, 7, 10) on seed 0 alone. cpu-small at its per-maze
# plan shape, 200 episodes per evaluation, two jobs at a time with one torch thread each.
# Usage: MAZE=medium bash docs/results/run_maze_variants.sh (after run_maze_curves.sh, or on its own).
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment nfe-curves "${common[@]}" --beta-max 0.3
bridgeplan experiment nfe-curves "${common[@]}" --consistent
bridgeplan experiment ddpm-steps "${common[@]}" --seeds 0
campaign_report
