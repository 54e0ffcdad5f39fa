#!/usr/bin/env bash
# Issue 15: the I2SB bridge sampled by its posterior means (`--sampler mean`, no noise) against I2SB's own chain
# (`posterior`), on the same trained runs: each seed's bridge from the line prior of run_maze_curves.sh (umaze:
# run_umaze_v2_curves.sh) at its final snapshot, NFE 2, 4 and full, tracked (Diffuser's controller) and pursued
# (lookahead 1, the default), 200 episodes of the training seed's test tasks. Writes one eval JSON per setting and
# summary.md (mean ± standard error over seeds) under docs/results/$MAZE-v2-samplers.
# Usage: MAZE=medium bash docs/results/run_bridge_sampler.sh (RESULTS: the store, default results/$MAZE-v2-curves;
# RUNS: the runs' names, a glob, default the line-prior I2SB bridge's; OUT: where to write; CONTROLLERS: default
# "track pursuit"). The consistent bridge from each prior, tracked: MAZE=medium
# RESULTS=results/medium-v2-consistent-priors RUNS='medium-bridge-*-N16-consistent-*-s[0-9]' CONTROLLERS=track
# OUT=docs/results/medium-v2-consistent-samplers bash docs/results/run_bridge_sampler.sh. SNAPSHOT (a training step;
# default the final snapshot), SAMPLERS (default "posterior mean") and NFES (default "2 4 15") narrow it, e.g. the
# line prior's consistent runs by their means at NFE 2 across training: SNAPSHOT=2000 SAMPLERS=mean NFES=2
# RUNS='medium-bridge-line-N16-consistent-*-s[0-9]' OUT=docs/results/medium-v2-consistent-samplers/step2000 ...
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
MAZE=${MAZE:?set MAZE=umaze, medium or large}
R=${RESULTS:-results/$MAZE-v2-curves}/runs
OUT=${OUT:-docs/results/$MAZE-v2-samplers}
mkdir -p "$OUT"
for run in "$R"/${RUNS:-$MAZE-bridge-line-N16-H*-cpu-small-s[0-9]}; do
  [ -d "$run" ] || { echo "no run matches $run" >&2; exit 2; }
  seed=${run##*-s}
  name=$(basename "$run"); prior=${name#"$MAZE"-bridge-}; prior=${prior%%-*}
  for sampler in ${SAMPLERS:-posterior mean}; do
    for nfe in ${NFES:-2 4 15}; do
      for controller in ${CONTROLLERS:-track pursuit}; do
        json="$OUT/$(if [ "$prior" != line ]; then echo "$prior-"; fi)s$seed-$sampler-nfe$nfe-$controller.json"
        [ -f "$json" ] || bridgeplan eval "$run" --nfe "$nfe" --episodes 200 --seed "$seed" --sampler "$sampler" \
          --controller "$controller" ${SNAPSHOT:+--snapshot "$SNAPSHOT"} --out "$json" > /dev/null
      done
    done
  done
done
python3 - "$OUT" > "$OUT/summary.md" <<'PY'
import json, sys
from collections import defaultdict
from pathlib import Path
import numpy as np
groups = defaultdict(list)
for path in sorted(Path(sys.argv[1]).glob("*.json")):
    *prior, _, sampler, nfe, controller = path.stem.split("-")
    groups[(prior[0] if prior else "line", controller, int(nfe[3:]), sampler)].append(json.loads(path.read_text()))
print("| prior | controller | NFE | sampler | seeds | score (minari) | success | code |")
print("|---|---|---|---|---|---|---|---|")
for (prior, controller, nfe, sampler), rs in sorted(groups.items()):
    v = np.array([r["score"]["minari"]["mean"] for r in rs])
    se = v.std(ddof=1) / np.sqrt(len(v)) if len(v) > 1 else float("nan")
    code = sorted({r["environment"]["code_version"] for r in rs})
    print(f"| {prior} | {controller} | {nfe} | {sampler} | {len(v)} | {v.mean():.1f} ± {se:.1f} | "
          f"{np.mean([r['success_rate']['mean'] for r in rs]):.2f} | {', '.join(code)} |")
PY
cat "$OUT/summary.md"
