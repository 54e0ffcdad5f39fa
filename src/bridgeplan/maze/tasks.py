"""Evaluation tasks: seeded (start, goal) positions, single-task (fixed goal cell) or multi-task."""

from __future__ import annotations

import numpy as np

from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import POSITION_NOISE, Maze


def sample_tasks(maze: Maze, n: int, seed: int, multi_task: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``n`` starts and goals ``[n, 2]``: cell centres plus U(-0.25, 0.25) noise, like gymnasium-robotics.

    Single-task: the goal cell is the maze's evaluation cell and the start a uniformly random other free
    cell. Multi-task: start and goal are two distinct random free cells.
    """
    if n <= 0:
        raise BridgeplanError(f"number of episodes must be positive, got {n}")
    rng = np.random.default_rng(seed)
    free = maze.free_cells
    goal_cells = np.empty((n, 2), dtype=int)
    start_cells = np.empty((n, 2), dtype=int)
    for k in range(n):
        goal = free[rng.integers(len(free))] if multi_task else np.asarray(maze.eval_goal_cell)
        others = free[np.any(free != goal, axis=1)]
        goal_cells[k], start_cells[k] = goal, others[rng.integers(len(others))]
    noise = rng.uniform(-POSITION_NOISE, POSITION_NOISE, size=(2, n, 2))
    return maze.cell_to_xy(start_cells) + noise[0], maze.cell_to_xy(goal_cells) + noise[1]
