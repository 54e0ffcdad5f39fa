"""Typed configs for every run. Frozen dataclasses, saved with every run and checkpoint.

The CLI maps its flags onto these; ``preset_config`` gives the defaults per maze and preset:
``diffuser`` follows Diffuser's Maze2D settings (Janner et al. 2022, its ``config/maze2d.py``: horizon
128/256/384 and 64/256/256 diffusion steps for umaze/medium/large), ``cpu-small`` is a smaller network
and schedule that trains on a 2-core CPU in minutes. The process (``DDPM``, ``Bridge``) is itself the
process config: one definition that training, evaluation, sweeps and reports ask.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from bridgeplan.envs import family_of
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.nets.unet import UNetConfig
from bridgeplan.priors import PRIORS, REPLAN_ONLY
from bridgeplan.processes import DDPM, Process, make_process, process_from_dict
from bridgeplan.trajectory import Layout, span

PRESETS = ("diffuser", "cpu-small")


def plan_shape(maze: str, preset: str) -> tuple[int, int]:
    """``(horizon, stride)`` of ``preset``'s plans in environment ``maze``: its family's
    (:meth:`~bridgeplan.envs.family.Family.plan_shape`)."""
    check_choice("preset", preset, PRESETS)
    return family_of(maze).plan_shape(maze, preset)


def _check_horizon(maze: str, horizon: int, stride: int) -> None:
    if stride < 1:
        raise BridgeplanError(f"stride must be >= 1 (environment steps between planned states), got {stride}")
    # a plan must also fit its dataset's episodes (an OGBench stitch dataset's are 201 steps)
    episode = family_of(maze).longest_span(maze)
    if horizon < 2 or span(horizon, stride) > episode:
        at = f" at stride {stride}" if stride > 1 else ""
        raise BridgeplanError(f"horizon {horizon}{at} does not fit {maze}: a plan spans (horizon - 1) * stride + 1 "
                              f"= {span(horizon, stride)} steps, at least 2 and at most {episode} (the maze's "
                              f"episode length)")


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run of a planner (or of a learned prior)."""

    maze: str = "umaze"
    """Maze the data comes from and the planner is evaluated in: a Maze2D maze (``umaze``, ...) or an OGBench
    pointmaze dataset's name (``pointmaze-medium-navigate-v0``: its maze, and the kind of data it holds)."""
    dataset: str = ""
    """Path to the dataset directory (``bridgeplan data generate``) or a legacy D4RL hdf5 file; for OGBench
    pointmaze, the dataset's ``.npz`` file (``bridgeplan data generate``, or an official one)."""
    horizon: int = 128
    """Planning horizon H (planned states); divisible by the U-Net's downsampling factor."""
    stride: int = 1
    """Environment steps between planned states: a plan spans ``(H - 1) * stride + 1`` steps and is linearly
    interpolated to every step for the controller (Hierarchical Diffuser's high level plans every 15th state).
    1 is Diffuser's (every state); a larger stride buys a long span with a short, cheap network input."""
    preset: str = "diffuser"
    """Name of the preset the defaults came from (``diffuser`` or ``cpu-small``)."""
    model: UNetConfig = field(default_factory=UNetConfig)
    process: Process = field(default_factory=DDPM)
    """The generative process and its parameters (``DDPM(steps=64)``, ``Bridge(steps=16, beta_max=1.0)``);
    saved as ``process.to_dict()``."""
    prior: str = "gaussian"
    """What the process starts from: ``gaussian``, ``line`` or ``learned``; a process that does not take
    a prior (DDPM) always starts from ``gaussian``."""
    prior_run: str = ""
    """Run directory of a trained learned prior (``bridgeplan train-prior``); needed for ``learned``."""
    steps: int = 2_000_000
    """Optimizer steps to train for."""
    minutes: float = 0.0
    """Wall-clock budget in minutes; training stops at whichever of ``steps``/``minutes`` comes first (0: none)."""
    batch_size: int = 32
    """Windows per gradient (per accumulation step)."""
    grad_accum: int = 2
    """Gradient accumulation steps per optimizer step (Diffuser: 2)."""
    lr: float = 2e-4
    """Adam's learning rate (a positive, finite number)."""
    ema_decay: float = 0.995
    """Decay of the EMA weights (Diffuser: 0.995); plans are sampled from them."""
    ema_every: int = 10
    """Update the EMA weights every this many optimizer steps."""
    ema_start: int = 2000
    """Before this step the EMA weights are a plain copy of the model."""
    checkpoint_every: int = 10_000
    """Write the resumable checkpoint and an EMA snapshot every this many steps."""
    log_every: int = 100
    """Write a line of ``metrics.jsonl`` every this many steps."""
    seed: int = 0
    """Seeds the initial weights and the windows' sampling."""
    device: str = "auto"
    """``auto`` (CUDA when present), ``cpu``, ``cuda``, ``cuda:1``, ..."""
    threads: int = 0
    """CPU threads for torch (0: automatic, see ``device.configure_threads``: one on a CPU device)."""
    hold_share: float = 0.0
    """Share of training windows that wait still from a random index on (``data.windows.hold_tails``): the
    expert's windows never stop, so plans conditioned to end at the goal at H - 1 spend the whole horizon
    getting there; trained with some windows that arrive early and wait, a plan may too (0: Diffuser's)."""
    precision: str = "fp32"
    """``fp32``, or ``bf16``: the network's forward and backward passes under bfloat16 autocast (weights,
    optimizer and loss stay float32); refused on a device without bfloat16 kernels."""
    compile: bool = False
    """Train through ``torch.compile``'d network (compiles at the first step; may be changed on resume)."""
    subgoal_every: int = 0
    """The low level of a hierarchy (:mod:`bridgeplan.hierarchy`): every ``subgoal_every``-th planned state
    (``j, 2j, ..., H - 1``) is a condition besides the start, in training the window's own states, in planning
    a high-level plan's (whose stride must be ``subgoal_every * stride``); 0: the start and the goal only."""

    def __post_init__(self):
        family_of(self.maze)
        _check_horizon(self.maze, self.horizon, self.stride)
        check_prior(self.process, self.prior)
        check_subgoals(self.horizon, self.subgoal_every, self.prior)
        check_optimization(self)
        if not 0 <= self.hold_share <= 1:
            raise BridgeplanError(f"hold_share must be in [0, 1], got {self.hold_share}")
        if self.grad_accum < 1:
            raise BridgeplanError(f"grad_accum must be >= 1, got {self.grad_accum}")
        if not 0 <= self.ema_decay <= 1:
            raise BridgeplanError(f"ema_decay must be in [0, 1], got {self.ema_decay}")
        if self.ema_every < 1 or self.ema_start < 0:
            raise BridgeplanError(f"ema_every must be >= 1 and ema_start >= 0, got {self.ema_every}, {self.ema_start}")
        check_choice("precision", self.precision, PRECISIONS)
        if self.compile and self.process.forward_mode:
            raise BridgeplanError(f"--compile: the {self.process.display_name} trains through a Jacobian-vector "
                                  "product (forward-mode AD), which a torch.compile'd network does not support: "
                                  "train without --compile")

    @property
    def layout(self) -> Layout:
        """The columns of the run's transitions: its environment family's."""
        return family_of(self.maze).layout(self.maze)

    def run_name(self) -> str:
        """Directory name of the run, derived from what distinguishes it."""
        hold = [f"hold{self.hold_share:g}"] if self.hold_share else []
        subgoals = [f"sg{self.subgoal_every}"] if self.subgoal_every else []
        parts = [family_of(self.maze).label(self.maze), *self.process.run_tag(self.prior), *hold,
                 _horizon_tag(self.horizon, self.stride), *subgoals, self.preset, f"s{self.seed}"]
        return "-".join(parts)

    def label(self) -> str:
        """The method's name in tables and figures, e.g. ``bridge (line)``, ``DDPM, hold 0.5``."""
        return method_label(self.process, self.prior, self.hold_share)


