"""OGBench's datasets as both OGBench families make them (:mod:`.ogbench_pointmaze.generate`,
:mod:`.ogbench_manipulation.generate`): ``NAME.npz`` and ``NAME-val.npz`` in OGBench's format (the names
``make_env_and_datasets`` expects), a tenth of the episodes for validation, and ``NAME.json``: the dataset's identity
(its recipe and settings, the generator's and ogbench's versions) with each file's sha256. That record is the cache:
the same identity with the recorded files is not made again. And what both families' dataset commands share
(:class:`OGBenchFamily`)."""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from bridgeplan.envs.family import Family
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_bytes, atomic_write_text, check_writable
from bridgeplan.paths import datasets_root
from bridgeplan.progress import progress_bar


@contextlib.contextmanager
def legacy_rng(seed: int | np.random.RandomState) -> Iterator[None]:
    """Within the block NumPy's global legacy RNG is ``RandomState(seed)`` (or continues the given
    ``RandomState``, whose state is advanced); the caller's global state is restored afterwards. OGBench's recipes
    draw from that global RNG."""
    saved = np.random.get_state()
    rs = seed if isinstance(seed, np.random.RandomState) else np.random.RandomState(seed)
    np.random.set_state(rs.get_state())
    try:
        yield
    finally:
        rs.set_state(np.random.get_state())
        np.random.set_state(saved)


def validation_episodes(episodes: int) -> int:
    """OGBench's ``episodes // 10``, but at least 1 (its loader cannot read an empty file)."""
    return max(1, episodes // 10)


def ogbench_version() -> str:
    from importlib.metadata import version

    return version("ogbench")


def made_with() -> dict:
    """What else a generated dataset's arrays depend on besides its identity: MuJoCo's and NumPy's versions and the CPU
    (the same recipe and seed regenerated on another machine gave other arrays: scene's and cube-double's, on an
    AVX2-only CPU with MuJoCo 4.0.1, against the committed rows' data). Recorded beside the identity, not in it: a
    dataset made elsewhere is still this recipe's."""
    from importlib.metadata import version

    from bridgeplan.device import cpu_model

    return {"mujoco": version("mujoco"), "numpy": np.__version__, "cpu": cpu_model()}


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def content_sha256(arrays: dict[str, np.ndarray]) -> str:
    """The arrays' own digest (names, dtypes, shapes, bytes): equal for equal data, whatever the zip's timestamps."""
    digest = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        digest.update(f"{k}:{a.dtype.str}:{a.shape}".encode())
        digest.update(a.tobytes())
    return digest.hexdigest()


@dataclass
class Generated:
    name: str
    train_path: Path
    val_path: Path
    record: dict
    """The identity record written beside the files (``NAME.json``)."""
    cached: bool
    seconds: float = 0.0
    made: Any = field(default=None)
    """What the recipe's ``make`` returned beside the arrays (manipulation: what its oracles reached)."""


def dataset_paths(name: str, out_dir: str | Path) -> tuple[Path, Path, Path]:
    """``NAME.npz``, ``NAME-val.npz`` and ``NAME.json`` (the identity) in ``out_dir``."""
    out_dir = Path(out_dir)
    return out_dir / f"{name}.npz", out_dir / f"{name}-val.npz", out_dir / f"{name}.json"


def cached_record(name: str, out_dir: str | Path, ident: dict) -> dict | None:
    """The identity record of ``out_dir``'s dataset if it was made with ``ident`` and its files are the ones it
    recorded (by sha256); else None."""
    train, val, record_path = dataset_paths(name, out_dir)
    if not (train.is_file() and val.is_file() and record_path.is_file()):
        return None
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError):
        return None
    if record.get("identity") != ident:
        return None
    if record.get("files", {}).get(train.name) != file_sha256(train) or \
            record.get("files", {}).get(val.name) != file_sha256(val):
        return None
    return record


