"""Datasets in the Minari format (hdf5): our writer, and one reader for ours and official ones.

The reader uses h5py on Minari's documented layout (``data/main_data.hdf5`` with ``episode_<k>``
groups, ``data/metadata.json``) so that it reads an official ``D4RL/pointmaze/*`` dataset a user
downloaded as well as ours, without Minari's per-episode overhead.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import h5py
import numpy as np

from bridgeplan.data.generate import Episodes
from bridgeplan.data.stream import Stream, join_episodes
from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import MAZE_NAMES, Maze, get_maze

DATA_FILE = Path("data") / "main_data.hdf5"
METADATA_FILE = Path("data") / "metadata.json"


def write_minari(episodes: Episodes, maze: Maze, out: Path, dataset_id: str, seed: int,
                 force: bool = False) -> Path:
    """Write ``episodes`` as a Minari dataset into the directory ``out`` (atomically: temp dir, then rename)."""
    import gymnasium as gym
    import gymnasium_robotics
    import minari
    from minari.data_collector import EpisodeBuffer

    out = Path(out).resolve()  # minari resolves paths relative to its own root
    if out.exists() and not force:
        raise BridgeplanError(f"{out} already exists; pass --force to overwrite it")
    gym.register_envs(gymnasium_robotics)
    buffers = []
    for k, (obs, act, rew, goal) in enumerate(zip(episodes.observations, episodes.actions, episodes.rewards,
                                                   episodes.goals)):
        steps = len(act)
        truncations = np.zeros(steps, dtype=bool)
        truncations[-1] = True
        observations = {"observation": obs, "achieved_goal": obs[:, :2].copy(),
                        "desired_goal": np.repeat(np.asarray(goal)[None], steps + 1, axis=0)}
        buffers.append(EpisodeBuffer(id=k, seed=seed if k == 0 else None, observations=observations,
                                     actions=act, rewards=rew, terminations=np.zeros(steps, dtype=bool),
                                     truncations=truncations))
    total = sum(len(a) for a in episodes.actions)
    env = gym.make(maze.gym_id, continuing_task=True, reset_target=True, max_episode_steps=total)
    eval_map = [["g" if (i, j) == maze.eval_goal_cell else c for j, c in enumerate(row)]
                for i, row in enumerate(maze.grid)]
    eval_env = gym.make(maze.gym_id, continuing_task=True, reset_target=False, maze_map=eval_map,
                        max_episode_steps=maze.episode_steps)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp_root = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    previous = os.environ.get("MINARI_DATASETS_PATH")
    try:
        os.environ["MINARI_DATASETS_PATH"] = str(tmp_root)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            minari.create_dataset_from_buffers(
                dataset_id, buffers, env=env, eval_env=eval_env, algorithm_name="noisy waypoint expert",
                author="bridgeplan", data_format="hdf5",
                description=f"bridgeplan noisy expert stream, Minari D4RL/pointmaze recipe, seed {seed}")
        built = tmp_root.joinpath(*dataset_id.split("/"))
        if out.exists():
            shutil.rmtree(out)
        os.replace(built, out)
    finally:
        if previous is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = previous
        shutil.rmtree(tmp_root, ignore_errors=True)
        env.close()
        eval_env.close()
    return out


def _maze_from_metadata(meta: dict, path: Path) -> str:
    spec = meta.get("env_spec")
    spec = json.loads(spec) if isinstance(spec, str) else spec
    maze_map = (spec or {}).get("kwargs", {}).get("maze_map")
    if maze_map is None:
        raise BridgeplanError(f"{path} is not a PointMaze dataset (no maze_map in its env spec)")
    walls = [[1 if c in (1, "1") else 0 for c in row] for row in maze_map]
    for name in MAZE_NAMES:
        if [list(r) for r in get_maze(name).grid] == walls:
            return name
    raise BridgeplanError(f"{path}: its maze layout is none of {', '.join(MAZE_NAMES)}")


def resolve_minari_path(path_or_id: str) -> Path | None:
    """A dataset directory from a path, or from a Minari id under ``MINARI_DATASETS_PATH`` / ~/.minari."""
    path = Path(path_or_id)
    if (path / DATA_FILE).exists():
        return path
    root = Path(os.environ.get("MINARI_DATASETS_PATH", Path.home() / ".minari" / "datasets"))
    candidate = root.joinpath(*path_or_id.split("/"))
    return candidate if (candidate / DATA_FILE).exists() else None


def read_minari(path: Path) -> Stream:
    """Read a Minari PointMaze dataset directory into a :class:`Stream`."""
    path = Path(path)
    try:
        meta = json.loads((path / METADATA_FILE).read_text())
    except (OSError, ValueError) as e:
        raise BridgeplanError(f"{path} is not a Minari dataset: cannot read {METADATA_FILE}: {e}") from None
    maze = _maze_from_metadata(meta, path)
    observations, actions = [], []
    try:
        with h5py.File(path / DATA_FILE, "r") as f:
            names = sorted((k for k in f.keys() if k.startswith("episode_")), key=lambda k: int(k.split("_")[1]))
            for name in names:
                group = f[name]
                obs = group["observations"]
                obs = obs["observation"][()] if isinstance(obs, h5py.Group) else obs[()]
                act = group["actions"][()]
                if obs.ndim != 2 or obs.shape[1] != 4 or act.shape != (len(obs) - 1, 2):
                    raise BridgeplanError(f"{path}: episode {name} has observations {obs.shape} and actions "
                                          f"{act.shape}, not a PointMaze episode")
                observations.append(obs.astype(np.float64))
                actions.append(act.astype(np.float64))
    except BridgeplanError:
        raise
    except (OSError, KeyError, ValueError) as e:
        raise BridgeplanError(f"cannot read {path / DATA_FILE} (truncated or not Minari hdf5?): {e}") from None
    if not observations:
        raise BridgeplanError(f"{path} holds no episodes")
    states, acts, starts = join_episodes(observations, actions)
    return Stream(maze, states, acts, starts, episodes=len(observations), source=str(path))
