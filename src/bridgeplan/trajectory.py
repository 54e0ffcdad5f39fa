"""The trajectory layout shared by data, networks, processes and planner.

A trajectory is a tensor ``[batch, horizon, transition_dim]`` whose columns are ``(actions, state)``: the
environment's :class:`Layout` says how many of each and which state columns are the position and the
velocity. Maze2D's (:data:`MAZE2D`) is Diffuser's ``(ax, ay, x, y, vx, vy)``; OGBench pointmaze's kinematic
point (:data:`KINEMATIC_POINT`) is ``(ax, ay, x, y)``; an environment's family names its own
(:meth:`bridgeplan.envs.family.Family.layout`).
Goal reaching is inpainting: ``conditions`` maps a time index to the state (normalized) that the trajectory
must have there, ``{0: start, horizon - 1: goal}``, each ``[batch, obs_dim]``; a row of NaN leaves that
trajectory free at that index (conditions that hold for some episodes of a batch only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from bridgeplan.errors import BridgeplanError

Conditions = dict[int, torch.Tensor]


@dataclass(frozen=True)
class Layout:
    """The columns of one transition: ``act_dim`` actions, then ``obs_dim`` state columns, of which ``goal_dim`` are
    the position (x, y: what a goal gives), two, if the environment observes it, the velocity (vx, vy), and the rest
    (a user's environment's, :mod:`bridgeplan.envs.goal_env`) what neither a goal nor a prior says: a goal leaves
    them free, the line prior holds them at the start's.

    The accessors take ``[..., transition_dim]`` transitions (``actions``, ``states``, ``positions``,
    ``velocities``) or ``[..., obs_dim]`` states alone (``state_positions``, ``state_velocities``), numpy or
    torch, and return views: assigning into them writes the trajectory.
    """

    name: str
    """How errors and docs name it (``maze2d``, ``kinematic point``)."""
    act_dim: int
    """Action columns, the first of a transition."""
    obs_dim: int
    """State columns, after the actions; a condition is a whole state."""
    position: int
    """Index in the state of the position's first column (x; y follows)."""
    velocity: int | None
    """Index in the state of the velocity's first column (vx; vy follows), or None: the state has none."""
    goal_dim: int = 2
    """Columns of the position, the part of the state a goal gives."""
    rest: bool = False
    """Whether the state has columns beyond the position and the velocity (else it is those alone)."""
    goal: tuple[int, ...] = ()
    """Where a goal is not a position (a manipulation task's object positions and switch states, not the robot's
    pose): the state's columns it names, a goal then being a whole goal observation of which those columns count;
    the state may hold other columns. Empty: a goal is a position (``goal_dim`` columns)."""

    def __post_init__(self):
        columns = sorted([*range(self.position, self.position + self.goal_dim),
                          *([] if self.velocity is None else [self.velocity, self.velocity + 1])])
        inside = len(set(columns)) == len(columns) and columns[0] >= 0 and columns[-1] < self.obs_dim
        if self.goal:  # a state with columns of its own (a robot's joints): the named ones must lie in it
            fits = inside and min(self.goal) >= 0 and max(self.goal) < self.obs_dim
        else:
            fits = columns == list(range(self.obs_dim)) or (self.rest and inside)
        if self.act_dim < 1 or self.goal_dim < 1 or not fits:
            raise ValueError(f"layout {self.name}: a state is a position and optionally a velocity (two columns), "
                             f"and the rest only where declared (or where its goal names columns), and a transition "
                             f"has actions; got act_dim {self.act_dim}, obs_dim {self.obs_dim}, position at "
                             f"{self.position} ({self.goal_dim} columns), velocity at {self.velocity}, "
                             f"goal {self.goal}")

    @property
    def transition_dim(self) -> int:
        return self.act_dim + self.obs_dim

    @property
    def has_velocity(self) -> bool:
        return self.velocity is not None

    @property
    def state_columns(self) -> slice:
        """The state's columns in a transition (the normalizer's ``dims`` for states)."""
        return slice(self.act_dim, None)

    def actions(self, x):
        return x[..., :self.act_dim]

    def states(self, x):
        return x[..., self.act_dim:]

    def positions(self, x):
        return x[..., self.act_dim + self.position:self.act_dim + self.position + self.goal_dim]

    def velocities(self, x):
        return self.states(x)[..., self._velocity_columns()]

    def state_positions(self, s):
        return s[..., self.position:self.position + self.goal_dim]

    def state_velocities(self, s):
        return s[..., self._velocity_columns()]

    def _velocity_columns(self) -> slice:
        if self.velocity is None:
            raise BridgeplanError(f"the {self.name} layout has no velocity columns (its state is the position)")
        return slice(self.velocity, self.velocity + 2)

    @property
    def goal_width(self) -> int:
        """A goal's width as an environment gives it: a whole goal observation where the layout names goal columns,
        else the position."""
        return self.obs_dim if self.goal else self.goal_dim

    @property
    def given_columns(self) -> list[int]:
        """The state's columns a goal gives: those the layout names, else the position's."""
        return list(self.goal) or list(range(self.position, self.position + self.goal_dim))

    def free_columns(self) -> list[int]:
        """The state's columns a goal leaves free: where the layout names goal columns every other one, else the rest
        (:meth:`rest_columns`; a goal position's velocity is given, at rest)."""
        if self.goal:
            return [c for c in range(self.obs_dim) if c not in self.goal]
        return self.rest_columns()

    def rest_columns(self) -> list[int]:
        """The state's columns that are neither the position nor the velocity."""
        taken = {*range(self.position, self.position + self.goal_dim),
                 *(() if self.velocity is None else (self.velocity, self.velocity + 1))}
        return [c for c in range(self.obs_dim) if c not in taken]

    def goal_only(self, states):
        """``states [..., obs_dim]`` (numpy or torch, a copy) with every column but the goal's NaN, i.e. free in a
        condition (:func:`apply_conditions`); as they are where the layout names no goal columns."""
        if not self.goal:
            return states
        free = np.ones(self.obs_dim, dtype=bool)
        free[list(self.goal)] = False
        if isinstance(states, torch.Tensor):
            out = states.clone()
            out[..., torch.as_tensor(free, device=states.device)] = float("nan")
            return out
        out = np.array(states, dtype=np.float64)
        out[..., free] = np.nan
        return out

    def goal_states(self, goals: np.ndarray) -> np.ndarray:
        """The states a planner's goal condition holds: goal positions ``[..., 2]`` at rest; where the layout names goal
        columns, goal observations ``[..., obs_dim]`` with every other column free (:meth:`goal_only`)."""
        if not self.goal:
            return self.at_rest(goals)
        goals = np.asarray(goals, dtype=np.float64)
        if goals.shape[-1] != self.obs_dim:
            raise BridgeplanError(f"a {self.name} goal is a {self.obs_dim}-D goal observation (its columns "
                                  f"{list(self.goal)} are the task's), got {goals.shape[-1]}-D")
        return self.goal_only(goals)

    def at_rest(self, positions: np.ndarray) -> np.ndarray:
        """States ``[..., obs_dim]`` at ``positions [..., goal_dim]``, with zero velocity where the state has one and
        NaN (free, as a condition) in the rest."""
        positions = np.asarray(positions, dtype=np.float64)
        states = np.zeros((*positions.shape[:-1], self.obs_dim))
        states[..., self.rest_columns()] = np.nan
        self.state_positions(states)[...] = positions
        return states


