"""Typed configs for every run. Frozen dataclasses, saved with every run and checkpoint.

The CLI maps its flags onto these; ``preset_config`` gives the defaults per maze and preset:
``diffuser`` follows Diffuser's Maze2D settings (REFERENCE §2), ``cpu-small`` is a smaller network
and schedule that trains on a 2-core CPU in minutes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.unet import UNetConfig


@dataclass(frozen=True)
class ProcessConfig:
    """The generative process that maps a prior sample to a plan."""

    name: str = "ddpm"
    """``ddpm`` (Diffuser's baseline) or ``bridge`` (I2SB)."""
    steps: int = 64
    """Number of diffusion steps N the network is trained with."""
    beta_max: float = 1.0
    """Bridge only: the largest beta of I2SB's symmetric schedule (I2SB used 0.3 and 1.0). 1.0 is the
    default because it scored far better on umaze (line prior, NFE 1: 88.8 vs 57.9; docs/results)."""
    ot_ode: bool = False
    """Bridge only: drop the noise of the training marginal and of the sampler (I2SB's OT-ODE)."""

    def params(self) -> dict[str, Any]:
        """Keyword arguments for ``processes.make_process``."""
        if self.name == "bridge":
            return {"steps": self.steps, "beta_max": self.beta_max, "ot_ode": self.ot_ode}
        return {"steps": self.steps}


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run of a planner (or of a learned prior)."""

    maze: str = "umaze"
    """Maze the data comes from and the planner is evaluated in."""
    dataset: str = ""
    """Path to the dataset directory (``bridgeplan data generate``) or a legacy D4RL hdf5 file."""
    horizon: int = 128
    """Planning horizon H (trajectory length); divisible by the U-Net's downsampling factor."""
    preset: str = "diffuser"
    """Name of the preset the defaults came from (``diffuser`` or ``cpu-small``)."""
    model: UNetConfig = field(default_factory=UNetConfig)
    process: ProcessConfig = field(default_factory=ProcessConfig)
    prior: str = "gaussian"
    """Prior the bridge starts from: ``gaussian``, ``line`` or ``learned`` (DDPM always uses noise)."""
    prior_run: str = ""
    """Run directory of a trained learned prior (``bridgeplan train-prior``); needed for ``learned``."""
    steps: int = 2_000_000
    """Optimizer steps to train for."""
    minutes: float = 0.0
    """Wall-clock budget in minutes; training stops at whichever of ``steps``/``minutes`` comes first (0: none)."""
    batch_size: int = 32
    grad_accum: int = 2
    """Gradient accumulation steps per optimizer step (Diffuser: 2)."""
    lr: float = 2e-4
    ema_decay: float = 0.995
    ema_every: int = 10
    """Update the EMA weights every this many optimizer steps."""
    ema_start: int = 2000
    """Before this step the EMA weights are a plain copy of the model."""
    checkpoint_every: int = 10_000
    """Write the resumable checkpoint and an EMA snapshot every this many steps."""
    log_every: int = 100
    seed: int = 0
    device: str = "auto"
    """``auto`` (CUDA when present), ``cpu``, ``cuda``, ``cuda:1``, ..."""
    threads: int = 0
    """CPU threads for torch (0: torch's default)."""

    def run_name(self) -> str:
        """Directory name of the run, derived from what distinguishes it."""
        parts = [self.maze, self.process.name]
        if self.process.name == "bridge":
            parts.append(self.prior)
        parts += [f"N{self.process.steps}", f"H{self.horizon}", self.preset, f"s{self.seed}"]
        return "-".join(parts)


@dataclass(frozen=True)
class PriorTrainConfig:
    """Training of the learned prior: the thesis's two-layer MLP on (start, goal)."""

    maze: str = "umaze"
    dataset: str = ""
    horizon: int = 128
    steps: int = 20_000
    minutes: float = 0.0
    batch_size: int = 64
    lr: float = 1e-3
    log_every: int = 100
    checkpoint_every: int = 5_000
    seed: int = 0
    device: str = "auto"
    threads: int = 0

    def run_name(self) -> str:
        return f"{self.maze}-prior-learned-H{self.horizon}-s{self.seed}"


# Diffuser's Maze2D settings per maze (REFERENCE §2): horizon and diffusion steps.
_DIFFUSER_MAZE = {"umaze": (128, 64), "medium": (256, 256), "large": (384, 256), "open": (128, 64)}
PRESETS = ("diffuser", "cpu-small")


def preset_config(maze: str, preset: str = "diffuser", **overrides: Any) -> TrainConfig:
    """Default training config for ``maze`` and ``preset``, with field ``overrides`` applied."""
    if maze not in _DIFFUSER_MAZE:
        raise BridgeplanError(f"unknown maze {maze!r}: choose from {', '.join(_DIFFUSER_MAZE)}")
    horizon, n_steps = _DIFFUSER_MAZE[maze]
    if preset == "diffuser":
        base = TrainConfig(maze=maze, preset=preset, horizon=horizon,
                           process=ProcessConfig(steps=n_steps))
    elif preset == "cpu-small":
        base = TrainConfig(
            maze=maze, preset=preset, horizon=horizon,
            model=UNetConfig(dim=16, dim_mults=(1, 2, 4)),
            process=ProcessConfig(steps=16),  # the thesis's 16 diffusion steps
            steps=200_000, batch_size=32, grad_accum=1, lr=1e-3,
            # a short run needs a short EMA window (~200 steps), not Diffuser's ~2000
            ema_every=1, ema_start=200, checkpoint_every=1000, log_every=50,
        )
    else:
        raise BridgeplanError(f"unknown preset {preset!r}: choose from {', '.join(PRESETS)}")
    return replace(base, **overrides)


def replace(config, **changes: Any):
    """``dataclasses.replace`` that also accepts nested dataclass fields given as dicts."""
    for name, value in list(changes.items()):
        current = getattr(config, name)
        if dataclasses.is_dataclass(current) and isinstance(value, dict):
            changes[name] = dataclasses.replace(current, **value)
    return dataclasses.replace(config, **changes)


def to_dict(config) -> dict[str, Any]:
    """JSON-ready dict of a config (tuples become lists)."""
    return dataclasses.asdict(config)


def from_dict(cls, d: dict[str, Any]):
    """Rebuild a (possibly nested) config dataclass from :func:`to_dict`'s output."""
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in d:
            continue
        value = d[f.name]
        sub = {"model": UNetConfig, "process": ProcessConfig}.get(f.name) if cls is TrainConfig else None
        if sub is not None:
            value = from_dict(sub, value)
        elif isinstance(value, list):
            value = tuple(value)
        kwargs[f.name] = value
    return cls(**kwargs)
