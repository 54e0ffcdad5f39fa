"""How a plan is executed in the maze: the point mass's :data:`BODY` for the controllers of
:mod:`bridgeplan.envs.controllers`.

A plan is a batch of planned states ``[N, H, 4]`` (x, y, vx, vy); its actions are ignored. The two controllers,
both stateless apart from a pursuer's progress along its plan:

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

from bridgeplan.envs.controllers import Body
from bridgeplan.envs.maze2d.expert import pd_action
from bridgeplan.trajectory import MAZE2D

# Maze2D's controllers read Maze2D states (x, y, vx, vy): the point mass's position and velocity
_position, _velocity = MAZE2D.state_positions, MAZE2D.state_velocities

DEFAULT_LOOKAHEAD = 1.0
"""Pursuit's default lookahead (maze units; a cell is 1): the middle of the measured 0.5-1.5; which is best
depends on the planner and its NFE (noisier plans want a longer one): choose it on validation episodes
(`experiment controllers --validation`; docs/results/controllers.md)."""


def tracking_action(state: np.ndarray, planned_next_state: np.ndarray) -> np.ndarray:
    """``clip((p_next - p) + (v_next - v), -1, 1)`` for ``state [N, 4]`` and ``planned_next_state [N, 4]``."""
    state, target = np.asarray(state, np.float64), np.asarray(planned_next_state, np.float64)
    return np.clip((_position(target) - _position(state)) + (_velocity(target) - _velocity(state)), -1.0, 1.0)


def pursuit_action(state: np.ndarray, waypoint: np.ndarray) -> np.ndarray:
    """The expert's PD law toward ``waypoint [N, 2]``: ``clip(10 (w - p) - v, -1, 1)``."""
    return np.clip(pd_action(waypoint, np.asarray(state, np.float64)), -1.0, 1.0)


BODY = Body(MAZE2D, tracking_action, pursuit_action, DEFAULT_LOOKAHEAD)
