"""Building the pieces of a run from its config, and loading a trained run back as a planner.

This is the one composition root: training, evaluation, sweeps and the bench all build their
windows, normalizer, network, prior and planner through these functions.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from bridgeplan import config as cfg
from bridgeplan.checkpoint import load_checkpoint
from bridgeplan.device import resolve_device
from bridgeplan.envs import family_of
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.prior_mlp import PriorMLP
from bridgeplan.nets.unet import FrozenUNet, TemporalUNet
from bridgeplan.normalizer import Normalizer
from bridgeplan.paths import checkpoint_path, snapshot_path, snapshot_steps
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.trajectory import Layout


def windows_of(stream, horizon: int, stride: int = 1):
    """Training windows of ``stream`` and the normalizer fitted to it (Diffuser: the whole dataset)."""
    from bridgeplan.data.windows import WindowDataset

    normalizer = Normalizer.fit(stream.transitions())
    return WindowDataset(stream, horizon, normalizer, stride), normalizer


def load_windows(dataset: str, maze: str, horizon: int, stride: int = 1):
    """:func:`windows_of` the dataset at ``dataset``, read and checked to be of environment ``maze`` by its
    family."""
    if not dataset:
        raise BridgeplanError("no dataset given: pass --dataset (see `bridgeplan data generate`)")
    return windows_of(family_of(maze).load_stream(dataset, maze), horizon, stride)


def build_model(config: cfg.TrainConfig) -> TemporalUNet:
    """The run's U-Net, with the second time input its process asks for (``Process.takes_interval``)."""
    return TemporalUNet.from_config(config.model, config.layout.transition_dim, horizon=config.horizon,
                                    interval=config.process.takes_interval)


def build_prior_net(layout: Layout, horizon: int) -> PriorMLP:
    return PriorMLP(layout.obs_dim, horizon, layout.transition_dim)


def build_prior(config: cfg.TrainConfig, normalizer: Normalizer, device: torch.device,
                prior_net: torch.nn.Module | None = None):
    """The prior ``config.prior``; ``learned`` loads its net from ``config.prior_run`` unless given one."""
    if config.prior != "learned" or prior_net is not None:
        return make_prior(config.prior, normalizer, config.layout, net=prior_net, stride=config.stride)
    if not config.prior_run:
        raise BridgeplanError("the learned prior needs --prior-run (a run of `bridgeplan train-prior`)")
    state = load_checkpoint(Path(config.prior_run))
    if state["kind"] != "prior":
        raise BridgeplanError(f"{config.prior_run} is not a learned-prior run")
    saved = state["config"]
    for name in ("maze", "horizon", "stride"):
        trained_for = saved.get(name, 1)  # runs from before strides planned every step
        if trained_for != getattr(config, name):
            raise BridgeplanError(f"learned prior {config.prior_run} was trained for {name} {trained_for!r}, "
                                  f"not {getattr(config, name)!r}")
    if state["normalizer"] != normalizer.to_dict():
        raise BridgeplanError(f"learned prior {config.prior_run} was trained on a different dataset")
    net = build_prior_net(config.layout, config.horizon)
    net.load_state_dict(state["model"])
    return make_prior("learned", normalizer, config.layout, net=net.to(device).eval())


def load_teacher(config: cfg.TrainConfig, normalizer: Normalizer, device: torch.device) -> torch.nn.Module | None:
    """The network a distilling process (``Process.distills``) trains against: the EMA weights of its ``teacher``
    run, checked to be a DDPM run of the same maze, plan shape, network, steps and data; None for the others."""
    process = config.process
    if not process.distills:
        return None
    if not process.teacher:
        raise BridgeplanError(f"{process.name} needs a teacher: --process-param teacher=RUN (a trained DDPM run)")
    path = Path(process.teacher)
    if not path.exists():
        raise BridgeplanError(f"teacher {process.teacher} does not exist")
    teacher, info = load_planner(path, device=str(device))
    if teacher.process.name != "ddpm":
        raise BridgeplanError(f"teacher {process.teacher} is a {teacher.process.display_name} run; {process.name} "
                              f"distills a DDPM run")
    for name in ("maze", "horizon", "stride", "subgoal_every", "model"):
        if getattr(info.config, name) != getattr(config, name):
            raise BridgeplanError(f"teacher {process.teacher} was trained for {name} {getattr(info.config, name)!r}, "
                                  f"not {getattr(config, name)!r}")
    if teacher.process.steps != process.steps:
        raise BridgeplanError(f"teacher {process.teacher} has {teacher.process.steps} diffusion steps, the student "
                              f"{process.steps} (give --diffusion-steps {teacher.process.steps})")
    if teacher.normalizer.to_dict() != normalizer.to_dict():
        raise BridgeplanError(f"teacher {process.teacher} was trained on a different dataset")
    return teacher.model.requires_grad_(False)


