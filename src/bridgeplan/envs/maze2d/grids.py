"""The Maze2D layouts (gymnasium-robotics' PointMaze v3 grids), evaluation goals and coordinates.

Cells are ``(row, column)``, 0-based, walls included; ``1`` is a wall. Coordinates follow
gymnasium-robotics: the maze is centred on the origin and cell ``(i, j)`` has its centre at
``x = j + 0.5 - W/2``, ``y = H/2 - i - 0.5`` (``H`` rows, ``W`` columns, cell size 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from bridgeplan.errors import BridgeplanError

_GRIDS = {
    "open": ("1111111",
             "1000001",
             "1000001",
             "1000001",
             "1111111"),
    "umaze": ("11111",
              "10001",
              "11101",
              "10001",
              "11111"),
    "medium": ("11111111",
               "10011001",
               "10010001",
               "11000111",
               "10010001",
               "10100101",
               "10001001",
               "11111111"),
    "large": ("111111111111",
              "100001000001",
              "101101010101",
              "100000010001",
              "101111011101",
              "100101000001",
              "110101010111",
              "100100010001",
              "111111111111"),
}
# gym id, evaluation goal cell (single-task setting of Diffuser and Minari), episode steps
_SETTINGS = {
    "open": ("PointMaze_Open-v3", (2, 3), 300),
    "umaze": ("PointMaze_UMaze-v3", (1, 1), 300),
    "medium": ("PointMaze_Medium-v3", (6, 6), 600),
    "large": ("PointMaze_Large-v3", (7, 9), 800),
}
MAZE_NAMES: tuple[str, ...] = tuple(_GRIDS)
GOAL_RADIUS = 0.45
"""Reward 1 for every step within this distance of the goal (gymnasium-robotics; D4RL used 0.5)."""
POSITION_NOISE = 0.25
"""Start and goal positions are cell centres plus U(-0.25, 0.25) per coordinate (gymnasium-robotics)."""


@dataclass(frozen=True)
class Maze:
    """One maze: its grid, its single-task evaluation goal cell and its episode length."""

    name: str
    grid: tuple[tuple[int, ...], ...]
    """Rows of 0 (free) and 1 (wall)."""
    eval_goal_cell: tuple[int, int]
    """(row, column) of the fixed goal in the single-task evaluation setting."""
    episode_steps: int
    """Evaluation episode length (300 open/umaze, 600 medium, 800 large)."""
    gym_id: str
    """The gymnasium-robotics environment id with this layout and physics."""

    @property
    def shape(self) -> tuple[int, int]:
        """(rows H, columns W)."""
        return len(self.grid), len(self.grid[0])

    @cached_property
    def walls(self) -> np.ndarray:
        """``[H, W]`` bool, True on walls (read-only)."""
        walls = np.asarray(self.grid, dtype=np.int64) == 1
        walls.setflags(write=False)
        return walls

    @cached_property
    def free_cells(self) -> np.ndarray:
        """``[K, 2]`` (row, column) of every free cell, row-major (read-only)."""
        cells = np.argwhere(~self.walls)
        cells.setflags(write=False)
        return cells

    @property
    def eval_goal_xy(self) -> np.ndarray:
        """Centre of the evaluation goal cell."""
        return self.cell_to_xy(self.eval_goal_cell)

    def cell_to_xy(self, cells) -> np.ndarray:
        """Cell centres ``[..., 2]`` (x, y) of cells ``[..., 2]`` (row, column)."""
        cells = np.asarray(cells, dtype=np.float64)
        rows, cols = self.shape
        return np.stack([cells[..., 1] + 0.5 - cols / 2, rows / 2 - cells[..., 0] - 0.5], axis=-1)

    def xy_to_cell(self, xy) -> np.ndarray:
        """The cell ``[..., 2]`` (row, column, int) of each position ``[..., 2]`` (may lie outside)."""
        xy = np.asarray(xy, dtype=np.float64)
        rows, cols = self.shape
        return np.stack([np.floor(rows / 2 - xy[..., 1]), np.floor(xy[..., 0] + cols / 2)],
                        axis=-1).astype(np.int64)

    def is_free_cell(self, cells) -> np.ndarray:
        """True where the cell ``[..., 2]`` is inside the grid and not a wall."""
        cells = np.asarray(cells, dtype=np.int64)
        rows, cols = self.shape
        r, c = cells[..., 0], cells[..., 1]
        inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        free = np.zeros(cells.shape[:-1], dtype=bool)
        free[inside] = ~self.walls[r[inside], c[inside]]
        return free

    def is_free_xy(self, xy) -> np.ndarray:
        """True where the position ``[..., 2]`` lies in a free cell (NaN/inf positions are not free)."""
        xy = np.asarray(xy, dtype=np.float64)
        finite = np.isfinite(xy).all(axis=-1)
        return self.is_free_cell(self.xy_to_cell(np.where(finite[..., None], xy, 1e6))) & finite


def get_maze(name: str) -> Maze:
    """The maze called ``name`` (open, umaze, medium, large)."""
    if name not in _GRIDS:
        raise BridgeplanError(f"unknown maze {name!r}: choose from {', '.join(MAZE_NAMES)}")
    gym_id, goal, steps = _SETTINGS[name]
    grid = tuple(tuple(int(c) for c in row) for row in _GRIDS[name])
    return Maze(name, grid, goal, steps, gym_id)
