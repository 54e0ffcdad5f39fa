"""Reading a dataset in the Minari format (minari 0.5, hdf5) with h5py: its metadata and its episodes.

Minari's layout is ``data/metadata.json`` and ``data/main_data.hdf5`` with ``episode_<k>`` groups, each with
``observations`` (``T + 1`` rows; a dict environment's are a group whose ``observation`` is the state) and
``actions`` (``T`` rows). Read without Minari itself, which costs a Python object per episode. Which environment
the episodes are of is the family's to say (:mod:`bridgeplan.envs.maze2d.minari_io`, :mod:`bridgeplan.envs.goal_env`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from bridgeplan.errors import BridgeplanError

DATA_FILE = Path("data") / "main_data.hdf5"
METADATA_FILE = Path("data") / "metadata.json"


def one_line(e: Exception) -> str:
    return " ".join(str(e).split()) or type(e).__name__


@dataclass
class MinariEpisodes:
    """A Minari dataset's episodes, in the order of their numbers."""

    metadata: dict
    observations: list[np.ndarray]
    """Per episode ``[T + 1, obs_dim]``."""
    actions: list[np.ndarray]
    """Per episode ``[T, act_dim]``."""
    goals_reached: int
    """Episodes whose last reward is positive."""


def read_metadata(path: Path) -> dict:
    try:
        return json.loads((Path(path) / METADATA_FILE).read_text())
    except (OSError, ValueError) as e:
        raise BridgeplanError(f"{path} is not a Minari dataset: cannot read {METADATA_FILE} ({one_line(e)})") from None


def read_episodes(path: Path, check: Callable[[str, np.ndarray, np.ndarray], None]) -> MinariEpisodes:
    """Every episode of the Minari dataset directory ``path``; ``check(name, observations, actions)`` raises a
    BridgeplanError for an episode that is not of the environment expected."""
    import h5py

    path = Path(path)
    meta = read_metadata(path)
    observations, actions = [], []
    reached = 0
    try:
        with h5py.File(path / DATA_FILE, "r") as f:
            names = sorted((k for k in f.keys() if k.startswith("episode_")), key=lambda k: int(k.split("_")[1]))
            for name in names:
                group = f[name]
                obs = group["observations"]
                obs = obs["observation"][()] if isinstance(obs, h5py.Group) else obs[()]
                act = group["actions"][()]
                check(name, obs, act)
                if "rewards" in group and len(act):
                    reached += bool(group["rewards"][-1] > 0)
                observations.append(obs)
                actions.append(act)
    except BridgeplanError:
        raise
    except (OSError, KeyError, ValueError, TypeError) as e:
        raise BridgeplanError(f"cannot read {path / DATA_FILE} (truncated, or not Minari hdf5): "
                              f"{one_line(e)}") from None
    return MinariEpisodes(meta, observations, actions, reached)
