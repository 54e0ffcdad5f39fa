"""Dataset files: generate one (Minari format, written atomically), load any into a :class:`Stream`.

``load_stream(path_or_id)`` is the one entry point for training. It accepts our dataset directories,
official Minari ``D4RL/pointmaze/*`` datasets (by directory or id) and legacy D4RL ``maze2d-*.hdf5``
files, and goes through a flat ``.npz`` cache next to the source (states, actions, segment starts,
maze, source, data version), valid while the source file keeps its size and modification time. A
dataset of ours made by an older generator (:data:`~bridgeplan.envs.maze2d.generate.DATA_VERSION`) loads with
a one-line warning on stderr.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from bridgeplan.data.stream import Stream
from bridgeplan.envs.maze2d.d4rl_io import read_d4rl
from bridgeplan.envs.maze2d.generate import DATA_VERSION, generate_streams
from bridgeplan.envs.maze2d.grids import get_maze
from bridgeplan.envs.maze2d.minari_io import (
    DATA_FILE,
    read_minari,
    replace_directory,
    resolve_minari_path,
    write_minari_into,
)
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import check_writable
from bridgeplan.paths import datasets_root
from bridgeplan.trajectory import MAZE2D

CACHE_VERSION = 2
"""2: the cache records the data version (a version-1 cache is rebuilt from its source)."""
CACHE_NAME = "bridgeplan-cache.npz"


def default_dataset_path(maze_name: str, steps: int, root: str | Path | None = None,
                         piece_steps: int | None = None) -> Path:
    """``<root>/<maze>-<steps>`` (``-pieces<N>`` for pieces of N steps); root: the argument, else
    ``$BRIDGEPLAN_DATASETS``, else ``datasets``."""
    pieces = f"-pieces{piece_steps}" if piece_steps else ""
    return Path(root or datasets_root()) / f"{maze_name}-{steps}{pieces}"


def stream_from_generated(maze_name: str, streams, source: str = "") -> Stream:
    """The :class:`Stream` of freshly generated streams (each a continuous segment)."""
    starts = np.cumsum([0] + [len(s) for s in streams[:-1]])
    return Stream(maze_name, np.concatenate([s.observations[:-1] for s in streams]),
                  np.concatenate([s.actions for s in streams]), starts,
                  episodes=sum(len(s.episode_starts) for s in streams),
                  goals_reached=sum(s.goals_reached for s in streams), source=source, data_version=DATA_VERSION,
                  layout=MAZE2D)


def generate_dataset(maze_name: str, steps: int, seed: int = 123, out: str | Path | None = None,
                     force: bool = False, progress: bool = True, workers: int = 1,
                     piece_steps: int | None = None) -> Path:
    """Generate a noisy expert dataset of ``steps`` transitions (one stream per worker, or independent pieces of
    ``piece_steps``: ``generate.generate_streams``) and write it as a Minari dataset directory ``out`` (default
    :func:`default_dataset_path`), with its cache; returns ``out``.

    Atomic: the dataset is built in a temporary directory beside ``out`` and renamed into place; an
    existing ``out`` is only replaced with ``force``. Nothing is left behind on error or interrupt.
    """
    maze = get_maze(maze_name)
    if steps <= 0:
        raise BridgeplanError(f"steps must be positive, got {steps}")
    if workers <= 0:
        raise BridgeplanError(f"workers must be positive, got {workers}")
    out = Path(out) if out is not None else default_dataset_path(maze.name, steps, piece_steps=piece_steps)
    if (out.exists() or out.is_symlink()) and not force:
        raise BridgeplanError(f"{out} already exists; pass --force to overwrite it")
    if out.exists() and not out.is_dir():
        raise BridgeplanError(f"{out} exists and is not a directory")
    check_writable(out, "dataset folder", folder=True)
    streams = generate_streams(maze, steps, seed, workers=workers, progress=progress, piece_steps=piece_steps)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp.", dir=out.parent))
    try:
        built = write_minari_into(tmp, streams, maze, seed)
        stream = stream_from_generated(maze.name, streams, str(out))
        write_cache(built / DATA_FILE, built / CACHE_NAME, stream)
        replace_directory(built, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out


def _source(path_or_id: str) -> tuple[str, Path, Path]:
    """(kind, source file, cache file) of a dataset path or Minari id; kind is ``minari`` or ``d4rl``."""
    directory = resolve_minari_path(path_or_id)
    if directory is not None:
        return "minari", directory / DATA_FILE, directory / CACHE_NAME
    path = Path(path_or_id)
    if path.is_file():
        return "d4rl", path, path.with_name(path.name + "." + CACHE_NAME)
    if path.is_dir():
        raise BridgeplanError(f"{path} is not a Minari dataset (no {DATA_FILE} in it)")
    raise BridgeplanError(f"no dataset at {path_or_id} (expected a Minari dataset directory or id, "
                          f"or a D4RL maze2d .hdf5 file)")


def _stamp(source: Path) -> np.ndarray:
    try:
        stat = source.stat()
    except OSError:
        raise BridgeplanError(f"{source} is missing: the dataset is incomplete") from None
    return np.array([CACHE_VERSION, stat.st_size, stat.st_mtime_ns], dtype=np.int64)


def write_cache(source: Path, cache: Path, stream: Stream) -> bool:
    """Write the flat copy of ``stream`` (atomically); False if the directory is not writable."""
    tmp = cache.with_name(f".{cache.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, stamp=_stamp(source), maze=stream.maze, states=stream.states, actions=stream.actions,
                     segment_starts=stream.segment_starts, episodes=stream.episodes,
                     goals_reached=stream.goals_reached, source=stream.source,
                     data_version=-1 if stream.data_version is None else stream.data_version)  # npz: no None
        os.replace(tmp, cache)
        return True
    except OSError:
        tmp.unlink(missing_ok=True)
        return False


def read_cache(source: Path, cache: Path) -> Stream | None:
    """The cached stream if the cache is there and matches ``source``; None otherwise."""
    if not cache.exists():
        return None
    try:
        with np.load(cache, allow_pickle=False) as z:
            if not np.array_equal(z["stamp"], _stamp(source)):
                return None
            version = int(z["data_version"])
            return Stream(str(z["maze"]), z["states"], z["actions"], z["segment_starts"], int(z["episodes"]),
                          int(z["goals_reached"]), str(z["source"]), None if version < 0 else version,
                          layout=MAZE2D)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # truncated, bad CRC, foreign
        return None  # a broken cache is rebuilt


def load_stream(path_or_id: str | Path, maze: str | None = None, use_cache: bool = True) -> Stream:
    """Load a dataset (Minari directory or id, or D4RL maze2d hdf5 file) as a :class:`Stream`, through
    the flat-array cache. ``maze`` overrides the maze named by the dataset (needed for a D4RL file
    whose name and data do not tell it)."""
    kind, source, cache = _source(str(path_or_id))
    stream = read_cache(source, cache) if use_cache else None
    if stream is None or (maze is not None and get_maze(maze).name != stream.maze):
        if not source.exists():
            raise BridgeplanError(f"{source} is missing: the dataset is incomplete")
        stream = read_minari(source.parent.parent, maze) if kind == "minari" else read_d4rl(source, maze)
        if use_cache:
            write_cache(source, cache, stream)
    if stream.data_version is not None and stream.data_version < DATA_VERSION:
        print(f"warning: {path_or_id} was made by an older bridgeplan data generator (data version "
              f"{stream.data_version}; version {DATA_VERSION} follows Minari's recipe): regenerate it with "
              f"`bridgeplan data generate`", file=sys.stderr)
    return stream