def build_planner(config: cfg.TrainConfig, model: torch.nn.Module, normalizer: Normalizer,
                  device: torch.device, prior_net: torch.nn.Module | None = None) -> Planner:
    """The planner of ``config`` around a network (trained or not)."""
    prior = build_prior(config, normalizer, device, prior_net)
    return Planner(model, config.process, prior, normalizer, config.horizon, device, config.layout, config.stride,
                   subgoal_every=config.subgoal_every)


@dataclass(frozen=True)
class RunInfo:
    """What a loaded checkpoint says about the run it came from."""

    path: Path
    """The run directory."""
    config: cfg.TrainConfig
    config_dict: dict
    """The config as saved (what the run was trained with)."""
    step: int
    elapsed_seconds: float
    dataset_covers_every_cell: bool = False
    """Known without the dataset at hand (a shipped planner's, checked when it was exported): its dataset visits
    every free cell, as Multi2D's goals need."""
    dataset: str = ""
    """What the run was trained on (``Stream.identity``: name, maze, size, data version, sha256 of the arrays);
    '' for a run saved before runs recorded it."""

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def portable_config(self) -> dict:
        """``config_dict`` as results record it: the dataset named by its directory (``medium-1000000-v2``) and a
        learned prior by its run's name, not by where they lay on the machine that trained the run, so that
        committed rows carry no absolute path (a distilled run's teacher likewise)."""
        out = dict(self.config_dict)
        if out.get("dataset"):
            out["dataset"] = Path(out["dataset"]).name
        if out.get("prior_run"):
            prior = Path(out["prior_run"])  # a run directory or one of its checkpoint files
            out["prior_run"] = (run_dir_of(prior) if prior.suffix == ".pt" else prior).name
        if out.get("process"):
            out["process"] = portable_process(out["process"])
        return out


def portable_process(process: dict) -> dict:
    """A process's dict (``Process.to_dict``) as results and evaluation JSONs record it: a distilled run's teacher
    by its run's name, not by where it lay on the machine that trained the run."""
    if not process.get("teacher"):
        return process
    return {**process, "teacher": run_dir_of(Path(process["teacher"])).name}


def load_planner(run: Path, snapshot: int | None = None, device: str = "auto", sampler: str | None = None,
                 eta: float = 0.0, compile: bool = False, frozen: bool = False) -> tuple[Planner, RunInfo]:
    """A planner from a run directory (EMA weights of the latest checkpoint, or of snapshot ``step``).

    ``sampler``/``eta`` choose how the process is sampled (DDPM: ``ancestral`` or ``ddim``), as
    ``planner.with_sampler`` does. ``compile`` wraps the network in ``torch.compile`` (off by default:
    see the benchmark in docs/results); ``frozen`` plans through it traced and frozen (:class:`FrozenUNet`: the same
    numbers, a batch-1 decision faster on a CPU).
    """
    if compile and frozen:
        raise BridgeplanError("--compile and --frozen are two ways of preparing the network: choose one")
    run_dir = run_dir_of(run)
    run = resolve_run(run)
    path = run if run.is_file() else (snapshot_path(run, snapshot) if snapshot is not None else checkpoint_path(run))
    if snapshot is not None and not path.exists():
        raise BridgeplanError(f"no snapshot at step {snapshot} in {run} (have: {snapshot_steps(run) or 'none'})")
    state = load_checkpoint(path)
    if state.get("shipped") and snapshot is not None and snapshot != state["step"]:
        raise BridgeplanError(f"shipped planner {state['shipped']!r} has the weights of step {state['step']} only, "
                              f"not {snapshot}")
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
    if frozen:
        model = FrozenUNet(model, config.horizon)
    planner = build_planner(config, model, normalizer, dev)
    if sampler is not None:
        planner = planner.with_sampler(sampler, eta)
    return planner, RunInfo(run_dir, config, state["config"], state["step"], state["elapsed_seconds"],
                            bool(state.get("dataset_covers_every_cell", False)), state.get("dataset", ""))


def resolve_run(run: str | Path) -> Path:
    """A run argument as a file or directory: the path itself when it exists (a run directory, its checkpoint or a
    snapshot), else a shipped planner's name (:mod:`bridgeplan.shipped`: its file in the package, checked against
    the manifest's sha256). The one place ``eval``, ``render``, ``PlannerPolicy.from_run`` and the others resolve
    a run; anything else is a :class:`BridgeplanError` that lists the shipped names."""
    from bridgeplan import shipped

    path = Path(run)
    if path.exists():
        return path
    entry = shipped.get(str(run))
    if entry is None:
        raise BridgeplanError(shipped.unknown_message(run))
    return shipped.verified_path(entry)


def run_dir_of(path: str | Path) -> Path:
    """The run directory of a run, its checkpoint or one of its snapshots; for a shipped planner's name, where
    commands write beside it (``runs/shipped/NAME``, :func:`bridgeplan.shipped.output_dir`)."""
    from bridgeplan import shipped

    path = Path(path)
    if path.is_dir():
        return path
    if not path.exists() and shipped.get(str(path)) is not None:
        return shipped.output_dir(str(path))
    return path.parent.parent if path.parent.name == "snapshots" else path.parent
