"""Offline datasets: generation, Minari and legacy D4RL readers, the flat-array cache, windows.

Entry points (imported lazily, so that generation workers do not import torch):
``load_stream(path_or_id)`` -> :class:`Stream`, ``WindowDataset(stream, horizon, normalizer)``,
``generate_dataset(maze, steps, seed, out)``.
"""

from __future__ import annotations

import importlib

__all__ = ["Stream", "WindowDataset", "default_dataset_path", "generate_dataset", "load_stream"]
_HOME = {"Stream": "stream", "WindowDataset": "windows", "default_dataset_path": "datasets",
         "generate_dataset": "datasets", "load_stream": "datasets"}


def __getattr__(name):
    if name in _HOME:
        return getattr(importlib.import_module(f"bridgeplan.data.{_HOME[name]}"), name)
    raise AttributeError(f"module 'bridgeplan.data' has no attribute {name!r}")
