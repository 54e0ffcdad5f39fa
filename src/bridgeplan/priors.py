"""Priors: each maps the conditions (start, goal) to a whole trajectory x1 ``[B, H, D]`` (normalized).

A new prior is one small class with a ``name`` and ``sample(conditions, horizon, batch, generator)``,
registered in ``PRIORS``. Every prior returns its sample with the start and goal inpainted.
"""

from __future__ import annotations

import torch

from bridgeplan.data.normalizer import Normalizer
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import ACT_DIM, TRANSITION_DIM, Conditions, apply_conditions

SIM_DT = 0.01
"""Seconds per environment step (MuJoCo timestep, one step per action): converts positions to velocities."""


def _endpoints(conditions: Conditions, horizon: int) -> tuple[torch.Tensor, torch.Tensor]:
    return conditions[0], conditions[horizon - 1]


class GaussianPrior:
    """White noise: the bridge from it is a noise-to-data bridge (the thesis's control experiment)."""

    name = "gaussian"

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start = conditions[0]
        x = torch.randn((batch, horizon, TRANSITION_DIM), generator=generator, device=start.device)
        return apply_conditions(x, conditions)


class LinePrior:
    """Straight line from start to goal in position, walls ignored.

    Positions are evenly spaced over the H steps; the velocity is the constant one that covers the
    line in ``(H - 1) * SIM_DT`` seconds; the action is the unit vector toward the goal.
    """

    name = "line"

    def __init__(self, normalizer: Normalizer):
        self.normalizer = normalizer

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start_n, goal_n = _endpoints(conditions, horizon)
        state = slice(ACT_DIM, None)
        start = self.normalizer.unnormalize(start_n.double(), state)[:, :2]
        goal = self.normalizer.unnormalize(goal_n.double(), state)[:, :2]
        frac = torch.linspace(0, 1, horizon, dtype=torch.float64, device=start.device)[None, :, None]
        pos = start[:, None] + frac * (goal - start)[:, None]
        delta = goal - start
        vel = (delta / ((horizon - 1) * SIM_DT))[:, None].expand(-1, horizon, -1)
        direction = delta / delta.norm(dim=-1, keepdim=True).clamp_min(1e-9)
        act = direction[:, None].expand(-1, horizon, -1)
        traj = torch.cat([act, pos, vel], dim=-1)
        x = self.normalizer.normalize(traj).to(start_n.dtype)
        return apply_conditions(x, conditions)


class LearnedPrior:
    """The thesis's learned prior: an MLP on (start, goal) trained on the same windows (``train-prior``)."""

    name = "learned"

    def __init__(self, net: torch.nn.Module):
        self.net = net

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start, goal = _endpoints(conditions, horizon)
        with torch.no_grad():
            x = self.net(start, goal)
        return apply_conditions(x, conditions)


def train_prior_loss(net: torch.nn.Module, x0: torch.Tensor) -> torch.Tensor:
    """L2 between the net's trajectory for the window's (first, last) states and the window."""
    out = net(x0[:, 0, ACT_DIM:], x0[:, -1, ACT_DIM:])
    return torch.mean((out - x0) ** 2)


PRIORS = ("gaussian", "line", "learned")


def make_prior(name: str, normalizer: Normalizer, net: torch.nn.Module | None = None):
    """Build a prior by name; ``learned`` needs its trained ``net``."""
    if name == "gaussian":
        return GaussianPrior()
    if name == "line":
        return LinePrior(normalizer)
    if name == "learned":
        if net is None:
            raise BridgeplanError("the learned prior needs a trained network (--prior-run)")
        return LearnedPrior(net)
    raise BridgeplanError(f"unknown prior {name!r}: choose from {', '.join(PRIORS)}")
