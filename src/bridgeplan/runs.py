"""Building the pieces of a run from its config, and loading a trained run back as a planner."""

from __future__ import annotations

from pathlib import Path

import torch

from bridgeplan import config as cfg
from bridgeplan.checkpoint import load_checkpoint
from bridgeplan.data.normalizer import Normalizer
from bridgeplan.device import resolve_device
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.prior_mlp import PriorMLP
from bridgeplan.nets.unet import TemporalUNet
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.processes import make_process
from bridgeplan.trajectory import OBS_DIM, TRANSITION_DIM


def load_windows(dataset: str, maze: str, horizon: int):
    """Training windows of ``dataset`` and the normalizer fitted to it (Diffuser: the whole dataset)."""
    from bridgeplan.data import WindowDataset, load_stream

    if not dataset:
        raise BridgeplanError("no dataset given: pass --dataset (see `bridgeplan data generate`)")
    stream = load_stream(dataset)
    if stream.maze != maze:
        raise BridgeplanError(f"dataset {dataset} is from maze {stream.maze!r}, not {maze!r}")
    normalizer = Normalizer.fit(stream.transitions())
    return WindowDataset(stream, horizon, normalizer), normalizer


def build_model(config: cfg.TrainConfig) -> TemporalUNet:
    return TemporalUNet.from_config(config.model, TRANSITION_DIM, horizon=config.horizon)


def build_prior_net(horizon: int) -> PriorMLP:
    return PriorMLP(OBS_DIM, horizon, TRANSITION_DIM)


def build_prior(config: cfg.TrainConfig, normalizer: Normalizer, device: torch.device):
    """The prior the process starts from: DDPM always starts from noise; the bridge from ``config.prior``."""
    if config.process.name != "bridge":
        return make_prior("gaussian", normalizer)
    if config.prior != "learned":
        return make_prior(config.prior, normalizer)
    if not config.prior_run:
        raise BridgeplanError("the learned prior needs --prior-run (a run of `bridgeplan train-prior`)")
    state = load_checkpoint(Path(config.prior_run))
    if state["kind"] != "prior":
        raise BridgeplanError(f"{config.prior_run} is not a learned-prior run")
    saved = state["config"]
    for name in ("maze", "horizon"):
        if saved[name] != getattr(config, name):
            raise BridgeplanError(f"learned prior {config.prior_run} was trained for {name} {saved[name]!r}, "
                                  f"not {getattr(config, name)!r}")
    if state["normalizer"] != normalizer.to_dict():
        raise BridgeplanError(f"learned prior {config.prior_run} was trained on a different dataset")
    net = build_prior_net(config.horizon)
    net.load_state_dict(state["model"])
    return make_prior("learned", normalizer, net=net.to(device).eval())


def snapshot_path(run: Path, step: int) -> Path:
    """Where training saves the EMA snapshot of ``step`` in ``run``."""
    return Path(run) / "snapshots" / f"step_{step:08d}.pt"


def snapshot_steps(run: Path) -> list[int]:
    """The training steps of the EMA snapshots saved in ``run``, ascending."""
    return sorted(int(p.stem.split("_")[1]) for p in (Path(run) / "snapshots").glob("step_*.pt"))


def load_planner(run: Path, snapshot: int | None = None, device: str = "auto", sampler: str | None = None,
                 eta: float = 0.0, compile: bool = False) -> tuple[Planner, dict]:
    """A planner from a run directory (EMA weights of the latest checkpoint, or of snapshot ``step``).

    ``sampler``/``eta`` choose DDPM's sampler (``ancestral`` or ``ddim``); the bridge has one.
    ``compile`` wraps the network in ``torch.compile`` (off by default: see the benchmark in docs/results).
    """
    run = Path(run)
    path = run if run.is_file() else (
        snapshot_path(run, snapshot) if snapshot is not None else run / "checkpoint.pt")
    if snapshot is not None and not path.exists():
        raise BridgeplanError(f"no snapshot at step {snapshot} in {run} (have: {snapshot_steps(run) or 'none'})")
    state = load_checkpoint(path)
    if state["kind"] != "planner":
        raise BridgeplanError(f"{path} is a {state['kind']} checkpoint, not a planner")
    config = cfg.from_dict(cfg.TrainConfig, state["config"])
    dev = resolve_device(device)
    normalizer = Normalizer.from_dict(state["normalizer"])
    model = build_model(config)
    model.load_state_dict(state["ema"])
    model.to(dev).eval()
    if compile:
        model = torch.compile(model)
    params = config.process.params()
    if sampler is not None:
        if config.process.name != "ddpm":
            raise BridgeplanError(f"--sampler applies to ddpm runs; {path} is a {config.process.name} run")
        params |= {"sampler": sampler, "eta": eta}
    process = make_process(config.process.name, **params)
    prior = build_prior(config, normalizer, dev)
    planner = Planner(model, process, prior, normalizer, config.horizon, dev)
    return planner, {"config": config, "config_dict": state["config"], "step": state["step"],
                     "elapsed_seconds": state["elapsed_seconds"]}
