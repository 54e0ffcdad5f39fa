"""Reading a dataset in OGBench's npz format: one row per step (``observations``, ``actions``), ``terminals`` 1 at
each episode's last row; no metadata. Which environment the rows are of is the family's to check
(:mod:`bridgeplan.envs.ogbench_pointmaze.reading`, :mod:`bridgeplan.envs.ogbench_manipulation.reading`,
:mod:`bridgeplan.envs.goal_env`)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from bridgeplan.errors import BridgeplanError

REQUIRED = ("observations", "actions", "terminals")


def read_npz(path: str | Path, optional: tuple[str, ...] = ()) -> tuple[dict[str, np.ndarray], list[str]]:
    """The arrays of :data:`REQUIRED` (and those of ``optional`` the file has), and the names of all its arrays.

    One-line BridgeplanErrors: a missing or unreadable file, missing arrays, arrays of unequal length, no rows, a last
    episode not closed by a terminal; a folder."""
    path = Path(path)
    if path.is_dir():
        raise BridgeplanError(f"{path} is a folder, not an npz file (OGBench's datasets are single .npz files)")
    if not path.is_file():
        raise BridgeplanError(f"no dataset file at {path}")
    if not zipfile.is_zipfile(path):
        raise BridgeplanError(f"{path} is not an npz file")
    try:
        with np.load(path) as f:
            keys = list(f.keys())
            missing = [k for k in REQUIRED if k not in keys]
            if missing:
                raise BridgeplanError(f"{path} is not an OGBench dataset: no {', '.join(missing)} array")
            arrays = {k: np.asarray(f[k]) for k in (*REQUIRED, *optional) if k in keys}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise BridgeplanError(f"{path} is not a readable npz file ({type(e).__name__}: {e})") from None
    obs, actions, terminals = (arrays[k] for k in REQUIRED)
    if len(actions) != len(obs) or terminals.shape != obs.shape[:1]:
        raise BridgeplanError(f"{path}: arrays of unequal length (observations {obs.shape}, actions {actions.shape}, "
                              f"terminals {terminals.shape})")
    if len(obs) == 0 or not terminals[-1]:
        raise BridgeplanError(f"{path}: {'empty' if len(obs) == 0 else 'the last episode has no terminal'}")
    return arrays, keys
