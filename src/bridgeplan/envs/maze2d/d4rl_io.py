"""Legacy D4RL ``maze2d-*.hdf5`` files, converted to gymnasium-robotics coordinates.

D4RL indexed the maze by (row, column): ``x = qpos_y + 0.7 - W/2``, ``y = H/2 - 0.7 - qpos_x``,
``v = (qvel_y, -qvel_x)``, ``a = (a_y, -a_x)``. Its generator did not record the step on which a
goal was reached (the next row repeats the previous observation while the simulator moved on), so
its flags do not say where the stream is continuous. Segments are therefore split wherever the
physics does not connect two rows: MuJoCo's Euler integrator gives ``p[t+1] = p[t] + dt * v[t+1]``
(dt = 0.01) for every real step, to float32 precision.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridgeplan.data.stream import Stream
from bridgeplan.envs.maze2d.grids import MAZE_NAMES, Maze, get_maze
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D

TIMESTEP = 0.01
CONTINUITY_TOLERANCE = 1e-4
"""Largest ``|p[t+1] - p[t] - dt v[t+1]|`` of a real step (float32 files are good to about 1e-6)."""
OFFSET = 0.7


def from_d4rl(observations: np.ndarray, actions: np.ndarray, maze: Maze) -> tuple[np.ndarray, np.ndarray]:
    """D4RL ``(qpos, qvel)`` rows and actions -> gymnasium-robotics states ``[T, 4]``, actions ``[T, 2]``."""
    o, a = np.asarray(observations, np.float64), np.asarray(actions, np.float64)
    rows, cols = maze.shape
    states = np.stack([o[:, 1] + OFFSET - cols / 2, rows / 2 - OFFSET - o[:, 0], o[:, 3], -o[:, 2]], axis=1)
    return states, np.stack([a[:, 1], -a[:, 0]], axis=1)


def to_d4rl(states: np.ndarray, actions: np.ndarray, maze: Maze) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`from_d4rl`."""
    s, a = np.asarray(states, np.float64), np.asarray(actions, np.float64)
    rows, cols = maze.shape
    obs = np.stack([rows / 2 - OFFSET - s[:, 1], s[:, 0] - OFFSET + cols / 2, -s[:, 3], s[:, 2]], axis=1)
    return obs, np.stack([-a[:, 1], a[:, 0]], axis=1)


def continuity_breaks(states: np.ndarray, tolerance: float = CONTINUITY_TOLERANCE) -> np.ndarray:
    """``[T - 1]`` bool: True where ``states[t + 1]`` is not one simulator step after ``states[t]``."""
    residual = states[1:, :2] - states[:-1, :2] - TIMESTEP * states[1:, 2:]
    return ~(np.abs(residual).max(axis=1) <= tolerance)


def maze_from_filename(path: Path) -> str | None:
    name = Path(path).name.lower()
    for maze in sorted(MAZE_NAMES, key=len, reverse=True):
        if maze in name:
            return maze
    return None


def infer_maze(observations: np.ndarray) -> str | None:
    """The maze the data was recorded in, from the data alone: among the layouts in whose free cells
    every converted position lies, the one whose free cells the data covers best (at least 90 %, and
    strictly better than any other; None otherwise). A umaze stream also fits the open maze, but
    covers only part of it."""
    coverage = {}
    for name in MAZE_NAMES:
        maze = get_maze(name)
        states, _ = from_d4rl(observations, np.zeros((len(observations), 2)), maze)
        if maze.is_free_xy(states[:, :2]).all():
            visited = np.unique(maze.xy_to_cell(states[:, :2]), axis=0)
            coverage[name] = len(visited) / len(maze.free_cells)
    ranked = sorted(coverage.items(), key=lambda kv: -kv[1])
    if not ranked or ranked[0][1] < 0.9 or (len(ranked) > 1 and ranked[1][1] == ranked[0][1]):
        return None
    return ranked[0][0]


def read_d4rl(path: Path, maze_name: str | None = None) -> Stream:
    """Read a legacy D4RL maze2d hdf5 file into a :class:`Stream` (maze from ``maze_name``, else the file
    name, else the only layout the data fits)."""
    import h5py

    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            missing = [k for k in ("observations", "actions") if k not in f]
            if missing:
                raise BridgeplanError(f"{path} is not a D4RL maze2d file (no {', '.join(missing)} in it)")
            obs = np.asarray(f["observations"][()], dtype=np.float64)
            act = np.asarray(f["actions"][()], dtype=np.float64)
            flags = None
            for key in ("timeouts", "terminals"):
                if key in f and np.asarray(f[key][()]).any():
                    flags = np.asarray(f[key][()], dtype=bool)
                    break
    except BridgeplanError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as e:
        raise BridgeplanError(f"cannot read {path} as HDF5 (truncated, or not an hdf5 file): "
                              f"{' '.join(str(e).split())}") from None
    if obs.ndim != 2 or obs.shape[1] != 4 or act.shape != (len(obs), 2) or len(obs) < 2:
        raise BridgeplanError(f"{path}: observations {list(obs.shape)} / actions {list(act.shape)} are not "
                              f"maze2d data ([N, 4] / [N, 2])")
    if not np.isfinite(obs).all() or not np.isfinite(act).all():
        raise BridgeplanError(f"{path}: observations or actions contain NaN or inf")
    name = maze_name or maze_from_filename(path) or infer_maze(obs)
    if name is None:
        raise BridgeplanError(f"cannot tell the maze of {path.name}: name it (one of "
                              f"{', '.join(MAZE_NAMES)})")
    maze = get_maze(name)
    states, actions = from_d4rl(obs, act, maze)
    starts = np.concatenate([[0], np.flatnonzero(continuity_breaks(states)) + 1]).astype(np.int64)
    reached = int(flags.sum()) if flags is not None else 0
    return Stream(maze.name, states, actions, starts, episodes=reached + 1, goals_reached=reached,
                  source=str(path), layout=MAZE2D)
