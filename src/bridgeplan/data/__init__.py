"""Offline datasets: generation, Minari and legacy D4RL readers, the flat-array cache, windows.

``load_stream(path)`` is the one entry point for training: it reads a cached flat copy when one is
up to date, else the source (Minari directory or id, or a D4RL hdf5 file), and writes the cache.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridgeplan.checkpoint import atomic_write_bytes
from bridgeplan.data.d4rl_io import read_d4rl
from bridgeplan.data.generate import generate_episodes
from bridgeplan.data.minari_io import DATA_FILE, read_minari, resolve_minari_path, write_minari
from bridgeplan.data.stream import Stream
from bridgeplan.data.windows import WindowDataset
from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import get_maze

__all__ = ["Stream", "WindowDataset", "generate_dataset", "load_stream"]
CACHE_VERSION = 1


def generate_dataset(maze_name: str, steps: int, seed: int, out: Path, force: bool = False,
                     progress: bool = True) -> Path:
    """Generate a noisy expert stream and write it as a Minari dataset directory ``out``."""
    if steps <= 0:
        raise BridgeplanError(f"steps must be positive, got {steps}")
    maze = get_maze(maze_name)
    out = Path(out)
    if out.exists() and not force:
        raise BridgeplanError(f"{out} already exists; pass --force to overwrite it")
    episodes = generate_episodes(maze, steps, seed, progress=progress)
    return write_minari(episodes, maze, out, f"bridgeplan/pointmaze-{maze.name}-v0", seed, force=force)


def _source(path_or_id: str) -> tuple[Path, Path]:
    """(source file, cache file) for a dataset path or Minari id."""
    directory = resolve_minari_path(path_or_id)
    if directory is not None:
        return directory / DATA_FILE, directory / "bridgeplan-cache.npz"
    path = Path(path_or_id)
    if path.is_file():
        return path, path.with_name(path.name + ".bridgeplan-cache.npz")
    raise BridgeplanError(f"no dataset at {path_or_id} (expected a Minari dataset directory or id, "
                          f"or a D4RL maze2d .hdf5 file)")


def load_stream(path_or_id: str, use_cache: bool = True) -> Stream:
    """Load a dataset as a :class:`Stream`, through the flat-array cache."""
    source, cache = _source(str(path_or_id))
    stat = source.stat()
    stamp = np.array([CACHE_VERSION, stat.st_size, stat.st_mtime_ns], dtype=np.int64)
    if use_cache and cache.exists():
        try:
            with np.load(cache, allow_pickle=False) as z:
                if np.array_equal(z["stamp"], stamp):
                    return Stream(str(z["maze"]), z["states"], z["actions"], z["segment_starts"],
                                  int(z["episodes"]), str(z["source"]))
        except (OSError, ValueError, KeyError):
            pass  # a broken cache is rebuilt
    is_minari = source.name == DATA_FILE.name and source.parent.name == "data"
    stream = read_minari(source.parent.parent) if is_minari else read_d4rl(source)
    if use_cache:
        try:
            atomic_write_bytes(cache, lambda f: np.savez(
                f, stamp=stamp, maze=stream.maze, states=stream.states, actions=stream.actions,
                segment_starts=stream.segment_starts, episodes=stream.episodes, source=stream.source))
        except OSError:
            pass  # a read-only dataset directory: no cache
    return stream
