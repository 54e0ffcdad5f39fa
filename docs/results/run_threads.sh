#!/usr/bin/env bash
# Issue 12: does training keep its speed when another process keeps a core busy? `bridgeplan bench`'s
# busy-core figure (cpu-small training steps/s, quiet and with one spinning process, at one torch thread,
# bridgeplan's default, and at one per core, torch's own), plus the small latency and overhead tables.
# Run on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/../.."
export PATH="$PWD/.venv/bin:$PATH"
bridgeplan bench --out docs/results/threads --presets cpu-small --batch-sizes 1 --nfes 1 --repeats 3 \
  --overhead-repeats 5 --no-compile --busy-steps 60 --device cpu
