"""Shared fixtures: one tiny umaze dataset for the whole session (a few thousand steps)."""

from __future__ import annotations

import os

import pytest
import torch

os.environ.setdefault("MUJOCO_GL", "egl")
torch.set_num_threads(1)  # tiny networks: one thread is fastest, and CI has only 2 cores

TINY_STEPS = 6000


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> str:
    """A small umaze dataset written through the real CLI."""
    from bridgeplan.cli import main

    root = tmp_path_factory.mktemp("data") / "umaze-tiny"
    assert main(["data", "generate", "--maze", "umaze", "--steps", str(TINY_STEPS), "--seed", "1",
                 "--out", str(root), "--no-progress"]) == 0
    return str(root)
