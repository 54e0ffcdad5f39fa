"""Point masses stepping in lockstep on gymnasium-robotics' PointMaze MuJoCo model.

The model is built once by gymnasium-robotics (so walls and physics are exactly PointMaze v3's);
each episode is one ``mujoco.MjData`` stepped directly with PointEnv's semantics: the action is
clipped to [-1, 1], the velocity to [-5, 5] before the step, then one ``mj_step`` (timestep 0.01).
Stepping MjData directly skips gymnasium's per-step overhead; a test checks it against ``env.step``.
"""

from __future__ import annotations

from functools import lru_cache

import mujoco
import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import GOAL_RADIUS, Maze

MAX_SPEED = 5.0


@lru_cache(maxsize=None)
def _gym_env(gym_id: str):
    import gymnasium as gym
    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    return gym.make(gym_id).unwrapped


def point_maze_model(maze: Maze) -> mujoco.MjModel:
    """The MuJoCo model of ``maze`` as gymnasium-robotics builds it."""
    return _gym_env(maze.gym_id).point_env.model


def check_free(maze: Maze, xy: np.ndarray, what: str) -> None:
    bad = ~maze.is_free_xy(xy)
    if bad.any():
        k = int(np.argmax(bad))
        raise BridgeplanError(f"{what} {np.round(xy[k], 3).tolist()} is inside a wall or outside the "
                              f"{maze.name} maze (cell {maze.xy_to_cell(xy[k]).tolist()})")


class BatchedPointMaze:
    """``n`` point masses in ``maze``; ``reset(starts, goals)`` then ``step(actions)``."""

    def __init__(self, maze: Maze, n: int):
        if n <= 0:
            raise BridgeplanError(f"number of episodes must be positive, got {n}")
        self.maze = maze
        self.model = point_maze_model(maze)
        self.datas = [mujoco.MjData(self.model) for _ in range(n)]
        self.goals = np.zeros((n, 2))
        self.obs = np.zeros((n, 4))

    def reset(self, starts_xy: np.ndarray, goals_xy: np.ndarray, velocities: np.ndarray | None = None) -> np.ndarray:
        starts_xy, goals_xy = np.asarray(starts_xy, float), np.asarray(goals_xy, float)
        check_free(self.maze, starts_xy, "start")
        check_free(self.maze, goals_xy, "goal")
        self.goals = goals_xy.copy()
        vel = np.zeros_like(starts_xy) if velocities is None else np.asarray(velocities, float)
        for d, p, v in zip(self.datas, starts_xy, vel):
            mujoco.mj_resetData(self.model, d)
            d.qpos[:] = p
            d.qvel[:] = v
            mujoco.mj_forward(self.model, d)
        self.obs = np.concatenate([starts_xy, vel], axis=1)
        return self.obs.copy()

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance every episode one step; returns observations ``[n, 4]`` and sparse rewards ``[n]``."""
        actions = np.clip(actions, -1.0, 1.0)
        model, obs = self.model, self.obs
        for k, d in enumerate(self.datas):
            np.clip(d.qvel, -MAX_SPEED, MAX_SPEED, out=d.qvel)
            d.ctrl[:] = actions[k]
            mujoco.mj_step(model, d)
            obs[k, :2] = d.qpos
            obs[k, 2:] = d.qvel
        reward = (np.linalg.norm(obs[:, :2] - self.goals, axis=1) <= GOAL_RADIUS).astype(np.float64)
        return obs.copy(), reward
