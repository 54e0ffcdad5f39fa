"""Reading OGBench manipulation dataset files (ours or official ones from a local path) with ogbench's own loader,
after checking that the file is one of the named dataset.

OGBench's npz format holds no metadata, so the dataset is recognised from its arrays: every manipulation scene here
has its own observation width (:attr:`~bridgeplan.envs.ogbench_manipulation.names.Scene.obs_dim`) and 5-D actions in
[-1, 1]; a file of another scene (or of pointmaze) fails that check.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bridgeplan.data.npz import REQUIRED, read_npz
from bridgeplan.envs.ogbench_manipulation.names import ACT_DIM, parse_dataset_name
from bridgeplan.errors import BridgeplanError


@dataclass
class DatasetCheck:
    """What :func:`check_dataset` found in a file."""

    path: str
    name: str
    transitions: int
    episodes: int
    episode_lengths: list[int]
    """The distinct episode lengths (one value for a play dataset)."""
    keys: list[str]
    action_mean: list[float]
    action_std: list[float]
    sha256: str | None = None
    """The file's digest as its identity record says (None: no record beside it)."""

    def summary(self) -> str:
        lengths = ", ".join(map(str, self.episode_lengths))
        digest = f", sha256 {self.sha256[:16]}" if self.sha256 else ""
        return (f"{self.path}: {self.name}, {self.transitions} steps in {self.episodes} "
                f"episode{'s' if self.episodes != 1 else ''} of {lengths} steps, action std "
                f"{', '.join(f'{s:.2f}' for s in self.action_std)}, arrays {', '.join(self.keys)}{digest}")


def check_dataset(path: str | Path, name: str) -> DatasetCheck:
    """Check that ``path`` is an OGBench manipulation dataset of ``name`` (``cube-single-play-v0``): one-line
    BridgeplanErrors for a missing or unreadable file, missing arrays, observations of another width, actions that are
    not 5-D in [-1, 1], arrays of unequal length, a last episode without its terminal (:func:`read_npz`)."""
    spec = parse_dataset_name(name)
    path = Path(path)
    arrays, keys = read_npz(path)
    obs, actions, terminals = (arrays[k] for k in REQUIRED)
    if obs.ndim != 2 or obs.shape[1] != spec.obs_dim:
        raise BridgeplanError(f"{path} is not a {spec.name} dataset: observations have shape {list(obs.shape)}, "
                              f"{spec.name}'s are [N, {spec.obs_dim}]")
    if actions.ndim != 2 or actions.shape[1] != ACT_DIM or np.abs(actions).max(initial=0) > 1:
        raise BridgeplanError(f"{path} is not a manipulation dataset: actions have shape {list(actions.shape)}, "
                              f"expected [N, {ACT_DIM}] in [-1, 1]")
    ends = np.flatnonzero(terminals)
    lengths = np.diff(np.concatenate([[-1], ends]))
    return DatasetCheck(str(path), spec.name, len(obs), len(ends), sorted({int(n) for n in lengths}), keys,
                        actions.mean(axis=0).round(4).tolist(), actions.std(axis=0).round(4).tolist(),
                        _recorded_sha256(path))


def _recorded_sha256(path: Path) -> str | None:
    """The file's sha256 as the identity record beside it (``NAME.json``, a generated dataset's) has it."""
    import json

    from bridgeplan.envs.ogbench_data import file_sha256

    stem = path.name.removesuffix(".npz").removesuffix("-val")
    record = path.with_name(f"{stem}.json")
    if not record.is_file():
        return None
    try:
        recorded = json.loads(record.read_text()).get("files", {}).get(path.name)
    except (OSError, ValueError):
        return None
    if recorded is not None and recorded != file_sha256(path):
        raise BridgeplanError(f"{path} is not the file its identity record {record.name} names (sha256 differs)")
    return recorded


def load_dataset(path: str | Path, name: str, compact_dataset: bool = False) -> dict[str, np.ndarray]:
    """:func:`check_dataset`, then ``ogbench.utils.load_dataset`` (the package's own reader)."""
    from ogbench.utils import load_dataset as ogbench_load

    check_dataset(path, name)
    return ogbench_load(str(path), compact_dataset=compact_dataset)
