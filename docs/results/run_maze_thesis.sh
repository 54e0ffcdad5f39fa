#!/usr/bin/env bash
# Issue 12 on medium and large (data version 2): the thesis's experiments in the store of run_maze_curves.sh
# (its DDPM and line-bridge runs are shared, not retrained): each prior vs DDPM at NFE 1, bridge vs DDPM from
# Gaussian noise, the bridge across NFE, the priors (Gaussian, line, learned) at NFE 4; 3 training seeds.
# cpu-small at its per-maze plan shape, 200 episodes per evaluation, two jobs at a time with one torch thread
# each. run_maze_variants.sh has the rest (beta_max 0.3, the consistent bridge, DDPM's diffusion steps).
# Usage: MAZE=medium bash docs/results/run_maze_thesis.sh (after run_maze_curves.sh, or on its own).
source "$(dirname "$0")/maze_campaign.sh"
for name in nfe1 bridge-vs-ddpm bridge-nfe priors; do
  bridgeplan experiment "$name" "${common[@]}"
done
campaign_report
