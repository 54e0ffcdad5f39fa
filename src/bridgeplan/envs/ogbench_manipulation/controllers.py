"""How a plan is executed by OGBench's arm: the inverse dynamics that turns consecutive planned states into an action.

The arm is position-controlled: an action is the change of the effector's position (x, y, z: at most 0.05 m per
step each), of its yaw (at most 0.3 rad) and of the gripper's opening (at most 1), each scaled to [-1, 1]
(``ManipSpaceEnv.action_low/high``, ``set_control``). The observation holds the effector's position (centred at
(0.425, 0, 0) and scaled by 10), its yaw as cos and sin, and the gripper's opening scaled by 3. So the action that
moves the effector from a state to a planned state is their difference, unscaled and normalized (what the play
oracles do toward their own plans, ``PlanOracle.select_action``), times the arm's measured response
(:data:`RESPONSE`: the IK controller follows its target partly within one step): :func:`inverse_dynamics`. So
``track`` (Diffuser's: the next planned state as the target) executes a
state-only plan (Decision Diffuser's form, with this exact inverse dynamics in place of a learned one). ``pursuit``
(a waypoint in the plane) has no meaning for an arm's 5-D action and is refused.
"""

from __future__ import annotations

import numpy as np

from bridgeplan.envs.controllers import Body
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import Layout

EFFECTOR = slice(12, 15)
"""The effector's scaled position in the observation (after 6 joint positions and 6 joint velocities)."""
YAW_COS, YAW_SIN, GRIPPER = 15, 16, 17
XYZ_SCALER, GRIPPER_SCALER = 10.0, 3.0
"""``compute_observation``'s scalers."""
ACTION_RANGE = np.array([0.05, 0.05, 0.05, 0.3, 1.0])
"""``ManipSpaceEnv``'s action range: the most an action asks the effector to move (m), turn (rad), open."""
RESPONSE = np.array([2.2, 2.3, 2.5, 3.7, 2.9])
"""How much more an action asks than the arm does in one step, per axis (x, y, z, yaw, gripper): the IK controller
follows its target partly. The play data's actions per unit of the change they made in one step, least squares per
axis on a generated cube-single dataset (a test fits it again)."""


def inverse_dynamics(states: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``[N, 5]`` actions toward ``targets [N, obs_dim]`` from ``states [N, obs_dim]``, clipped to [-1, 1]."""
    states, targets = np.asarray(states, np.float64), np.asarray(targets, np.float64)
    delta = np.empty((len(states), 5))
    delta[:, :3] = (targets[:, EFFECTOR] - states[:, EFFECTOR]) / XYZ_SCALER
    turn = (np.arctan2(targets[:, YAW_SIN], targets[:, YAW_COS]) - np.arctan2(states[:, YAW_SIN], states[:, YAW_COS]))
    delta[:, 3] = (turn + np.pi) % (2 * np.pi) - np.pi
    delta[:, 4] = (targets[:, GRIPPER] - states[:, GRIPPER]) / GRIPPER_SCALER
    return np.clip(RESPONSE * delta / ACTION_RANGE, -1.0, 1.0)


def _no_pursuit(states: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    raise BridgeplanError("--controller pursuit steers a point toward a waypoint in the plane; an arm's plans are "
                          "executed by track (the inverse dynamics toward the next planned state)")


def body(layout: Layout) -> Body:
    """The arm steered by :mod:`bridgeplan.envs.controllers` in ``layout`` (its scene's observation)."""
    return Body(layout, inverse_dynamics, _no_pursuit, default_lookahead=1.0)
