"""How a plan is executed in the maze: the controller that turns planned states into actions.

A plan is a batch of planned states ``[N, H, 4]`` (x, y, vx, vy); its actions are ignored. Two controllers
(:data:`CONTROLLERS`), both stateless apart from a pursuer's progress along its plan:

- ``track``, Diffuser's tracking controller (the default and the thesis's protocol): at step ``t`` of a
  plan it drives the point mass toward the next planned state,
  ``a_t = clip((p_{t+1} - p_t) + (v_{t+1} - v_t), -1, 1)``, and after the plan's end it holds the last
  planned position with zero velocity. The plan's timing is executed as well as its path.
- ``pursuit``: the plan's path at the expert's pace. It drives toward the first planned position at least
  ``lookahead`` away from the point mass, among those not yet passed, with the expert's PD law
  ``clip(10 (w - p) - v, -1, 1)`` (:func:`bridgeplan.envs.maze2d.expert.pd_action`); the plan's last position (the
  goal) once every other is passed. Why: the dataset's expert is slowed by its action noise, so a plan that
  imitates it arrives late however well it is tracked; its path (which way round the walls) is what the model
  knows and the expert lacks nothing of. The lookahead trades speed for corner cutting.
"""

from __future__ import annotations

import numpy as np

from bridgeplan.envs.maze2d.expert import pd_action
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D

# Maze2D's controllers read Maze2D states (x, y, vx, vy): the point mass's position and velocity
_position, _velocity = MAZE2D.state_positions, MAZE2D.state_velocities

CONTROLLERS = ("track", "pursuit")
DEFAULT_LOOKAHEAD = 1.0
"""Pursuit's default lookahead (maze units; a cell is 1): the middle of the measured 0.5-1.5; which is best
depends on the planner and its NFE (noisier plans want a longer one): choose it on validation episodes
(`experiment controllers --validation`; docs/results/controllers.md)."""


def tracking_action(state: np.ndarray, planned_next_state: np.ndarray) -> np.ndarray:
    """``clip((p_next - p) + (v_next - v), -1, 1)`` for ``state [N, 4]`` and ``planned_next_state [N, 4]``."""
    state, target = np.asarray(state, np.float64), np.asarray(planned_next_state, np.float64)
    return np.clip((_position(target) - _position(state)) + (_velocity(target) - _velocity(state)), -1.0, 1.0)


def planned_target(plans: np.ndarray, t: int) -> np.ndarray:
    """The state ``[N, 4]`` to track at step ``t``: ``plans[:, t + 1]``, or after the plan's end its last
    position with zero velocity."""
    plans = np.asarray(plans, np.float64)
    if t + 1 < plans.shape[1]:
        return plans[:, t + 1]
    return MAZE2D.at_rest(_position(plans[:, -1]))


def planned_targets(plans: np.ndarray, steps_into_plan: np.ndarray) -> np.ndarray:
    """:func:`planned_target` with a step per plan: ``plans[n, s_n + 1]`` for ``steps_into_plan [N]`` (the
    steps since each plan was made; closed loop), or past its end its last position with zero velocity."""
    plans = np.asarray(plans, np.float64)
    steps = np.asarray(steps_into_plan, dtype=np.int64)
    horizon = plans.shape[1]
    rows = np.arange(len(plans))
    target = plans[rows, np.minimum(steps + 1, horizon - 1)].copy()
    ended = steps + 1 >= horizon
    _velocity(target)[ended] = 0.0
    return target


def tracking_actions(states: np.ndarray, plans: np.ndarray, t: int) -> np.ndarray:
    """Actions ``[N, 2]`` at step ``t`` for observed ``states [N, 4]`` tracking ``plans [N, H, 4]``."""
    return tracking_action(states, planned_target(plans, t))


def pursuit_waypoints(plans: np.ndarray, positions: np.ndarray, passed: np.ndarray,
                      lookahead: float) -> np.ndarray:
    """``[N]`` the index of each plan's waypoint: the first planned position at index >= ``passed [N]`` (the
    previous waypoint: progress along the plan never goes back, and a plan's stretch on the far side of a
    wall is not skipped to) that is at least ``lookahead`` from ``positions [N, 2]``; the plan's last index
    when there is none."""
    plans = np.asarray(plans, np.float64)
    horizon = plans.shape[1]
    far = np.linalg.norm(_position(plans) - np.asarray(positions, np.float64)[:, None], axis=2) >= lookahead
    far &= np.arange(horizon)[None, :] >= np.asarray(passed)[:, None]
    return np.where(far.any(axis=1), far.argmax(axis=1), horizon - 1)


class Follower:
    """A batch of ``n`` controllers of one kind (:data:`CONTROLLERS`) executing the newest plan of each
    episode. :meth:`new_plans` when episodes get a plan; :meth:`actions` at every step, with ``age [n]`` the
    steps since each plan was made; :meth:`drift` how far each episode is from its plan (``track``: from
    where the plan put it now; ``pursuit``: from the nearest point of the plan's path)."""

    def __init__(self, n: int, kind: str = "track", lookahead: float = DEFAULT_LOOKAHEAD):
        check_controller(kind, lookahead)
        self.kind, self.lookahead = kind, float(lookahead)
        self.passed = np.zeros(int(n), dtype=np.int64)

    def new_plans(self, episodes: np.ndarray) -> None:
        self.passed[episodes] = 0

    def actions(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        states = np.asarray(states, np.float64)
        if self.kind == "track":
            return tracking_action(states, planned_targets(plans, age))
        self.passed = pursuit_waypoints(plans, _position(states), self.passed, self.lookahead)
        waypoint = _position(np.asarray(plans, np.float64)[np.arange(len(states)), self.passed])
        return np.clip(pd_action(waypoint, states), -1.0, 1.0)

    def drift(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        positions = _position(np.asarray(states, np.float64))[:, None]
        if self.kind == "track":
            expected = _position(plans[np.arange(len(plans)), np.minimum(age, plans.shape[1] - 1)])
            return np.linalg.norm(positions[:, 0] - expected, axis=1)
        return np.linalg.norm(_position(np.asarray(plans, np.float64)) - positions, axis=2).min(axis=1)


def check_controller(kind: str, lookahead: float) -> None:
    if kind not in CONTROLLERS:
        raise BridgeplanError(f"unknown --controller {kind!r}: choose from {', '.join(CONTROLLERS)}")
    if not lookahead > 0:
        raise BridgeplanError(f"--lookahead must be > 0 (a distance in position), got {lookahead}")
