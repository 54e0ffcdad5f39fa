"""Shared fixtures: one tiny umaze dataset (a few thousand steps) and two tiny trained runs on it."""

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


@pytest.fixture(scope="session")
def tiny_runs(tiny_dataset, tmp_path_factory) -> dict:
    """A DDPM run and a bridge run from a learned prior (horizon 32, 3 steps each, EMA snapshots at steps 2
    and 3), trained through the CLI."""
    from bridgeplan.cli import main
    from tests.test_train import train_args

    root = tmp_path_factory.mktemp("runs")
    prior = root / "prior"
    assert main(["train-prior", "--maze", "umaze", "--dataset", tiny_dataset, "--run-dir", str(prior),
                 "--horizon", "32", "--steps", "3", "--no-progress", "--device", "cpu"]) == 0
    runs = {"ddpm": root / "ddpm", "bridge": root / "bridge"}
    assert main(train_args(tiny_dataset, runs["ddpm"], 3, "--checkpoint-every", "2")) == 0
    assert main(train_args(tiny_dataset, runs["bridge"], 3, "--checkpoint-every", "2", "--process", "bridge",
                           "--prior", "learned", "--prior-run", str(prior))) == 0
    return runs


@pytest.fixture(scope="session")
def medium_navigate(tmp_path_factory) -> str:
    """OGBench's pointmaze-medium-navigate-v0 dataset by its recipe: at its default place if it is there
    (``datasets/ogbench``, or under ``$BRIDGEPLAN_DATASETS``), else made here (a few minutes: slow tests only)."""
    from bridgeplan.cli import main
    from bridgeplan.paths import datasets_root

    dataset = datasets_root() / "ogbench" / "pointmaze-medium-navigate-v0.npz"
    if not dataset.exists():
        folder = tmp_path_factory.mktemp("ogbench")
        assert main(["data", "generate", "--maze", dataset.stem, "--out", str(folder), "--no-progress"]) == 0
        dataset = folder / dataset.name
    return str(dataset.resolve())