def write_dataset(name: str, out_dir: str | Path, ident: dict, episodes: int, episode_steps: int,
                  make: Callable[[int, Callable[[int], Any]], tuple[dict[str, np.ndarray], dict, Any]],
                  force: bool = False, progress: bool = True) -> Generated:
    """Dataset ``name`` of identity ``ident`` in ``out_dir``: ``make(episodes, progress)`` (its training and
    validation episodes in one run; ``progress`` called with steps done) returns the arrays to write, what its record
    adds and what :attr:`Generated.made` holds. Files already there with the same identity and the recorded digests
    are the cache: nothing is made. Other files there are refused (BridgeplanError) unless ``force``. Each file is
    written whole (a temporary file renamed)."""
    if episodes <= 0 or episode_steps <= 0:
        raise BridgeplanError(f"episodes and steps must be positive, got {episodes} and {episode_steps}")
    train_path, val_path, record_path = dataset_paths(name, out_dir)
    record = None if force else cached_record(name, out_dir, ident)
    if record is not None:
        return Generated(name, train_path, val_path, record, cached=True)
    existing = [str(p) for p in (train_path, val_path, record_path) if p.exists()]
    if existing and not force:
        raise BridgeplanError(f"{', '.join(existing)} already exist and are not this dataset (another identity, or "
                              "changed since): pass --force to overwrite")
    check_writable(out_dir, "dataset folder", folder=True)
    total = episodes + validation_episodes(episodes)
    t0 = time.perf_counter()
    with progress_bar(progress, total=total * episode_steps, desc=f"generate {name}", unit="step",
                      unit_scale=True, mininterval=1.0) as bar:
        data, extra, made = make(total, bar.update)
    seconds = time.perf_counter() - t0
    cut = episodes * episode_steps
    train = {k: v[:cut] for k, v in data.items()}
    val = {k: v[cut:] for k, v in data.items()}
    for path, arrays in ((train_path, train), (val_path, val)):
        atomic_write_bytes(path, lambda f, arrays=arrays: np.savez_compressed(f, **arrays))
    record = {"identity": ident,
              "files": {train_path.name: file_sha256(train_path), val_path.name: file_sha256(val_path)},
              "content_sha256": {train_path.name: content_sha256(train), val_path.name: content_sha256(val)},
              **extra, "made_with": made_with(), "seconds": round(seconds, 1)}
    atomic_write_text(record_path, json.dumps(record, indent=2) + "\n")
    return Generated(name, train_path, val_path, record, cached=False, seconds=seconds, made=made)


def compact_stream(data: dict[str, np.ndarray], name: str, source: str | Path, layout):
    """An OGBench file as read by ogbench's loader in its compact form (every row: the state before each action, and
    that action; each episode's last row marked invalid) as environment ``name``'s training
    :class:`~bridgeplan.data.stream.Stream` of ``layout``: one continuous segment per episode, split after those rows.
    An episode's last row is kept (its action is what was done there; windows never cross it)."""
    from bridgeplan.data.stream import Stream

    ends = np.flatnonzero(data["valids"] == 0)  # each episode's last row (the files' checks: the file's last is one)
    starts = np.concatenate([[0], ends[:-1] + 1]).astype(np.int64)
    return Stream(name, data["observations"].astype(np.float64), data["actions"].astype(np.float64), starts,
                  episodes=len(ends), source=str(source), layout=layout)


class OGBenchFamily(Family):
    """The data commands of a family whose datasets are OGBench's: npz files under ``datasets/ogbench`` (or
    ``$BRIDGEPLAN_DATASETS/ogbench``), of the recipe's size, made by the package ``data_package``'s
    ``generate.generate_dataset`` and checked by its ``reading.check_dataset``."""

    data_package: str

    def default_dataset(self, env: str, steps: int, piece_steps: int = 0, version: int | None = None) -> str:
        return str(datasets_root() / "ogbench" / f"{self.check(env)}.npz")

    def generate_dataset(self, env: str, out: Path | None, seed: int, steps: int | None = None,
                         piece_steps: int | None = None, episodes: int | None = None, episode_steps: int | None = None,
                         workers: int = 1, force: bool = False, progress: bool = True) -> tuple[Path, bool]:
        """OGBench's recipe (its size unless ``episodes`` and ``episode_steps`` say otherwise): NAME.npz,
        NAME-val.npz and NAME.json (identity and sha256) in ``out``'s folder (default ``datasets/ogbench``, or under
        ``$BRIDGEPLAN_DATASETS``); returns NAME.npz. The same identity already there is reused (a cache)."""
        if steps is not None or piece_steps is not None or workers != 1:
            raise BridgeplanError("an OGBench dataset has its recipe's size: give --episodes and --episode-steps, "
                                  "not --steps, --piece-steps or --workers")
        folder = datasets_root() / "ogbench" if out is None else Path(out)
        folder = folder.parent if folder.suffix == ".npz" else folder
        made = import_module(f"{self.data_package}.generate").generate_dataset(
            env, folder, seed=seed, episodes=episodes, episode_steps=episode_steps, force=force, progress=progress)
        return made.train_path, not made.cached

    def tasks(self, env: str, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
              task_ids: tuple[int, ...] | None = None):
        if multi_task:
            raise BridgeplanError("OGBench's protocol has its 5 tasks, no Multi2D (--multi-task): choose tasks with "
                                  "--tasks")
        return self.protocol_tasks(env, self.episodes if episodes is None else episodes, seed, task_ids)

    def protocol_tasks(self, env: str, episodes: int, seed: int, task_ids: tuple[int, ...] | None):
        """``episodes`` per task of the protocol's tasks (``task_ids``: some of them, or validation tasks)."""
        raise NotImplementedError

    def reads(self, path: str) -> bool:
        """An npz file (OGBench's format); which environment's it is is :meth:`dataset_info`'s to check."""
        import zipfile

        return Path(path).is_file() and zipfile.is_zipfile(path)

    def dataset_info(self, path: str, env: str | None) -> tuple[dict, str]:
        from dataclasses import asdict

        if env is None:
            raise BridgeplanError(f"{path}: an OGBench file does not say its dataset: give --maze NAME")
        c = import_module(f"{self.data_package}.reading").check_dataset(path, env)
        return asdict(c), c.summary()
