"""The ogbench environments, their maze geometry, and a cached oracle equal to ``get_oracle_subgoal``.

The maze map, cell size and offsets are read from the ogbench environment itself (nothing is copied), so a
change in the package shows up here. ogbench draws its start and goal noise (and teleports) from NumPy's
global legacy RNG; :func:`legacy_rng` seeds it for a block and restores the caller's state afterwards.
"""

from __future__ import annotations

import functools
import warnings
from collections import deque
from dataclasses import dataclass

import numpy as np

from bridgeplan.envs.ogbench_pointmaze.names import env_id


def make_env(maze: str, **kwargs):
    """``gymnasium.make`` of ``maze``'s registered ogbench environment (``kwargs`` go to ``MazeEnv``)."""
    import gymnasium
    import ogbench.locomaze  # noqa: F401  (registers the environments)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's checker warns about the 6-D declared observation space
        return gymnasium.make(env_id(maze), **kwargs)


@dataclass(frozen=True)
class MazeGeometry:
    """One maze's map (1 = wall) and its cell <-> xy convention, as the ogbench env defines them."""

    maze: str
    maze_map: np.ndarray
    unit: float
    offset_x: float
    offset_y: float

    def cells_of(self, xy: np.ndarray) -> np.ndarray:
        """``[N, 2]`` (i, j) cells of ``[N, 2]`` positions (``MazeEnv.xy_to_ij``, floor instead of ``int``:
        the two differ only outside the map, which is wall either way)."""
        xy = np.asarray(xy, dtype=np.float64)
        i = np.floor((xy[:, 1] + self.offset_y + 0.5 * self.unit) / self.unit)
        j = np.floor((xy[:, 0] + self.offset_x + 0.5 * self.unit) / self.unit)
        return np.stack([i, j], axis=1).astype(np.int64)

    def is_free(self, cells: np.ndarray) -> np.ndarray:
        """``[N]`` whether each (i, j) is inside the map and not a wall."""
        i, j = cells[:, 0], cells[:, 1]
        h, w = self.maze_map.shape
        inside = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        free = np.zeros(len(cells), dtype=bool)
        free[inside] = self.maze_map[i[inside], j[inside]] == 0
        return free

    def cell_xy(self, cell: tuple[int, int]) -> np.ndarray:
        return np.array([cell[1] * self.unit - self.offset_x, cell[0] * self.unit - self.offset_y])

    @property
    def free_cells(self) -> list[tuple[int, int]]:
        """Free cells in row-major order (the order OGBench's generator samples from)."""
        return [(int(i), int(j)) for i, j in zip(*np.nonzero(self.maze_map == 0))]

    @property
    def vertex_cells(self) -> list[tuple[int, int]]:
        """Free cells that are not hallway cells (free on exactly two opposite sides, walls on the other two):
        the navigate datasets' goal cells."""
        m = self.maze_map
        out = []
        for i, j in self.free_cells:
            vertical = m[i - 1, j] == 0 and m[i + 1, j] == 0 and m[i, j - 1] == 1 and m[i, j + 1] == 1
            horizontal = m[i, j - 1] == 0 and m[i, j + 1] == 0 and m[i - 1, j] == 1 and m[i + 1, j] == 1
            if not (vertical or horizontal):
                out.append((i, j))
        return out


@functools.cache
def geometry(maze: str) -> MazeGeometry:
    u = make_env(maze).unwrapped
    return MazeGeometry(maze, np.array(u.maze_map, dtype=np.int64), float(u._maze_unit), float(u._offset_x),
                        float(u._offset_y))


NEIGHBOURS = ((-1, 0), (0, -1), (1, 0), (0, 1))
"""The order ``get_oracle_subgoal`` (and the stitch generator) visit neighbours in; it breaks ties."""


def bfs(maze_map: np.ndarray, source: tuple[int, int]) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Steps from ``source`` to every cell through free cells (4-connected; -1 for walls and unreachable
    cells; ``source`` itself is 0 even if it is a wall, as in ogbench), and the cells in the order the search
    discovers them (``source`` first), which OGBench's stitch generator samples goals from."""
    dist = np.full(maze_map.shape, -1, dtype=np.int64)
    dist[source] = 0
    order = [source]
    queue = deque([source])
    h, w = maze_map.shape
    while queue:
        i, j = queue.popleft()
        for di, dj in NEIGHBOURS:
            ni, nj = i + di, j + dj
            if 0 <= ni < h and 0 <= nj < w and maze_map[ni, nj] == 0 and dist[ni, nj] == -1:
                dist[ni, nj] = dist[i, j] + 1
                order.append((ni, nj))
                queue.append((ni, nj))
    return dist, order


class Oracle:
    """``MazeEnv.get_oracle_subgoal`` with the goal cell's BFS map cached: the same subgoal (the centre of the
    neighbouring free cell with the strictly smallest distance to the goal cell, first in :data:`NEIGHBOURS`
    order; the own cell when none is smaller), without a BFS per call."""

    def __init__(self, maze: str):
        self.geometry = geometry(maze)
        self._maps: dict[tuple[int, int], np.ndarray] = {}

    def _cell(self, xy) -> tuple[int, int]:
        g = self.geometry
        # MazeEnv.xy_to_ij, int() truncation included
        return (int((xy[1] + g.offset_y + 0.5 * g.unit) / g.unit), int((xy[0] + g.offset_x + 0.5 * g.unit) / g.unit))

    def subgoal(self, xy, goal_xy) -> np.ndarray:
        goal = self._cell(goal_xy)
        dist = self._maps.get(goal)
        if dist is None:
            dist = self._maps[goal] = bfs(self.geometry.maze_map, goal)[0]
        m = self.geometry.maze_map
        h, w = m.shape
        best = start = self._cell(xy)
        for di, dj in NEIGHBOURS:
            ni, nj = start[0] + di, start[1] + dj
            if 0 <= ni < h and 0 <= nj < w and m[ni, nj] == 0 and dist[ni, nj] < dist[best]:
                best = (ni, nj)
        return self.geometry.cell_xy(best)

    def direction(self, xy, goal_xy) -> np.ndarray:
        """The unit direction towards the subgoal, normalized as OGBench's generator does (``+ 1e-6``)."""
        d = self.subgoal(xy, goal_xy) - np.asarray(xy, dtype=np.float64)
        return d / (np.linalg.norm(d) + 1e-6)
