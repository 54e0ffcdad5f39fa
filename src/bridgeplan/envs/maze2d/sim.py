"""Point masses stepping in lockstep on gymnasium-robotics' PointMaze MuJoCo model.

The model is built once per maze by gymnasium-robotics itself (so walls and physics are exactly
PointMaze v3's: timestep 0.01, damping 1, gear 100). Each episode is one ``mujoco.MjData`` stepped
directly with PointEnv's semantics: the action is clipped to [-1, 1], the velocity to [-5, 5] before
the step, then one ``mj_step``; the observation is ``(x, y, vx, vy)`` = ``(qpos, qvel)`` and the sparse
reward is 1 within 0.45 of the goal. This skips gymnasium's per-step overhead; ``tests/test_maze_sim.py``
checks it against ``env.step`` of the real environment.
"""

from __future__ import annotations

from functools import lru_cache

import mujoco
import numpy as np

from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, Maze
from bridgeplan.errors import BridgeplanError

MAX_SPEED = 5.0
"""PointEnv clips each velocity component to [-5, 5] before every step."""


def import_gymnasium_robotics():
    """Import gymnasium-robotics and register its environments, without its import-time notice on stderr
    (an unrelated Adroit message that would garble the CLI's one-line errors)."""
    import contextlib
    import io
    import warnings

    import gymnasium as gym

    with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
        warnings.simplefilter("ignore")
        import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    return gymnasium_robotics


def make_gym_env(maze: Maze, **kwargs):
    """A fresh gymnasium-robotics PointMaze environment for ``maze`` (``gym.make(maze.gym_id, **kwargs)``)."""
    import warnings

    import gymnasium as gym

    import_gymnasium_robotics()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(maze.gym_id, **kwargs)


@lru_cache(maxsize=None)
def _cached_env(maze: Maze):
    return make_gym_env(maze).unwrapped


def point_maze_model(maze: Maze) -> mujoco.MjModel:
    """The MuJoCo model of ``maze`` as gymnasium-robotics builds it (built once per process, shared)."""
    return _cached_env(maze).point_env.model


def check_free(maze: Maze, xy, what: str) -> np.ndarray:
    """``xy`` as a float ``[N, 2]`` array; raises BridgeplanError if a position is in a wall or outside."""
    xy = np.asarray(xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise BridgeplanError(f"{what} positions must have shape [N, 2], got {list(xy.shape)}")
    bad = ~maze.is_free_xy(xy)
    if bad.any():
        k = int(np.argmax(bad))
        raise BridgeplanError(f"{what} {np.round(xy[k], 3).tolist()} is inside a wall or outside the "
                              f"{maze.name} maze (cell {maze.xy_to_cell(xy[k]).tolist()})")
    return xy


class BatchedPointMaze:
    """``n`` point masses in ``maze``: ``reset(starts, goals)``, then ``step(actions)`` in lockstep.

    Attributes: ``goals [n, 2]`` (the goals of the current episodes), ``obs [n, 4]`` (the latest
    observations; copies are returned).
    """

    def __init__(self, maze: Maze, n: int):
        if n <= 0:
            raise BridgeplanError(f"number of episodes must be positive, got {n}")
        self.maze, self.n = maze, int(n)
        self.model = point_maze_model(maze)
        self.datas = [mujoco.MjData(self.model) for _ in range(self.n)]
        self.goals = np.zeros((self.n, 2))
        self.obs = np.zeros((self.n, 4))

    def reset(self, starts_xy, goals_xy, velocities=None) -> np.ndarray:
        """Place each point mass at its start (zero velocity unless given); returns ``obs [n, 4]``."""
        starts_xy = check_free(self.maze, starts_xy, "start")
        goals_xy = check_free(self.maze, goals_xy, "goal")
        vel = np.zeros_like(starts_xy) if velocities is None else np.asarray(velocities, dtype=np.float64)
        if len(starts_xy) != self.n or goals_xy.shape != starts_xy.shape or vel.shape != starts_xy.shape:
            raise BridgeplanError(f"reset needs {self.n} starts, goals (and velocities) of shape "
                                  f"[{self.n}, 2], "
                                  f"got {list(starts_xy.shape)}, {list(goals_xy.shape)}, {list(vel.shape)}")
        self.goals = goals_xy.copy()
        for d, p, v in zip(self.datas, starts_xy, vel):
            mujoco.mj_resetData(self.model, d)
            d.qpos[:] = p
            d.qvel[:] = v
            mujoco.mj_forward(self.model, d)
        self.obs = np.concatenate([starts_xy, vel], axis=1)
        return self.obs.copy()

    def step(self, actions) -> tuple[np.ndarray, np.ndarray]:
        """Advance every point mass one step; returns observations ``[n, 4]`` and sparse rewards ``[n]``."""
        actions = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        if actions.shape != (self.n, 2):
            raise BridgeplanError(f"actions must have shape [{self.n}, 2], got {list(actions.shape)}")
        model, obs = self.model, self.obs
        step = mujoco.mj_step
        for k, d in enumerate(self.datas):
            qvel = d.qvel
            np.clip(qvel, -MAX_SPEED, MAX_SPEED, out=qvel)
            d.ctrl[:] = actions[k]
            step(model, d)
            obs[k, :2] = d.qpos
            obs[k, 2:] = qvel
        return obs.copy(), self.rewards(obs)

    def rewards(self, obs: np.ndarray) -> np.ndarray:
        """Sparse reward ``[n]``: 1.0 where the position is within 0.45 of the goal."""
        return (np.linalg.norm(obs[:, :2] - self.goals, axis=1) <= GOAL_RADIUS).astype(np.float64)


class MazeFilm:
    """An episode's observed states ``[T, 4]`` replayed in gymnasium-robotics' PointMaze renderer, the goal's site
    where the episode's goal was (:meth:`bridgeplan.envs.family.Family.film`)."""

    def __init__(self, maze: Maze, states: np.ndarray, goal: np.ndarray, success: bool, size: int):
        self.maze, self.states, self.goal, self.size = maze, np.asarray(states, np.float64), goal, size
        self.length = len(self.states)
        self.outcome = "reached the goal" if success else "never reached the goal"

    def frames(self, steps, plans=None) -> list[np.ndarray]:
        """The states ``steps`` (``plans`` are drawn by the map, not here)."""
        from bridgeplan.trajectory import MAZE2D

        env = make_gym_env(self.maze, render_mode="rgb_array", width=self.size, height=self.size)
        env.reset(seed=0)
        point = env.unwrapped.point_env
        env.unwrapped.goal = np.asarray(self.goal, dtype=np.float64)
        env.unwrapped.update_target_site_pos()
        frames = []
        for s in self.states[list(steps)]:
            point.set_state(MAZE2D.state_positions(s), MAZE2D.state_velocities(s))
            frames.append(env.render())
        env.close()
        return frames
