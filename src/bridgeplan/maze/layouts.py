"""The Maze2D layouts (gymnasium-robotics' PointMaze v3 grids), evaluation goals and coordinates.

Cells are (row, column), 0-based, walls included; 1 is a wall. Coordinates follow
gymnasium-robotics: the maze is centred on the origin, cell (i, j) has its centre at
``x = j + 0.5 - W/2``, ``y = H/2 - i - 0.5``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from bridgeplan.errors import BridgeplanError

_GRIDS = {
    "open": ["1111111", "1000001", "1000001", "1000001", "1111111"],
    "umaze": ["11111", "10001", "11101", "10001", "11111"],
    "medium": ["11111111", "10011001", "10010001", "11000111", "10010001", "10100101", "10001001",
               "11111111"],
    "large": ["111111111111", "100001000001", "101101010101", "100000010001", "101111011101",
              "100101000001", "110101010111", "100100010001", "111111111111"],
}
# (gym id, evaluation goal cell, episode steps): the single-task setting of Diffuser and Minari
_SETTINGS = {
    "open": ("PointMaze_Open-v3", (2, 3), 300),
    "umaze": ("PointMaze_UMaze-v3", (1, 1), 300),
    "medium": ("PointMaze_Medium-v3", (6, 6), 600),
    "large": ("PointMaze_Large-v3", (7, 9), 800),
}
MAZE_NAMES = tuple(_GRIDS)
GOAL_RADIUS = 0.45
"""Reward 1 for every step within this distance of the goal (gymnasium-robotics; D4RL used 0.5)."""
POSITION_NOISE = 0.25
"""Start and goal positions are cell centres plus U(-0.25, 0.25) per coordinate."""


@dataclass(frozen=True)
class Maze:
    name: str
    grid: tuple[tuple[int, ...], ...]
    gym_id: str
    eval_goal_cell: tuple[int, int]
    episode_steps: int

    @property
    def shape(self) -> tuple[int, int]:
        return len(self.grid), len(self.grid[0])

    @cached_property
    def free_cells(self) -> np.ndarray:
        """``[K, 2]`` (row, column) of every free cell, row-major."""
        return np.argwhere(np.asarray(self.grid) == 0)

    def cell_to_xy(self, cells) -> np.ndarray:
        cells = np.asarray(cells, dtype=np.float64)
        rows, cols = self.shape
        return np.stack([cells[..., 1] + 0.5 - cols / 2, rows / 2 - cells[..., 0] - 0.5], axis=-1)

    def xy_to_cell(self, xy) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        rows, cols = self.shape
        return np.stack([np.floor(rows / 2 - xy[..., 1]), np.floor(xy[..., 0] + cols / 2)], axis=-1).astype(int)

    def is_free_cell(self, cells) -> np.ndarray:
        cells = np.asarray(cells)
        rows, cols = self.shape
        inside = (cells[..., 0] >= 0) & (cells[..., 0] < rows) & (cells[..., 1] >= 0) & (cells[..., 1] < cols)
        grid = np.asarray(self.grid)
        free = np.zeros(cells.shape[:-1], dtype=bool)
        free[inside] = grid[cells[..., 0][inside], cells[..., 1][inside]] == 0
        return free

    def is_free_xy(self, xy) -> np.ndarray:
        return self.is_free_cell(self.xy_to_cell(xy))


def get_maze(name: str) -> Maze:
    if name not in _GRIDS:
        raise BridgeplanError(f"unknown maze {name!r}: choose from {', '.join(MAZE_NAMES)}")
    gym_id, goal, steps = _SETTINGS[name]
    grid = tuple(tuple(int(c) for c in row) for row in _GRIDS[name])
    return Maze(name, grid, gym_id, goal, steps)
