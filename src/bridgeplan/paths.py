"""Where things live on disk: a results directory, its runs, a run's checkpoint and snapshots.

::

    RESULTS/results.sqlite             the results store (one row per evaluation)
    RESULTS/runs/<run name>/           one trained run (``TrainConfig.run_name``)
    RESULTS/data/<maze>-<steps>/       a sweep's generated dataset
    RESULTS/report/                    figures and report.md
    RUN/checkpoint.pt                  everything needed to resume (model, EMA, optimizer, RNG, step)
    RUN/config.json                    the run's config and code version, readable without torch
    RUN/snapshots/step_00001000.pt     EMA weights at a training step (what sweeps evaluate)
    RUN/eval/*.json, RUN/render/*      what ``bridgeplan eval`` and ``render`` write
"""

from __future__ import annotations

import os
from pathlib import Path

STORE_NAME = "results.sqlite"
CHECKPOINT_NAME = "checkpoint.pt"
CONFIG_NAME = "config.json"
DATASETS_ENV = "BRIDGEPLAN_DATASETS"
"""Environment variable: the default root of generated datasets (default ``datasets`` in the cwd)."""


def datasets_root() -> Path:
    """Where generated datasets go by default: ``$BRIDGEPLAN_DATASETS`` when set, else ``datasets``."""
    return Path(os.environ.get(DATASETS_ENV) or "datasets")


def store_path(results_dir: Path | str) -> Path:
    return Path(results_dir) / STORE_NAME


def runs_dir(results_dir: Path | str) -> Path:
    return Path(results_dir) / "runs"


def data_dir(results_dir: Path | str) -> Path:
    return Path(results_dir) / "data"


def report_dir(results_dir: Path | str) -> Path:
    return Path(results_dir) / "report"


def checkpoint_path(run: Path | str) -> Path:
    return Path(run) / CHECKPOINT_NAME


def config_path(run: Path | str) -> Path:
    return Path(run) / CONFIG_NAME


def snapshot_path(run: Path | str, step: int) -> Path:
    """Where training saves the EMA snapshot of ``step`` in ``run``."""
    return Path(run) / "snapshots" / f"step_{step:08d}.pt"


def snapshot_steps(run: Path | str) -> list[int]:
    """The training steps of the EMA snapshots saved in ``run``, ascending."""
    return sorted(int(p.stem.split("_")[1]) for p in (Path(run) / "snapshots").glob("step_*.pt"))


def eval_dir(run: Path | str) -> Path:
    return Path(run) / "eval"


def render_dir(run: Path | str) -> Path:
    return Path(run) / "render"
