#!/usr/bin/env bash
# Issue 15's goal on medium, settled with a setting declared in advance: the `samplers` experiment (DDPM and the
# consistent bridge from the line prior at NFE 1, and at 2, 4 and full by each of their samplers: DDPM ancestral
# and DDIM, the bridge by posterior draws and by posterior means) over 5 training seeds, 200 test episodes per
# evaluation at every snapshot, then the final snapshots on validation episodes (other task seeds), where
# the prior-curves report (studies/prior-curves.toml) chooses the bridge's sampler and NFE (<= 2) before reading the test episodes.
# Usage: MAZE=medium bash docs/results/run_sampler_sweep.sh (RESULTS default results/$MAZE-v2-sampler-sweep, OUT
# default docs/results/$MAZE-v2-sampler-sweep; STEPS, CHECKPOINT_EVERY, DATASET as in maze_campaign.sh). The
# committed medium rows: this, then again with STEPS=16000 CHECKPOINT_EVERY=4000 (the runs resume from step 8000).
MAZE=${MAZE:?set MAZE=umaze, medium or large}
RESULTS=${RESULTS:-results/$MAZE-v2-sampler-sweep} OUT=${OUT:-docs/results/$MAZE-v2-sampler-sweep}
source "$(dirname "$0")/maze_campaign.sh"
bridgeplan experiment samplers "${common[@]}" --consistent --seeds 0,1,2,3,4
bridgeplan experiment samplers "${common[@]}" --consistent --seeds 0,1,2,3,4 --validation
campaign_report
