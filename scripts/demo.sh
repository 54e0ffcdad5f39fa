#!/usr/bin/env bash
# Set up .venv and run the main job on a small default (see `bridgeplan demo --help`).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL=${MUJOCO_GL:-egl}
exec .venv/bin/bridgeplan demo "$@"