MAZE2D = Layout("maze2d", act_dim=2, obs_dim=4, position=0, velocity=2)
"""Maze2D (gymnasium-robotics PointMaze): actions are forces, the state ``(x, y, vx, vy)``."""
KINEMATIC_POINT = Layout("kinematic point", act_dim=2, obs_dim=2, position=0, velocity=None)
"""OGBench pointmaze: actions are position steps (scaled by the environment's gain), the state ``(x, y)``."""


def apply_conditions(x: torch.Tensor, conditions: Conditions) -> torch.Tensor:
    """Overwrite the state columns of ``x`` at the conditioned time indices (returns a new tensor); rows of
    ``state`` that are NaN leave theirs as they are.

    Used by training and by every sampler step alike, so conditions hold exactly in every sample. A condition
    is a whole state and every layout puts the state last, so its width says which columns it covers: the
    processes stay free of layouts.
    """
    x = x.clone()
    for t, state in conditions.items():
        state = state.to(x.dtype)
        columns = slice(x.shape[-1] - state.shape[-1], None)
        x[:, t, columns] = torch.where(torch.isnan(state), x[:, t, columns], state)
    return x


def window_conditions(x0: torch.Tensor, layout: Layout, subgoal_every: int = 0) -> Conditions:
    """Start and goal conditions of a training window ``[B, H, D]``: its first and last states (Diffuser; of the last,
    the goal's columns alone where the layout names them, as a planner's goal holds them); for a
    hierarchy's low level (``subgoal_every`` j > 0) every j-th state as well (the last one is the goal)."""
    last = x0.shape[1] - 1
    indices = [0, *range(subgoal_every, last, subgoal_every), last] if subgoal_every else [0, last]
    conditions = {t: layout.states(x0[:, t]) for t in indices}
    if not subgoal_every:  # a goal names its own columns (all, but where the layout says which)
        conditions[last] = layout.goal_only(conditions[last])
    return conditions


def span(horizon: int, stride: int) -> int:
    """Environment steps covered by ``horizon`` planned states ``stride`` steps apart (both ends included)."""
    return (horizon - 1) * stride + 1


def densify(x, stride: int):
    """Plans ``x [N, H, D]`` whose states are ``stride`` environment steps apart, linearly interpolated to every
    step: ``[N, (H - 1) * stride + 1, D]``, equal to ``x`` at every ``stride``-th step."""
    x = np.asarray(x)
    if stride == 1:
        return x
    frac = (np.arange(stride) / stride)[None, None, :, None]
    a, b = x[:, :-1, None], x[:, 1:, None]
    inner = (a + frac * (b - a)).reshape(len(x), -1, x.shape[2])
    return np.concatenate([inner, x[:, -1:]], axis=1)
