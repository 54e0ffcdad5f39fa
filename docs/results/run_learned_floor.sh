#!/usr/bin/env bash
# The learned prior alone, tracked (no network call), next to the bridge it starts: each seed's bridge run from
# the learned prior (run_maze_thesis.sh) evaluated at its final snapshot at NFE 1 on its own 200 episodes; the
# JSON's `prior_only_learned` is the prior alone on the same episodes, `floor_line` the straight line.
# Usage: MAZE=medium bash docs/results/run_learned_floor.sh (RESULTS: the store, default results/$MAZE-v2-curves)
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH" PYTHONPATH="$PWD/src" MUJOCO_GL=${MUJOCO_GL:-egl}
MAZE=${MAZE:?set MAZE=umaze, medium or large}
R=${RESULTS:-results/$MAZE-v2-curves}/runs
OUT=docs/results/$MAZE-v2-curves/learned-floor
mkdir -p "$OUT"
for run in "$R"/$MAZE-bridge-learned-N16-*-s[0-9]*; do
  seed=${run##*-s}
  bridgeplan eval "$run" --nfe 1 --episodes 200 --seed "$seed" --out "$OUT/s$seed.json" > /dev/null
done
python3 - "$OUT" <<'PY'
import json, sys
from pathlib import Path
import numpy as np
rows = [json.loads(p.read_text()) for p in sorted(Path(sys.argv[1]).glob("s*.json"))]
def line(name, values):
    v = np.array(values)
    se = v.std(ddof=1) / np.sqrt(len(v)) if len(v) > 1 else float("nan")
    return f"{name}: {v.mean():.1f} ± {se:.1f} over {len(v)} seeds ({', '.join(f'{x:.1f}' for x in v)})"
print(line("bridge (learned) NFE 1", [r["score"]["minari"]["mean"] for r in rows]))
print(line("learned prior alone", [r["prior_only_learned"]["score"]["minari"]["mean"] for r in rows]))
print(line("line prior alone", [r["floor_line"]["score"]["minari"]["mean"] for r in rows]))
PY
