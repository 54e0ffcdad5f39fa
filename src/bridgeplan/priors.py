"""Priors: each maps the conditions (start, goal) to a whole trajectory x1 ``[B, H, D]`` (normalized).

A prior is a small class with a ``name`` and ``sample(conditions, horizon, batch, generator=None)``;
``conditions`` are the planner's normalized ``{0: start, horizon - 1: goal}`` states ``[B, obs_dim]``.
Every prior returns its sample with the start and goal inpainted (``apply_conditions``).
Priors build trajectories in the run's :class:`~bridgeplan.trajectory.Layout` (the environment's columns).
A new prior is one class plus one entry in ``PRIORS`` (name -> builder from ``(normalizer, layout, net, stride)``).
Priors in ``REPLAN_ONLY`` (``warm``: the previous plan, shifted) exist only while executing closed loop;
they cannot be trained with and cannot make a first plan.
"""

from __future__ import annotations

from typing import Callable, Protocol

import torch

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.normalizer import Normalizer
from bridgeplan.trajectory import Conditions, Layout, apply_conditions, span

SIM_DT = 0.01
"""Seconds per environment step (MuJoCo timestep, one step per action): converts positions to velocities."""
MAX_SPEED = 5.0
"""The simulator clips each velocity component to this (``maze.sim.MAX_SPEED``; a test keeps them equal)."""


class Prior(Protocol):
    name: str

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor: ...


