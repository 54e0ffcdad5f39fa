"""Batched episodes of a policy, in lockstep (what :meth:`bridgeplan.envs.maze2d.Maze2D.run` runs an agent through).

Evaluation is a continuing task: the goal stays for the whole episode and every step within 0.45
of it earns reward 1, so reaching the goal fast and staying there earns more.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, Maze
from bridgeplan.envs.maze2d.sim import BatchedPointMaze
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D

Policy = Callable[[int, np.ndarray], np.ndarray]
"""``policy(step_index, obs [N, 4]) -> actions [N, 2]``."""


@dataclass
class RolloutResult:
    returns: np.ndarray
    """``[N]`` sum of the sparse rewards over the episode."""
    success: np.ndarray
    """``[N]`` bool: the point mass was within 0.45 of the goal at some step."""
    states: np.ndarray
    """``[N, steps + 1, 4]`` observed states, the initial one first."""
    actions: np.ndarray
    """``[N, steps, 2]`` the actions applied (clipped to [-1, 1])."""


def rollout(maze: Maze, policy: Policy, starts_xy, goals_xy, steps: int | None = None) -> RolloutResult:
    """Run ``policy`` from ``starts_xy [N, 2]`` toward ``goals_xy [N, 2]`` for ``steps`` (default: the
    maze's episode length), all episodes in lockstep."""
    steps = maze.episode_steps if steps is None else int(steps)
    if steps <= 0:
        raise BridgeplanError(f"episode steps must be positive, got {steps}")
    sim = BatchedPointMaze(maze, len(np.asarray(starts_xy)))
    obs = sim.reset(starts_xy, goals_xy)
    n = len(obs)
    states = np.empty((n, steps + 1, MAZE2D.obs_dim))
    actions = np.empty((n, steps, MAZE2D.act_dim))
    states[:, 0] = obs
    returns = np.zeros(n)
    for t in range(steps):
        act = np.clip(np.asarray(policy(t, obs), dtype=np.float64), -1.0, 1.0)
        actions[:, t] = act
        obs, reward = sim.step(act)
        states[:, t + 1] = obs
        returns += reward
    dist = np.linalg.norm(MAZE2D.state_positions(states[:, 1:]) - sim.goals[:, None], axis=2)
    return RolloutResult(returns, (dist <= GOAL_RADIUS).any(axis=1), states, actions)
