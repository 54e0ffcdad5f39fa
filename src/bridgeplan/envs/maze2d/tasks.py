"""Evaluation tasks: seeded (start, goal) positions, single-task (fixed goal cell) or multi-task."""

from __future__ import annotations

import numpy as np

from bridgeplan.envs.maze2d.grids import POSITION_NOISE, Maze
from bridgeplan.errors import BridgeplanError


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