PRECISIONS = ("fp32", "bf16")


def check_optimization(config) -> None:
    """The fields every training config shares, checked before anything is built or written."""
    for name in ("steps", "batch_size", "checkpoint_every", "log_every"):
        if getattr(config, name) <= 0:
            raise BridgeplanError(f"{name} must be positive, got {getattr(config, name)}")
    if config.seed < 0:
        raise BridgeplanError(f"seed must be >= 0, got {config.seed}")
    if not (math.isfinite(config.lr) and config.lr > 0):
        raise BridgeplanError(f"lr must be a positive, finite number, got {config.lr}")
    if not (math.isfinite(config.minutes) and config.minutes >= 0):
        raise BridgeplanError(f"minutes must be >= 0, got {config.minutes}")


def method_label(process: Process, prior: str, hold_share: float = 0.0) -> str:
    """A trained method's name: its process's label from ``prior``, and the share of waiting windows if any."""
    label = process.label(prior)
    return f"{label}, hold {hold_share:g}" if hold_share else label


def check_prior(process: Process, prior: str) -> None:
    """The one rule tying processes to priors: a process without a prior starts from Gaussian noise."""
    check_choice("prior", prior, PRIORS)
    if prior in REPLAN_ONLY:
        raise BridgeplanError(f"the {prior} prior is only valid on replans (eval --replan-every K --prior {prior}), "
                              f"not for training")
    if not process.uses_prior and prior != "gaussian":
        raise BridgeplanError(f"{process.display_name} starts from Gaussian noise; --prior {prior} needs a "
                              f"process that takes a prior (bridge)")


def check_subgoals(horizon: int, every: int, prior: str) -> None:
    """A low level's subgoals fit its horizon (every ``every``-th state, the last at H - 1); the coarse prior, the
    line through the subgoals, exists only where there are subgoals."""
    if every < 0:
        raise BridgeplanError(f"subgoal_every must be >= 0, got {every}")
    if every and (every >= horizon - 1 or (horizon - 1) % every):
        raise BridgeplanError(f"subgoal_every {every} does not divide the plan into whole pieces: (horizon - 1) = "
                              f"{horizon - 1} must be a multiple of it, larger than it")
    if prior == "coarse" and not every:
        raise BridgeplanError("the coarse prior is the line through a hierarchy's subgoals: give --subgoal-every")


