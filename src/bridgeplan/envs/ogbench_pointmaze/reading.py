"""Reading OGBench pointmaze dataset files (ours or the official ones from a local path) with ogbench's own
loader, after checking that the file is one.

OGBench's npz format holds no metadata (``observations``, ``actions``, ``terminals``, ``qpos``, ``qvel``), and
the official files must be accepted as they are, so the maze is recognised from the data: every observation
of a pointmaze dataset is the point's xy, and the point (radius 0.7, stepping at most 0.2 per axis) never
puts its centre into a wall cell, so every observation must lie in one of the named maze's free cells. A
dataset of another maze (or of another environment: antmaze observations are 29-D) fails that check.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bridgeplan.data.npz import REQUIRED, read_npz
from bridgeplan.envs.ogbench_pointmaze.maze import geometry
from bridgeplan.envs.ogbench_pointmaze.names import MAZES, check_maze, parse_dataset_name
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import KINEMATIC_POINT


def resolve_maze(maze_or_name: str) -> str:
    """A maze (``medium``) or a dataset name (``pointmaze-medium-stitch-v0``) -> the maze."""
    return maze_or_name if maze_or_name in MAZES else parse_dataset_name(maze_or_name).maze


@dataclass
class DatasetCheck:
    """What :func:`check_dataset` found in a file."""

    path: str
    maze: str
    transitions: int
    episodes: int
    episode_lengths: list[int]
    """The distinct episode lengths (one value for every OGBench dataset)."""
    keys: list[str]
    cells_visited: int
    free_cells: int
    fits: list[str] = field(default_factory=list)
    """Every maze whose free cells hold all observations."""

    def summary(self) -> str:
        lengths = ", ".join(map(str, self.episode_lengths))
        return (f"{self.path}: pointmaze-{self.maze}, {self.transitions} steps in {self.episodes} "
                f"episode{'s' if self.episodes != 1 else ''} of {lengths} steps, "
                f"{self.cells_visited}/{self.free_cells} free cells visited, "
                f"arrays {', '.join(self.keys)}")


def _in_free_cells(maze: str, xy: np.ndarray) -> np.ndarray:
    g = geometry(maze)
    return g.is_free(g.cells_of(xy))


def check_dataset(path: str | Path, maze: str) -> DatasetCheck:
    """Check that ``path`` is an OGBench pointmaze dataset of ``maze`` (or of a dataset name's maze).

    One-line BridgeplanErrors: a missing or unreadable file, missing arrays, arrays of unequal length or
    not 2-D (x, y), an episode not closed by a terminal, an observation outside the maze's free cells.
    """
    maze = check_maze(resolve_maze(maze))
    path = Path(path)
    arrays, keys = read_npz(path)
    obs, actions, terminals = (arrays[k] for k in REQUIRED)
    if obs.ndim != 2 or obs.shape[1] != 2:
        raise BridgeplanError(f"{path} is not a pointmaze dataset: observations have shape {obs.shape}, "
                              "pointmaze's are [N, 2] (x, y)")
    if actions.shape != obs.shape:
        raise BridgeplanError(f"{path}: arrays of unequal length (observations {obs.shape}, actions "
                              f"{actions.shape}, terminals {terminals.shape})")
    inside = _in_free_cells(maze, obs)
    fits = [m for m in MAZES if _in_free_cells(m, obs).all()]
    if not inside.all():
        others = f"; it fits {', '.join(fits)}" if fits else ""
        raise BridgeplanError(f"{path} is not a pointmaze-{maze} dataset: {int((~inside).sum())} of {len(obs)} "
                              f"observations lie outside its free cells{others}")
    ends = np.flatnonzero(terminals)
    lengths = np.diff(np.concatenate([[-1], ends]))
    g = geometry(maze)
    visited = len({tuple(c) for c in g.cells_of(obs)})
    return DatasetCheck(str(path), maze, len(obs), len(ends), sorted({int(n) for n in lengths}), keys, visited,
                        len(g.free_cells), fits)


def load_dataset(path: str | Path, maze: str, compact_dataset: bool = False,
                 add_info: bool = False) -> dict[str, np.ndarray]:
    """:func:`check_dataset`, then ``ogbench.utils.load_dataset`` (the package's own reader: with
    ``compact_dataset=False`` it returns ``next_observations`` and drops each episode's last step)."""
    from ogbench.utils import load_dataset as ogbench_load

    check_dataset(path, maze)
    return ogbench_load(str(path), compact_dataset=compact_dataset, add_info=add_info)


def load_stream(path: str | Path, name: str):
    """Dataset file ``path`` of dataset ``name`` (``pointmaze-medium-navigate-v0``; checked as
    :func:`load_dataset` does) as bridgeplan's training :class:`~bridgeplan.data.stream.Stream`: maze ``name``
    (so the kinematic point's layout, ``trajectory.KINEMATIC_POINT``), one continuous segment per episode
    (:func:`~bridgeplan.envs.ogbench_data.compact_stream`)."""
    from bridgeplan.envs.ogbench_data import compact_stream

    return compact_stream(load_dataset(path, parse_dataset_name(name).maze, compact_dataset=True), name, path,
                          KINEMATIC_POINT)
