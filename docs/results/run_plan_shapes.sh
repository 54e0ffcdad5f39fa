#!/usr/bin/env bash
# Issue 12, item 3: cpu-small training speed per maze and plan shape (horizon x stride over about the same
# span), one torch thread, 300 optimizer steps each, one job at a time on an otherwise idle machine.
# Writes docs/results/plan-shapes/speed.csv (steps/s from the checkpoint's training seconds).
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH"
OUT=docs/results/plan-shapes
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$OUT"
echo "maze,horizon,stride,span,steps,train_seconds,steps_per_second,code_version" > "$TMP/speed.csv"
for spec in medium:256:1 medium:64:4 medium:32:8 large:384:1 large:96:4 large:48:8; do
  IFS=: read -r maze h k <<< "$spec"
  D=${DATASETS:-datasets}/$maze-1000000-v2
  [ -d "$D" ] || bridgeplan data generate --maze "$maze" --steps 1000000 --seed 123 --out "$D" --no-progress
  bridgeplan train --maze "$maze" --dataset "$D" --preset cpu-small --horizon "$h" --stride "$k" --steps 300 \
    --checkpoint-every 300 --threads 1 --run-dir "$TMP/$maze-$h-$k" --no-progress > /dev/null
  python3 - "$TMP/$maze-$h-$k" "$maze" "$h" "$k" >> "$TMP/speed.csv" <<'PY'
import json, sys
from pathlib import Path
import torch
run, maze, h, k = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
state = torch.load(Path(run) / "checkpoint.pt", weights_only=False, map_location="cpu")
seconds = state["elapsed_seconds"]
code = json.loads((Path(run) / "config.json").read_text()).get("code_version", "")
print(f"{maze},{h},{k},{(h - 1) * k + 1},{state['step']},{seconds:.2f},{state['step'] / seconds:.2f},{code}")
PY
done
mv "$TMP/speed.csv" "$OUT/speed.csv"
cat "$OUT/speed.csv"
