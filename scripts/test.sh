#!/usr/bin/env bash
# Set up .venv, lint (ruff, pinned in the test extras), then run the test suite (a few minutes on 2 CPU cores).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL=${MUJOCO_GL:-egl}
.venv/bin/python -m ruff check src tests
exec .venv/bin/python -m pytest "$@"
