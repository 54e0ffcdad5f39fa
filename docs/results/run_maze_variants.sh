#!/usr/bin/env bash
# Issues 12 and 15 on medium and large (data version 2), in the store of run_maze_curves.sh: the bridge with
# the thesis's beta_max 0.3 against the default 1.0, and the consistent bridge (line prior, NFE 1, 2, 4, full;
# 3 training seeds); then DDPM across diffusion steps (1, 4, 7, 10) on seed 0 alone. cpu-small at its per-maze
# plan shape, 200 episodes per evaluation, two jobs at a time with one torch thread each.
# Usage: MAZE=medium bash docs/results/run_maze_variants.sh (after run_maze_curves.sh, or on its own);
# PARTS picks among "beta-max consistent consistent-priors ddpm-steps" (default all; consistent-priors: the
# consistent bridge from each prior at NFE 1, 2, 4 and full across training, `prior-curves --consistent`), e.g.
# MAZE=large STEPS=16000 DATASET=/path/to/large-1000000-v2 PARTS=beta-max bash docs/results/run_maze_variants.sh.
# The committed consistent-priors rows were made in a store of their own: PARTS=consistent-priors
# RESULTS=results/$MAZE-v2-consistent-priors OUT=docs/results/$MAZE-v2-consistent-priors (umaze: STEPS=4000
# CHECKPOINT_EVERY=1000); the prior-curves report reads both.
source "$(dirname "$0")/maze_campaign.sh"
PARTS=${PARTS:-beta-max consistent consistent-priors ddpm-steps}
for part in $PARTS; do
  case $part in
    beta-max) bridgeplan experiment nfe-curves "${common[@]}" --beta-max 0.3 ;;
    consistent) bridgeplan experiment nfe-curves "${common[@]}" --consistent ;;
    consistent-priors) bridgeplan experiment prior-curves "${common[@]}" --consistent ;;
    ddpm-steps) bridgeplan experiment ddpm-steps "${common[@]}" --seeds 0 ;;
    *) echo "unknown part $part (choose from beta-max consistent consistent-priors ddpm-steps)" >&2; exit 2 ;;
  esac
done
campaign_report
