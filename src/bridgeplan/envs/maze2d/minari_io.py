"""Datasets in the Minari format (minari 0.5, hdf5): our writer, and one reader for ours and official ones.

Writer: ``minari.create_dataset_from_buffers`` with the PointMaze env spec (so that
``MinariDataset(path).recover_environment()`` works, and ``eval_env=True`` gives the single-task
evaluation env), one Minari episode per goal, observations as PointMaze's dict
(``observation``, ``achieved_goal``, ``desired_goal``), truncation at the end of every episode, and the
generator's data version in the metadata (:data:`VERSION_KEY`).

Reader: :mod:`bridgeplan.data.minari` on Minari's layout, so that it reads an official ``D4RL/pointmaze/*`` dataset a
user downloaded as well as ours, without Minari's per-episode overhead. Episodes are joined into continuous segments
by :func:`bridgeplan.data.stream.join_episodes`.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

from bridgeplan.data.minari import DATA_FILE, METADATA_FILE, read_episodes, read_metadata
from bridgeplan.data.stream import Stream, join_episodes
from bridgeplan.envs.maze2d.generate import DATA_VERSION, GeneratedStream
from bridgeplan.envs.maze2d.grids import MAZE_NAMES, Maze, get_maze
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D

AUTHOR = "bridgeplan"
VERSION_KEY = "bridgeplan_data_version"
"""Metadata key of the generator's :data:`~bridgeplan.envs.maze2d.generate.DATA_VERSION`."""


def dataset_id_for(maze: Maze) -> str:
    return f"bridgeplan/pointmaze-{maze.name}-v0"


def _episode_buffers(streams: list[GeneratedStream], seed: int):
    from minari.data_collector import EpisodeBuffer

    k = 0
    for stream in streams:
        for obs, act, rew, goal in stream.episodes():
            steps = len(act)
            truncations = np.zeros(steps, dtype=bool)
            truncations[-1] = True
            observations = {"observation": obs, "achieved_goal": MAZE2D.state_positions(obs).copy(),
                            "desired_goal": np.repeat(np.asarray(goal, np.float64)[None], steps + 1, axis=0)}
            yield EpisodeBuffer(id=k, seed=seed if k == 0 else None, observations=observations, actions=act,
                                rewards=rew, terminations=np.zeros(steps, dtype=bool),
                                truncations=truncations)
            k += 1


def write_minari_into(directory: Path, streams: list[GeneratedStream], maze: Maze, seed: int,
                      dataset_id: str | None = None) -> Path:
    """Write ``streams`` as a Minari dataset under the (existing, empty) ``directory``; returns the
    dataset directory inside it (``directory/<namespace>/<name>``). Not atomic: see
    ``bridgeplan.envs.maze2d.datasets.generate_dataset``."""
    import minari

    from bridgeplan.envs.maze2d.sim import make_gym_env

    dataset_id = dataset_id or dataset_id_for(maze)
    total = sum(len(s) for s in streams)
    env = make_gym_env(maze, continuing_task=True, reset_target=True, max_episode_steps=total)
    eval_map = [["g" if (i, j) == maze.eval_goal_cell else c for j, c in enumerate(row)]
                for i, row in enumerate(maze.grid)]
    eval_env = make_gym_env(maze, continuing_task=True, reset_target=False, maze_map=eval_map,
                            max_episode_steps=maze.episode_steps)
    previous = os.environ.get("MINARI_DATASETS_PATH")
    try:
        os.environ["MINARI_DATASETS_PATH"] = str(Path(directory).resolve())  # minari needs it absolute
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            minari.create_dataset_from_buffers(
                dataset_id, list(_episode_buffers(streams, seed)), env=env, eval_env=eval_env,
                algorithm_name="noisy shortest-path waypoint expert (Minari D4RL/pointmaze recipe)",
                author=AUTHOR, data_format="hdf5",
                description=(f"bridgeplan: {total} steps of a noisy waypoint expert in {maze.gym_id}, "
                             f"continuing task with a new random goal when reached (one episode per goal), "
                             f"{len(streams)} continuous stream(s), seed {seed}, data version {DATA_VERSION}"))
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous
        env.close()
        eval_env.close()
    built = Path(directory).resolve().joinpath(*dataset_id.split("/"))
    meta = json.loads((built / METADATA_FILE).read_text())
    meta[VERSION_KEY] = DATA_VERSION  # minari has no argument for extra metadata; it keeps unknown keys
    (built / METADATA_FILE).write_text(json.dumps(meta))
    return built


