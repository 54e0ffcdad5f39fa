"""How a plan is executed by OGBench's kinematic point: the controllers that turn planned positions into actions.

The point's action is a position step: each environment step moves it by ``GAIN * action`` (free space; the
walls stop it), the action clipped to [-1, 1] per component. So the action that moves the point from ``p`` to
a target ``w`` in one step is ``(w - p) / GAIN``, clipped where one step cannot get there
(:func:`step_action`). Plans are ``[N, S, 2]`` positions, one per environment step (``Plan.states``, densified
from a stride); their actions are ignored, as Maze2D's controllers ignore theirs. The two controllers of
:mod:`bridgeplan.envs.controllers`, with this body (:data:`BODY`):

- ``track`` (Diffuser's): at step ``t`` of a plan, the target is the plan's next state ``plan[t + 1]``, and after
  the plan's end its last position (the goal). The plan's timing is executed as well as its path: a plan that
  moves at the data's pace reproduces itself exactly while it moves less than ``GAIN`` per axis per step.
- ``pursuit``: the plan's path at the expert's pace. The waypoint is the first planned position, among those
  not yet passed and not behind the plan's schedule (the tracking target's index), at least ``lookahead`` from
  the point (the plan's last position once every other is passed),
  and the point steps toward it at the datasets' expert's speed, a unit action (the oracle's unit direction),
  i.e. :func:`step_action` toward the point one such step along the way; within one step of the waypoint it
  lands on it. Why not :func:`step_action` on the waypoint itself: a waypoint a lookahead away saturates both
  components, which would bend every move up to 45 degrees toward a diagonal. Why the expert's pace: the data's
  expert is slowed by its action noise (0.80-0.88 of the oracle's progress per step), so a plan that imitates
  it arrives late however well it is tracked. Why never behind the schedule: a plan that cuts a wall corner
  puts a waypoint behind the wall, the point stops against the wall, and a waypoint chosen by distance alone
  would never change (measured: every episode of a task stuck so); with the schedule it moves on along the
  plan, and the point slides along the wall after it, as under ``track``.
"""

from __future__ import annotations

import numpy as np

from bridgeplan.envs.controllers import Body
from bridgeplan.trajectory import KINEMATIC_POINT

GAIN = 0.2
"""Position moved per step per unit of action (``ogbench.locomaze.point``: ``qpos += 0.2 * action``; a test
steps the environment to check it)."""
DEFAULT_LOOKAHEAD = 2.0
"""Pursuit's default lookahead: half of a 4-unit cell (ten steps), as Maze2D's default (1.0) is a cell of its
own (1-unit cells) in the middle of its measured best; here it is not tuned yet: choose it on validation
episodes (another seed than the reported one)."""


def step_action(positions: np.ndarray, targets: np.ndarray, gain: float = GAIN) -> np.ndarray:
    """``clip((targets - positions) / gain, -1, 1)`` ``[N, 2]``: the action that puts the point on its target
    in one step, where one step can."""
    d = np.asarray(targets, np.float64) - np.asarray(positions, np.float64)
    return np.clip(d / gain, -1.0, 1.0)


def pursuit_action(positions: np.ndarray, waypoints: np.ndarray, gain: float = GAIN) -> np.ndarray:
    """A unit step toward ``waypoints [N, 2]`` (the expert's speed), or onto it when it is within one step."""
    positions = np.asarray(positions, np.float64)
    d = np.asarray(waypoints, np.float64) - positions
    dist = np.linalg.norm(d, axis=1, keepdims=True)
    reach = np.minimum(dist, gain) / np.maximum(dist, 1e-12)
    return step_action(positions, positions + reach * d, gain)


BODY = Body(KINEMATIC_POINT, step_action, pursuit_action, DEFAULT_LOOKAHEAD, keeps_schedule=True)
"""The kinematic point steered by :mod:`bridgeplan.envs.controllers`: a plan's positions are its states."""
