#!/usr/bin/env bash
# Create .venv (if missing) and install bridgeplan into it with its test extras.
# torch: kept if the venv already has one (e.g. your CUDA build); otherwise the CPU build
# torch==2.13.0 on machines without an NVIDIA GPU (a plain `torch` would pull several GB of CUDA
# wheels), and the default build where nvidia-smi exists. Override with BRIDGEPLAN_TORCH="torch==X".
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
PIP=".venv/bin/python -m pip"
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  if [ -n "${BRIDGEPLAN_TORCH:-}" ]; then spec=$BRIDGEPLAN_TORCH
  elif command -v nvidia-smi >/dev/null 2>&1; then spec=torch
  else spec=torch==2.13.0
  fi
  echo "installing $spec"
  $PIP install -q "$spec"
fi
$PIP install -q -e ".[test,tensorboard]"
echo "setup done: $(.venv/bin/python -c 'import torch, bridgeplan; print("bridgeplan", bridgeplan.__version__, "torch", torch.__version__)')"