def maze_from_metadata(meta: dict, path: Path) -> str:
    """The maze of a Minari dataset, from the ``maze_map`` of its env spec."""
    walls = None
    for key in ("env_spec", "eval_env_spec"):
        spec = meta.get(key)
        try:
            spec = json.loads(spec) if isinstance(spec, str) else spec
        except ValueError:
            spec = None
        maze_map = (spec or {}).get("kwargs", {}).get("maze_map")
        if maze_map is not None:
            walls = [[1 if c in (1, "1") else 0 for c in row] for row in maze_map]
            break
    if walls is None:
        raise BridgeplanError(f"{path} is not a PointMaze dataset (no maze_map in its env spec); "
                              f"name the maze explicitly")
    for name in MAZE_NAMES:
        if [list(r) for r in get_maze(name).grid] == walls:
            return name
    raise BridgeplanError(f"{path}: its maze layout is none of {', '.join(MAZE_NAMES)}")


def data_version_from_metadata(meta: dict) -> int | None:
    """The generator version of one of our datasets (1 if it predates recorded versions); None for a
    dataset bridgeplan did not write (an official Minari one)."""
    if VERSION_KEY in meta:
        return int(meta[VERSION_KEY])
    author = meta.get("author")
    authors = [author] if isinstance(author, str) else list(author or [])
    return 1 if AUTHOR in authors else None  # ours, written before versions were recorded


def read_minari(path: Path, maze_name: str | None = None) -> Stream:
    """Read a Minari PointMaze dataset directory (ours or an official one) into a :class:`Stream`."""
    path = Path(path)
    meta = read_metadata(path)
    maze = get_maze(maze_name).name if maze_name else maze_from_metadata(meta, path)

    def check(name: str, obs: np.ndarray, act: np.ndarray) -> None:
        if obs.ndim != 2 or obs.shape[1] != MAZE2D.obs_dim or act.shape != (len(obs) - 1, MAZE2D.act_dim):
            raise BridgeplanError(f"{path}: {name} has observations {list(obs.shape)} and actions "
                                  f"{list(act.shape)}, not a PointMaze episode")

    episodes = read_episodes(path, check)
    states, acts, starts = join_episodes(episodes.observations, episodes.actions)
    if len(states) == 0:
        raise BridgeplanError(f"{path} holds no transitions")
    return Stream(maze, states, acts, starts, episodes=len(episodes.observations),
                  goals_reached=episodes.goals_reached, source=str(path), data_version=data_version_from_metadata(meta),
                  layout=MAZE2D)


def resolve_minari_path(path_or_id: str) -> Path | None:
    """A dataset directory from a path, or from a Minari id under ``$MINARI_DATASETS_PATH`` (default
    ``~/.minari/datasets``); None if neither holds a dataset."""
    path = Path(path_or_id)
    if (path / METADATA_FILE).exists() or (path / DATA_FILE).exists():
        return path
    if path.is_absolute() or path_or_id.startswith("."):
        return None
    root = Path(os.environ.get("MINARI_DATASETS_PATH", Path.home() / ".minari" / "datasets"))
    candidate = root.joinpath(*path_or_id.split("/"))
    return candidate if (candidate / METADATA_FILE).exists() or (candidate / DATA_FILE).exists() else None


def replace_directory(built: Path, out: Path) -> None:
    """Move the finished directory ``built`` to ``out``, replacing an existing ``out`` (rename-based)."""
    out = Path(out)
    trash = None
    if out.exists() or out.is_symlink():
        trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
        os.replace(out, trash / out.name)
    os.replace(built, out)
    if trash is not None:
        shutil.rmtree(trash, ignore_errors=True)
