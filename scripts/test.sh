#!/usr/bin/env bash
# Set up .venv, lint (ruff, pinned in the test extras), check that every committed report is what its study
# generates from the committed data (trains nothing), then run the test suite: the default run leaves out the
# end-to-end tests marked slow (pyproject's addopts); `bash scripts/test.sh -m slow` runs those instead. The tests
# run on up to 2 processes (pytest-xdist; one torch thread each), fewer where the machine has fewer cores.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL=${MUJOCO_GL:-egl}
.venv/bin/python -m ruff check src tests studies scripts
.venv/bin/bridgeplan study report --check --root .
exec .venv/bin/python -m pytest -n auto --maxprocesses 2 "$@"