@dataclass(frozen=True)
class PriorTrainConfig:
    """Training of the learned prior: the thesis's two-layer MLP on (start, goal)."""

    maze: str = "umaze"
    dataset: str = ""
    preset: str = "diffuser"
    """The planner preset whose plans the prior serves: ``horizon`` and ``stride`` 0 take its values."""
    horizon: int = 0
    """Horizon of the planner runs that will use the prior (0: ``preset``'s for the maze)."""
    stride: int = 0
    """Stride of the planner runs that will use the prior (0: ``preset``'s for the maze)."""
    steps: int = 20_000
    minutes: float = 0.0
    batch_size: int = 64
    lr: float = 1e-3
    log_every: int = 100
    checkpoint_every: int = 5_000
    seed: int = 0
    device: str = "auto"
    threads: int = 0

    def __post_init__(self):
        check_optimization(self)
        horizon, stride = plan_shape(self.maze, self.preset)
        if self.horizon == 0:
            object.__setattr__(self, "horizon", horizon)
        if self.stride == 0:
            object.__setattr__(self, "stride", stride)
        _check_horizon(self.maze, self.horizon, self.stride)

    @property
    def layout(self) -> Layout:
        return family_of(self.maze).layout(self.maze)

    def run_name(self) -> str:
        return (f"{family_of(self.maze).label(self.maze)}-prior-learned-{_horizon_tag(self.horizon, self.stride)}"
                f"-s{self.seed}")


def learned_prior_config(planner: TrainConfig, steps: int, **fields: Any) -> PriorTrainConfig:
    """The learned prior ``planner``'s runs sample from: the thesis's MLP trained on the same windows (maze, dataset,
    horizon, stride), on the same device and threads, for ``steps`` (one snapshot, at the end); ``fields`` set
    the rest (the seed, the dataset where the planner's is not yet set)."""
    shared = {"maze": planner.maze, "dataset": planner.dataset, "horizon": planner.horizon, "stride": planner.stride,
              "seed": planner.seed, "device": planner.device, "threads": planner.threads}
    return PriorTrainConfig(**{**shared, **fields}, steps=steps, checkpoint_every=steps)


def _horizon_tag(horizon: int, stride: int) -> str:
    """``H128``, or ``H32k8`` for a stride (run names of stride 1 are unchanged)."""
    return f"H{horizon}" + (f"k{stride}" if stride > 1 else "")


def preset_config(maze: str, preset: str = "diffuser", **overrides: Any) -> TrainConfig:
    """Default training config for ``maze`` and ``preset``, with field ``overrides`` applied."""
    horizon, stride = plan_shape(maze, preset)
    family = family_of(maze)
    if preset == "diffuser":
        base = TrainConfig(maze=maze, preset=preset, horizon=horizon, process=DDPM(steps=family.diffusion_steps(maze)))
    else:
        batch_size, lr = family.batch(maze, preset) or (32, 1e-3)
        base = TrainConfig(
            maze=maze, preset=preset, horizon=horizon, stride=stride,
            model=UNetConfig(dim=16, dim_mults=(1, 2, 4)),
            process=DDPM(steps=16),  # the thesis's 16 diffusion steps
            steps=200_000, batch_size=batch_size, grad_accum=1, lr=lr,
            # a short run needs a short EMA window (~200 steps), not Diffuser's ~2000
            ema_every=1, ema_start=200, checkpoint_every=1000, log_every=50,
        )
    return replace(base, **overrides)


def replace(config, **changes: Any):
    """``dataclasses.replace`` that also accepts nested dataclass fields given as dicts.

    A process given as a dict may name another process (``{"name": "bridge"}``): it then starts from
    that process's defaults with the current number of steps.
    """
    for name, value in list(changes.items()):
        current = getattr(config, name)
        if isinstance(current, Process) and isinstance(value, dict):
            kind = value.get("name", current.name)
            base = current.to_dict() if kind == current.name else {"steps": current.steps}
            params = {k: v for k, v in (base | value).items() if k != "name"}
            changes[name] = make_process(kind, **params)
        elif dataclasses.is_dataclass(current) and isinstance(value, dict):
            changes[name] = dataclasses.replace(current, **value)
    return dataclasses.replace(config, **changes)


def to_dict(config) -> dict[str, Any]:
    """JSON-ready dict of a config (tuples become lists, a process its ``to_dict()``)."""
    out = dataclasses.asdict(config)
    if isinstance(config, TrainConfig):
        out["process"] = config.process.to_dict()
    return out


def from_dict(cls, d: dict[str, Any]):
    """Rebuild a (possibly nested) config dataclass from :func:`to_dict`'s output."""
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name not in d:
            continue
        value = d[f.name]
        if cls is TrainConfig and f.name == "process":
            value = process_from_dict(value)
        elif cls is TrainConfig and f.name == "model":
            value = from_dict(UNetConfig, value)
        elif isinstance(value, list):
            value = tuple(value)
        kwargs[f.name] = value
    return cls(**kwargs)
