#!/usr/bin/env bash
# The GPU check: a short real run (Diffuser's preset trained on medium
# for a few minutes, evaluated on 200 episodes at NFE 1, 16 and the full 256, and timed at batch 1), then
# `bridgeplan bench` on the CUDA device. About 7
# minutes on one H200. Outputs (the bench's JSON and Markdown, the evaluation JSONs, a log) go to $OUT, else
# gpu-check/; docs/results/gpu/README.md says how the committed ones were made.
#
#   bash scripts/gpu-check.sh                 # on a machine with a CUDA GPU
#   DEVICE=cpu MINUTES=0.1 EPISODES=4 SMALL=1 bash scripts/gpu-check.sh   # the same steps, tiny, anywhere
#
# Needs python3 with bridgeplan importable (`pip install -e .`, or PYTHONPATH=src with its dependencies); where
# the tree is a copy without .git, BRIDGEPLAN_COPIED_FROM=<commit> names the code in the results.
set -uo pipefail
cd "$(dirname "$0")/.."
out=${OUT:-gpu-check}
device=${DEVICE:-cuda}
minutes=${MINUTES:-2.5}
episodes=${EPISODES:-200}
mkdir -p "$out"
exec > >(tee "$out/log.txt") 2>&1
export PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-egl}
bp() { python3 -m bridgeplan.cli "$@"; }
step() { echo "== $(date +%T) $*"; }
failed=()
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

step machine
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv 2>/dev/null || echo "no nvidia-smi"
python3 -c "import torch, bridgeplan.files as f; print('torch', torch.__version__, '| code', f.code_version())"

step "data (medium, 1 M steps, seed 123: the studies' dataset)"
bp data generate --maze medium --steps "${DATA_STEPS:-1000000}" --seed 123 --out "$work/medium-1000000-v2" --no-progress \
  > /dev/null || failed+=(data)

step "train (diffuser preset, medium, $minutes minutes)"
bp train --maze medium --preset diffuser --dataset "$work/medium-1000000-v2" --minutes "$minutes" --device "$device" \
  --run-dir "$work/run" --no-progress || failed+=(train)

step "evaluate ($episodes episodes at NFE 1, 16, 256; 5 plans at batch 1, NFE 256)"
for nfe in 1 16 256; do
  bp eval "$work/run" --episodes "$episodes" --nfe "$nfe" --device "$device" --out "$out/eval-nfe$nfe.json" \
    || failed+=("eval-nfe$nfe")
done
bp eval "$work/run" --episodes 5 --plan-batch 1 --nfe 256 --device "$device" --out "$out/eval-nfe256-batch1.json" \
  > /dev/null || failed+=(eval-batch1)

step bench
if [ -n "${SMALL:-}" ]; then  # a smoke test of the steps, not a measurement
  sizes=(--batch-sizes 1,4 --nfes 1,2 --repeats 1 --overhead-repeats 1 --throughput-seconds 0)
else
  sizes=(--batch-sizes 1,64,1024 --nfes 1,16,64 --repeats 3 --overhead-repeats 10 --throughput-seconds 1.5
         --throughput-batch-sizes 256,1024)
fi
bp bench --device "$device" --out "$out/bench" --presets cpu-small,diffuser --methods "DDPM [ancestral],bridge (line)" \
  "${sizes[@]}" --busy-steps 0 --side-by-side-seconds 0 --no-compile > /dev/null || failed+=(bench)

step "done${failed[*]:+; failed: ${failed[*]}}"
[ ${#failed[@]} -eq 0 ]
