"""Evaluation tasks: seeded (start, goal) positions, single-task (fixed goal cell) or multi-task."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bridgeplan.envs.family import Tasks
from bridgeplan.envs.maze2d.grids import POSITION_NOISE, Maze
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D


def sample_tasks(maze: Maze, n: int, seed: int, multi_task: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``n`` starts and goals, each ``[n, 2]`` (x, y): cell centres plus U(-0.25, 0.25) noise per coordinate.

    Single-task: the goal cell is the maze's evaluation cell, the start cell a uniformly random other
    free cell. Multi-task ("Multi2D"): goal and start are two distinct uniformly random free cells.
    Reproducible: the same (maze, n, seed, multi_task) always gives the same tasks (the tasks of a
    smaller ``n`` are not a prefix of a larger one: compare runs with equal ``n``).
    """
    if n <= 0:
        raise BridgeplanError(f"number of episodes must be positive, got {n}")
    rng = np.random.default_rng(seed)
    free = maze.free_cells
    if multi_task:
        goal_idx = rng.integers(len(free), size=n)
    else:
        goal_idx = np.full(n, int(np.flatnonzero((free == maze.eval_goal_cell).all(axis=1))[0]))
    start_idx = rng.integers(len(free) - 1, size=n)
    start_idx += start_idx >= goal_idx  # uniform over the free cells other than the goal cell
    noise = rng.uniform(-POSITION_NOISE, POSITION_NOISE, size=(2, n, 2))
    return maze.cell_to_xy(free[start_idx]) + noise[0], maze.cell_to_xy(free[goal_idx]) + noise[1]


@dataclass(frozen=True, kw_only=True)
class MazeTasks(Tasks):
    """Seeded episodes in one maze: where each starts (at rest) and the goal it must reach (:func:`sample_tasks`)."""

    maze: Maze
    starts_xy: np.ndarray
    goals_xy: np.ndarray
    multi_task: bool = False

    @classmethod
    def sample(cls, maze: Maze, episodes: int, seed: int = 0, multi_task: bool = False) -> MazeTasks:
        if episodes <= 0:
            raise BridgeplanError(f"episodes must be positive, got {episodes}")
        starts, goals = sample_tasks(maze, episodes, seed=seed, multi_task=multi_task)
        return cls(maze.name, episodes, seed, maze.episode_steps, maze=maze, starts_xy=starts, goals_xy=goals,
                   multi_task=multi_task)

    @classmethod
    def of(cls, maze: Maze, starts_xy, goals_xy, seed: int = 0, multi_task: bool = False) -> MazeTasks:
        """Episodes from given starts and goals ``[N, 2]``."""
        starts, goals = np.asarray(starts_xy, np.float64), np.asarray(goals_xy, np.float64)
        return cls(maze.name, len(starts), seed, maze.episode_steps, maze=maze, starts_xy=starts, goals_xy=goals,
                   multi_task=multi_task)

    @property
    def start_states(self) -> np.ndarray:
        """``[N, 4]`` Maze2D states (x, y, vx, vy) with zero velocity."""
        return MAZE2D.at_rest(self.starts_xy)

    def fields(self) -> dict:
        return {"maze": self.maze.name, "episodes": self.episodes, "seed": self.seed, "multi_task": self.multi_task,
                "episode_steps": self.episode_steps}

    def first(self) -> MazeTasks:
        return MazeTasks(self.env, 1, self.seed, self.episode_steps, maze=self.maze, starts_xy=self.starts_xy[:1],
                         goals_xy=self.goals_xy[:1], multi_task=self.multi_task)
