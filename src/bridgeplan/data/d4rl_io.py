"""Legacy D4RL ``maze2d-*.hdf5`` files, converted to gymnasium-robotics coordinates.

D4RL indexed the maze by (row, column): ``x = qpos_y + 0.7 - W/2``, ``y = H/2 - 0.7 - qpos_x``,
``v = (qvel_y, -qvel_x)``, ``a = (a_y, -a_x)``. Its ``timeouts`` mark goal changes, not resets, so
segments are split only where the state jumps further than the point mass can move in one step.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from bridgeplan.data.stream import Stream
from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import MAZE_NAMES, get_maze

MAX_STEP_DISTANCE = 0.1
"""The point mass moves at most 5 m/s * 0.01 s = 0.05 per step; a larger jump is a discontinuity."""


def maze_from_filename(path: Path) -> str:
    for name in sorted(MAZE_NAMES, key=len, reverse=True):
        if name in path.name.lower():
            return name
    raise BridgeplanError(f"cannot tell the maze from the file name {path.name} (expected one of "
                          f"{', '.join(MAZE_NAMES)}, e.g. maze2d-umaze-v1.hdf5)")


def read_d4rl(path: Path, maze_name: str | None = None) -> Stream:
    path = Path(path)
    maze = get_maze(maze_name or maze_from_filename(path))
    try:
        with h5py.File(path, "r") as f:
            obs = f["observations"][()].astype(np.float64)
            act = f["actions"][()].astype(np.float64)
            timeouts = f["timeouts"][()] if "timeouts" in f else np.zeros(len(obs), dtype=bool)
    except (OSError, KeyError) as e:
        raise BridgeplanError(f"cannot read {path} as a D4RL maze2d file: {e}") from None
    if obs.ndim != 2 or obs.shape[1] != 4 or act.shape != (len(obs), 2) or len(obs) < 2:
        raise BridgeplanError(f"{path}: observations {obs.shape} / actions {act.shape} are not maze2d data")
    rows, cols = maze.shape
    states = np.stack([obs[:, 1] + 0.7 - cols / 2, rows / 2 - 0.7 - obs[:, 0], obs[:, 3], -obs[:, 2]], axis=1)
    actions = np.stack([act[:, 1], -act[:, 0]], axis=1)
    jumps = np.linalg.norm(np.diff(states[:, :2], axis=0), axis=1) > MAX_STEP_DISTANCE
    starts = np.concatenate([[0], np.flatnonzero(jumps) + 1]).astype(np.int64)
    return Stream(maze.name, states, actions, starts, episodes=int(timeouts.sum()) + 1, source=str(path))
