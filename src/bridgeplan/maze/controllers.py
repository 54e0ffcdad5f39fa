"""Diffuser's tracking controller: how every planner's plan is executed in the maze.

A plan is a batch of planned states ``[N, H, 4]`` (x, y, vx, vy); its actions are ignored. At step
``t`` the controller drives the point mass toward the next planned state::

    a_t = clip((p_{t+1} - p_t) + (v_{t+1} - v_t), -1, 1)

with ``p, v`` the observed position and velocity and ``p_{t+1}, v_{t+1}`` the planned ones. Once the
plan has ended (``t + 1 >= H``) it holds the last planned position with zero velocity.
"""

from __future__ import annotations

import numpy as np


def tracking_action(state: np.ndarray, planned_next_state: np.ndarray) -> np.ndarray:
    """``clip((p_next - p) + (v_next - v), -1, 1)`` for ``state [N, 4]`` and ``planned_next_state [N, 4]``."""
    state, target = np.asarray(state, np.float64), np.asarray(planned_next_state, np.float64)
    return np.clip((target[:, :2] - state[:, :2]) + (target[:, 2:] - state[:, 2:]), -1.0, 1.0)


def planned_target(plans: np.ndarray, t: int) -> np.ndarray:
    """The state ``[N, 4]`` to track at step ``t``: ``plans[:, t + 1]``, or after the plan's end its last
    position with zero velocity."""
    plans = np.asarray(plans, np.float64)
    if t + 1 < plans.shape[1]:
        return plans[:, t + 1]
    return np.concatenate([plans[:, -1, :2], np.zeros_like(plans[:, -1, 2:])], axis=1)


def planned_targets(plans: np.ndarray, steps_into_plan: np.ndarray) -> np.ndarray:
    """:func:`planned_target` with a step per plan: ``plans[n, s_n + 1]`` for ``steps_into_plan [N]`` (the
    steps since each plan was made; closed loop), or past its end its last position with zero velocity."""
    plans = np.asarray(plans, np.float64)
    steps = np.asarray(steps_into_plan, dtype=np.int64)
    horizon = plans.shape[1]
    rows = np.arange(len(plans))
    target = plans[rows, np.minimum(steps + 1, horizon - 1)].copy()
    ended = steps + 1 >= horizon
    target[ended, 2:] = 0.0
    return target


def tracking_actions(states: np.ndarray, plans: np.ndarray, t: int) -> np.ndarray:
    """Actions ``[N, 2]`` at step ``t`` for observed ``states [N, 4]`` tracking ``plans [N, H, 4]``."""
    return tracking_action(states, planned_target(plans, t))