def _endpoints(conditions: Conditions, horizon: int, batch: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The start and goal states, checked against ``horizon`` and ``batch``."""
    if 0 not in conditions or horizon - 1 not in conditions:
        raise BridgeplanError(f"a prior needs conditions at t=0 and t={horizon - 1} (the horizon), "
                              f"got t={sorted(conditions)}")
    start, goal = conditions[0], conditions[horizon - 1]
    if start.shape[0] != batch or goal.shape[0] != batch:
        raise BridgeplanError(f"conditions have batch {start.shape[0]}, the prior was asked for {batch}")
    return start, goal


def straight_segment(start: torch.Tensor, goal: torch.Tensor, frac: torch.Tensor, steps: torch.Tensor,
                     layout: Layout, rest: torch.Tensor | None = None) -> torch.Tensor:
    """Physical trajectory ``[B, T, D]`` in ``layout`` along the straight line from ``start`` to ``goal``
    (``[B, 2]``) at the fractions ``frac`` ``[B or 1, T]`` of the way: positions on the line, where the state has
    a velocity the constant one that covers the line in ``steps`` ``[B, 1]`` environment steps (the data's
    velocities are per second; each component clipped to the simulator's ``MAX_SPEED``), and the unit vector
    toward the goal as the action (zero when start == goal): the data's actions come from a saturating
    controller, so their magnitude is about 1. ``rest`` ``[B, len(layout.rest_columns())]``: the state's other
    columns (a user's environment's), held along the segment (default 0)."""
    delta = goal - start
    horizon = frac.shape[1]
    traj = delta.new_zeros(len(delta), horizon, layout.transition_dim)
    layout.positions(traj)[...] = start[:, None] + frac[..., None] * delta[:, None]
    if layout.has_velocity:
        layout.velocities(traj)[...] = (delta[:, None] / (steps[..., None] * SIM_DT)).clamp(-MAX_SPEED, MAX_SPEED)
    layout.actions(traj)[...] = (delta / delta.norm(dim=-1, keepdim=True).clamp_min(1e-9))[:, None]
    if rest is not None:
        layout.states(traj)[..., layout.rest_columns()] = rest[:, None]
    return traj


def rest_of(states: torch.Tensor, layout: Layout) -> torch.Tensor:
    """``[B, len(layout.rest_columns())]`` the columns of states ``[B, obs_dim]`` that a line does not draw."""
    return states[:, layout.rest_columns()]


def line_between(start: torch.Tensor, goal: torch.Tensor, frac: torch.Tensor, steps: torch.Tensor,
                 layout: Layout) -> torch.Tensor:
    """Physical trajectory ``[B, T, D]`` from states ``start`` to goal states ``goal`` (``[B, obs_dim]``, physical; a
    goal's free columns NaN) at the fractions ``frac`` ``[B or 1, T]`` of the way, covered in ``steps`` ``[B, 1]``
    environment steps: where the layout's goal is a position, :func:`straight_segment` between the positions (the
    rest of the state held at the start's); where it names goal columns (a robot moving objects), the line in state
    space: every column the goal gives from the start's to the goal's, every other column held at the start's (the
    goal says nothing of the robot's pose, and a line through joint angles toward a guessed pose would only add a
    guess), the actions zero."""
    if not layout.goal:
        return straight_segment(layout.state_positions(start), layout.state_positions(goal), frac, steps, layout,
                                rest_of(start, layout))
    end = torch.where(torch.isnan(goal), start, goal)
    traj = start.new_zeros(len(start), frac.shape[1], layout.transition_dim)
    layout.states(traj)[...] = start[:, None] + frac[..., None] * (end - start)[:, None]
    return traj


class GaussianPrior:
    """White noise: the bridge from it is a noise-to-data bridge (the thesis's control experiment)."""

    name = "gaussian"

    def __init__(self, layout: Layout):
        self.layout = layout

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start, _ = _endpoints(conditions, horizon, batch)
        x = torch.randn((batch, horizon, self.layout.transition_dim), generator=generator, device=start.device,
                        dtype=start.dtype)
        return apply_conditions(x, conditions)


class LinePrior:
    """The thesis's analytical prior: a straight line from start to goal in position, walls ignored.

    In physical units, in the run's layout: positions evenly spaced over the H planned states (``start`` at t=0,
    ``goal`` at t=H-1); where the state has a velocity, the constant one that covers the line in
    ``(H - 1) * stride * SIM_DT`` seconds (the plan's span; the data's velocities are per second), each component
    clipped to the simulator's ``MAX_SPEED``;
    the constant action is the unit vector toward the goal (zero when start == goal): the data's actions come
    from a saturating waypoint controller, so their magnitude is about 1, and the tracking controller ignores
    planned actions anyway; the rest of the state, where it has more (a user's environment), at the start's values.
    Where the layout names goal columns (OGBench manipulation), the line in state space instead
    (:func:`line_between`). The result is normalized with the normalizer of the data, then the start state
    (with its velocity) and the goal state (zero velocity, from the planner) are inpainted.
    """

    name = "line"

    def __init__(self, normalizer: Normalizer, layout: Layout, stride: int = 1):
        self.normalizer, self.layout, self.stride = normalizer, layout, int(stride)

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start_n, goal_n = _endpoints(conditions, horizon, batch)
        layout = self.layout
        start = self.normalizer.unnormalize(start_n.double(), layout.state_columns)
        goal = self.normalizer.unnormalize(goal_n.double(), layout.state_columns)
        frac = torch.linspace(0, 1, horizon, dtype=torch.float64, device=start.device)[None, :]
        steps = float(max(horizon - 1, 1) * self.stride)
        steps = torch.full((batch, 1), steps, dtype=torch.float64, device=start.device)
        x = self.normalizer.normalize(line_between(start, goal, frac, steps, layout)).to(start_n.dtype)
        return apply_conditions(x, conditions)


class CoarsePrior(LinePrior):
    """A hierarchy's low-level prior (:mod:`bridgeplan.hierarchy`): the piecewise straight line through every
    fully conditioned state (the start, the subgoals, the goal), each piece drawn as :class:`LinePrior` draws a
    whole plan (velocity covering the piece in its steps, action toward its end), then the conditions inpainted.

    With only the start and the goal conditioned it is the line prior. In training the subgoals are the
    window's own states (``TrainConfig.subgoal_every``), so the prior is the window's coarse version; in
    planning they are a high-level plan's states, so the prior is that coarse plan, densified. Conditions
    with NaN rows (holds) are inpainted but are not knots; a goal whose given columns are set (``Layout.given_columns``;
    its rest, a user's environment's or an arm's pose, free) is one. Where the layout names goal columns, each piece is
    the line in state space (:func:`line_between`).
    """

    name = "coarse"

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start_n, _ = _endpoints(conditions, horizon, batch)
        layout = self.layout
        knots = sorted(t for t, state in conditions.items()  # a goal's free columns do not unmake a knot
                       if not bool(torch.isnan(state[..., layout.given_columns]).any()))
        states = {t: self.normalizer.unnormalize(conditions[t].double(), layout.state_columns) for t in knots}
        traj = torch.zeros(batch, horizon, layout.transition_dim, dtype=torch.float64, device=start_n.device)
        for a, b in zip(knots[:-1], knots[1:]):
            frac = torch.linspace(0, 1, b - a + 1, dtype=torch.float64, device=start_n.device)[None, :]
            steps = torch.full((batch, 1), float((b - a) * self.stride), dtype=torch.float64, device=start_n.device)
            traj[:, a:b + 1] = line_between(states[a], states[b], frac, steps, layout)
        x = self.normalizer.normalize(traj).to(start_n.dtype)
        return apply_conditions(x, conditions)


class LearnedPrior:
    """The thesis's learned prior: ``nets.prior_mlp.PriorMLP`` on (start, goal), deterministic.

    The net is trained on the same windows as the process with :func:`train_prior_loss`.
    """

    name = "learned"

    def __init__(self, net: torch.nn.Module):
        self.net = net

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        start, goal = _endpoints(conditions, horizon, batch)
        net_horizon = getattr(self.net, "horizon", horizon)
        if net_horizon != horizon:
            raise BridgeplanError(f"the learned prior was trained for horizon {net_horizon}, not {horizon}")
        goal = torch.where(torch.isnan(goal), start, goal)  # what a goal leaves free, as trained (train_prior_loss)
        with torch.no_grad():
            x = self.net(start, goal).to(start.dtype)
        return apply_conditions(x, conditions)


class WarmPrior:
    """Warm start for replanning: the previous plan of each episode, shifted by the steps elapsed since it was
    made, its tail extended toward the goal with the line prior's rule, the conditions re-applied.

    ``previous`` ``[B, S, D]`` are the previous plans as executed, in physical units (``layout``'s columns),
    one row per environment step (``S = (H - 1) * stride + 1``), and ``elapsed`` ``[B]`` the steps since each
    was made. The sample at planned index ``t`` is the previous plan at step
    ``t * stride + elapsed`` while that is inside it; after its end (the last ``elapsed`` steps) positions go
    in a straight line from the previous plan's last state to the goal condition at ``t = H - 1`` as
    :func:`line_between` draws it (in the plane: velocity clipped to ``MAX_SPEED``, actions the unit vector toward
    the goal; where the layout names goal columns, those columns toward the goal's, the others held): the previous
    plan ended at the goal, so this holds the goal, unless the goal has moved. Then the current state is inpainted
    at ``t = 0`` and the goal at ``t = H - 1`` (``apply_conditions``). Built without previous plans
    (``make_prior("warm", ...)``), it refuses to sample: a first plan has nothing to start from.
    """

    name = "warm"

    def __init__(self, normalizer: Normalizer, layout: Layout, previous=None, elapsed=None, stride: int = 1):
        self.normalizer, self.layout, self.stride = normalizer, layout, int(stride)
        self.previous = None if previous is None else torch.as_tensor(previous, dtype=torch.float64)
        self.elapsed = None if elapsed is None else torch.as_tensor(elapsed, dtype=torch.int64).reshape(-1)
        if self.previous is not None:
            if self.previous.ndim != 3 or self.previous.shape[2] != layout.transition_dim:
                raise BridgeplanError(f"previous plans must be [B, S, {layout.transition_dim}] ({layout.name} "
                                      f"layout), got {list(self.previous.shape)}")
            if self.elapsed is None or len(self.elapsed) != len(self.previous) or bool((self.elapsed < 0).any()):
                raise BridgeplanError("the warm prior needs one elapsed step count >= 0 per previous plan")

    def sample(self, conditions: Conditions, horizon: int, batch: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        if self.previous is None:
            raise BridgeplanError("the warm prior is only valid on replans: it starts from the previous plan, "
                                  "and a first plan has none")
        start_n, goal_n = _endpoints(conditions, horizon, batch)
        steps = span(horizon, self.stride)
        if tuple(self.previous.shape[:2]) != (batch, steps):
            raise BridgeplanError(f"the warm prior holds previous plans of shape {list(self.previous.shape[:2])}, "
                                  f"asked for batch {batch} and {steps} steps (horizon {horizon}, stride "
                                  f"{self.stride})")
        device = start_n.device
        prev = self.previous.to(device)
        elapsed = self.elapsed.to(device)[:, None]
        t = torch.arange(horizon, device=device)[None, :]
        src = (t * self.stride + elapsed).clamp(max=steps - 1)
        layout = self.layout
        traj = torch.gather(prev, 1, src[..., None].expand(-1, -1, layout.transition_dim)).clone()
        # the tail after the previous plan's end (planned index `end`, fractional at a stride): a straight
        # line from its last position to the goal
        end = (steps - 1 - elapsed).clamp(min=0).double() / self.stride
        left = (horizon - 1 - end).clamp(min=1e-9)
        goal = self.normalizer.unnormalize(goal_n.double(), layout.state_columns)
        line = line_between(layout.states(prev[:, -1]), goal, (t - end).clamp(min=0) / left,
                            (left * self.stride).clamp(min=1), layout)
        traj = torch.where((t > end)[..., None], line, traj)
        x = self.normalizer.normalize(traj).to(start_n.dtype)
        return apply_conditions(x, conditions)


def train_prior_loss(net: torch.nn.Module, x0: torch.Tensor, layout: Layout) -> torch.Tensor:
    """L2 between the net's trajectory for each window's (first, last) states and the window ``x0``; the last state's
    columns that a goal leaves free (a user's environment's rest, an arm's pose) are the first's, as
    :class:`LearnedPrior` plans."""
    start, goal = layout.states(x0[:, 0]), layout.states(x0[:, -1]).clone()
    goal[:, layout.free_columns()] = start[:, layout.free_columns()]
    out = net(start, goal)
    return torch.mean((out - x0) ** 2)


def _learned(net: torch.nn.Module | None) -> LearnedPrior:
    if net is None:
        raise BridgeplanError("the learned prior needs a trained network (--prior-run)")
    return LearnedPrior(net)


PRIORS: dict[str, Callable[[Normalizer, Layout, torch.nn.Module | None, int], Prior]] = {
    "gaussian": lambda normalizer, layout, net, stride: GaussianPrior(layout),
    "line": lambda normalizer, layout, net, stride: LinePrior(normalizer, layout, stride),
    "learned": lambda normalizer, layout, net, stride: _learned(net),
    "coarse": lambda normalizer, layout, net, stride: CoarsePrior(normalizer, layout, stride),
    "warm": lambda normalizer, layout, net, stride: WarmPrior(normalizer, layout, stride=stride),
}
REPLAN_ONLY = frozenset({"warm"})
"""Priors that start from a previous plan: valid on replans only (never for training or a first plan)."""


def make_prior(name: str, normalizer: Normalizer, layout: Layout, net: torch.nn.Module | None = None,
               stride: int = 1) -> Prior:
    """Build a prior by name for plans in ``layout`` whose states are ``stride`` steps apart; ``learned`` needs its
    trained ``net``."""
    check_choice("prior", name, PRIORS)
    return PRIORS[name](normalizer, layout, net, stride)
