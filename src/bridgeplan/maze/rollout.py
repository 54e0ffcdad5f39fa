"""Batched episodes: a policy or a batch of plans, executed in lockstep."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from bridgeplan.maze.expert import tracking_actions
from bridgeplan.maze.layouts import Maze
from bridgeplan.maze.sim import BatchedPointMaze


@dataclass
class RolloutResult:
    returns: np.ndarray
    """``[N]`` sum of sparse rewards (the goal stays; every step within 0.45 earns 1)."""
    success: np.ndarray
    """``[N]`` 1.0 where the episode was ever within 0.45 of the goal."""
    states: np.ndarray
    """``[N, steps + 1, 4]`` observed states, the initial one first."""


def rollout(maze: Maze, policy: Callable[[int, np.ndarray], np.ndarray], starts_xy: np.ndarray,
            goals_xy: np.ndarray, steps: int | None = None) -> RolloutResult:
    """Run ``policy(t, obs [N, 4]) -> actions [N, 2]`` for ``steps`` (the maze's episode length)."""
    steps = maze.episode_steps if steps is None else steps
    sim = BatchedPointMaze(maze, len(starts_xy))
    obs = sim.reset(starts_xy, goals_xy)
    states = np.empty((len(obs), steps + 1, 4))
    states[:, 0] = obs
    returns = np.zeros(len(obs))
    for t in range(steps):
        obs, reward = sim.step(policy(t, obs))
        states[:, t + 1] = obs
        returns += reward
    return RolloutResult(returns, (returns > 0).astype(np.float64), states)


def execute_plans(maze: Maze, starts_xy: np.ndarray, goals_xy: np.ndarray, plans: np.ndarray,
                  steps: int | None = None) -> RolloutResult:
    """Track planned states ``[N, H, 4]`` open loop with Diffuser's controller."""
    return rollout(maze, lambda t, obs: tracking_actions(obs, plans, t), starts_xy, goals_xy, steps)
