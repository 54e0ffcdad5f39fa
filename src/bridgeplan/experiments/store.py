"""The results store: one SQLite row per evaluation, keyed by what the evaluation is; safe for concurrent sweeps.

An evaluation is a trained run's snapshot sampled and executed one way on one set of episodes (:data:`KEY`); the
experiments that show it are memberships beside it (table ``memberships``), so an evaluation that two experiments
name is computed once and shown by both. WAL journaling and a busy timeout let two sweeps write at once; every
insert is one transaction, so an interrupted sweep keeps everything it finished. ``PRAGMA user_version`` holds the
schema version: a database from a newer bridgeplan is refused, untouched; one from an older one is upgraded in
place, in one transaction. Versions 1-4 keyed a row by its experiment too (one table ``results``), so the same
evaluation could be stored once per experiment: the upgrade keeps the first of them (by id) and makes the others
memberships. Version 1 had no execution or multi-task columns (its rows were open loop, single-task); version 2
no sampler column (rows sampled as their processes are by default); version 3 no plan-cost columns
(``network_calls_per_plan`` and the plans' residuals are empty there); none had ``split`` (it was the experiment's
``-validation`` suffix). Version 5 had no ``dataset`` (what the run was trained on, ``Stream.identity``): empty
there, and in every row made before runs recorded it.

The CSV form (:meth:`ResultsStore.export_csv`, the committed ``results.csv`` files) is one row per evaluation with
every key, its ``split`` and its ``experiments`` (space-separated); it and
the older CSVs (one row per experiment and evaluation, with an ``experiment`` column) are read by
:func:`read_csv_rows` and imported by :meth:`ResultsStore.import_rows`, nothing recomputed.
"""

from __future__ import annotations

import csv
import io
import json
import os
import sqlite3
import tempfile
import time
from collections.abc import Iterable
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.files import atomic_write_text, check_writable

SCHEMA_VERSION = 6

COLUMNS = {
    "run_name": "TEXT NOT NULL",
    "dataset": "TEXT",
    "maze": "TEXT NOT NULL",
    "process": "TEXT NOT NULL",
    "prior": "TEXT NOT NULL",
    "diffusion_steps": "INTEGER NOT NULL",
    "seed": "INTEGER NOT NULL",
    "step": "INTEGER NOT NULL",
    "train_seconds": "REAL",
    "nfe": "INTEGER NOT NULL",
    "episodes": "INTEGER NOT NULL",
    "eval_seed": "INTEGER NOT NULL",
    "split": "TEXT NOT NULL DEFAULT 'test'",
    "score_minari": "REAL",
    "score_minari_se": "REAL",
    "score_d4rl": "REAL",
    "score_d4rl_se": "REAL",
    "success_rate": "REAL",
    "plan_ms": "REAL",
    "prior_ms": "REAL",
    "floor_minari": "REAL",
    "execution": "TEXT NOT NULL DEFAULT ''",
    "multi_task": "INTEGER NOT NULL DEFAULT 0",
    "sampler": "TEXT NOT NULL DEFAULT ''",
    "calls_per_episode": "REAL",
    "decision_ms_p50": "REAL",
    "decision_ms_p95": "REAL",
    "network_calls_per_plan": "REAL",
    "plan_kinematics_rms": "REAL",
    "plan_dynamics_rms": "REAL",
    "config": "TEXT",
    "code_version": "TEXT",
    "created": "REAL",
}
KEY = ("run_name", "step", "nfe", "sampler", "execution", "multi_task", "episodes", "eval_seed")
"""What an evaluation is: the run (its name within the results directory, which holds one run per name), the
snapshot, the NFE, the sampling tag, the execution and the task set on given episodes. ``sampler`` is
``consistency.sampling_tag``: ``Process.sampling_tag()`` ('' as the process samples by default) and the consistency
correction's tag, if any; ``execution`` is ``replan.Execution.tag()`` ('' for open loop), ``multi_task`` 0/1,
``eval_seed`` the task seed (the training seed, plus ``evaluate.VALIDATION_SEED_OFFSET`` on validation episodes)."""
SPLITS = ("test", "validation")
VALIDATION_SUFFIX = "-validation"
"""Experiments on the validation episodes are named ``<name>-validation`` (``experiments.runner``)."""


def key_of(row: dict) -> tuple:
    """A row's :data:`KEY` values, in order."""
    return tuple(row[k] for k in KEY)


def split_of(experiment: str) -> str:
    """The split of an experiment's evaluations, from its name (``-validation``: the validation episodes)."""
    return "validation" if experiment.endswith(VALIDATION_SUFFIX) else "test"


def _tables() -> list[str]:
    cols = ", ".join(f"{k} {v}" for k, v in COLUMNS.items())
    return [f"CREATE TABLE IF NOT EXISTS evaluations (id INTEGER PRIMARY KEY, {cols}, UNIQUE ({', '.join(KEY)}))",
            "CREATE TABLE IF NOT EXISTS memberships (experiment TEXT NOT NULL, "
            "evaluation INTEGER NOT NULL REFERENCES evaluations(id), PRIMARY KEY (experiment, evaluation))"]


def stored_keys(path: Path) -> tuple[set[tuple], set[tuple[str, tuple]]]:
    """The :data:`KEY` of every evaluation in the store at ``path``, and every (experiment, KEY) membership; read
    only, nothing when there is no store (a store of an older schema is read as its upgrade would make it)."""
    path = Path(path)
    if not path.exists():
        return set(), set()
    check_store(path)
    try:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=60.0)
        try:
            db.row_factory = sqlite3.Row
            if db.execute("PRAGMA user_version").fetchone()[0] < 5:
                rows = [_upgraded(dict(r)) for r in db.execute("SELECT * FROM results")]
                return {key_of(r) for r in rows}, {(r["experiment"], key_of(r)) for r in rows}
            keys = {tuple(r) for r in db.execute(f"SELECT {', '.join(KEY)} FROM evaluations")}
            members = {(r[0], tuple(r)[1:]) for r in db.execute(
                f"SELECT m.experiment, {', '.join('e.' + k for k in KEY)} FROM memberships m "
                "JOIN evaluations e ON e.id = m.evaluation")}
            return keys, members
        finally:
            db.close()
    except sqlite3.DatabaseError as e:
        raise BridgeplanError(f"cannot use results store {path}: {e}") from None


def check_store(path: Path) -> None:
    """Refuse (:class:`BridgeplanError`) a store file that is not a whole store, read only, before anything reads
    or writes it: empty (0 bytes: never a store, since :class:`ResultsStore` creates one whole, and taking it for an
    empty one would compute every row again), corrupted (SQLite's quick check), or of a newer schema."""
    path = Path(path)
    if path.stat().st_size == 0:
        raise BridgeplanError(f"results store {path} is empty (0 bytes), not a store; left as it is (remove it to "
                              f"start an empty store)")
    try:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=60.0)
        try:
            problems = [" ".join(r[0].split()) for r in db.execute("PRAGMA quick_check")]
            version = db.execute("PRAGMA user_version").fetchone()[0]
            tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        finally:
            db.close()
    except sqlite3.DatabaseError as e:
        raise BridgeplanError(f"cannot use results store {path}: {e}") from None
    if problems != ["ok"]:
        raise BridgeplanError(f"results store {path} is corrupted ({problems[0]}); left as it is")
    if version > SCHEMA_VERSION:
        raise BridgeplanError(f"{path} has schema version {version}, newer than this bridgeplan understands "
                              f"({SCHEMA_VERSION}); upgrade bridgeplan")
    expected = {"evaluations", "memberships"} if version >= 5 else {"results"}
    if not expected <= tables:  # a damaged header (its version), or another program's database
        raise BridgeplanError(f"results store {path} is corrupted or not a results store (schema version {version} "
                              f"without its table {sorted(expected - tables)[0]!r}); left as it is")


def _create(path: Path) -> None:
    """A new, empty store at ``path``, made whole under a temporary name and linked into place (a store killed as it
    was created leaves no 0-byte file); another process that made it first wins."""
    check_writable(path.parent, "results folder", folder=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        db = sqlite3.connect(tmp)
        try:
            db.execute("PRAGMA journal_mode=WAL")
            with db:
                for statement in _tables():
                    db.execute(statement)
                db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
        finally:
            db.close()
        try:
            os.link(tmp, path)
        except FileExistsError:
            pass
        except OSError:  # a file system without hard links
            if not path.exists():
                os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
        for suffix in ("-wal", "-shm"):
            Path(tmp + suffix).unlink(missing_ok=True)


def _upgraded(old: dict) -> dict:
    """A row of a version 1-4 table as today's columns, with its ``experiment``: the defaults of the columns it
    lacked, and its split from the experiment's name."""
    row = {k: v for k, v in old.items() if k in COLUMNS or k == "experiment"}
    row.setdefault("execution", "")
    row.setdefault("multi_task", 0)
    row.setdefault("sampler", "")
    row["split"] = split_of(old["experiment"])
    return row


class ResultsStore:
    """The store file (``paths.store_path(results_dir)``); rows come from evaluations' JSON
    (:func:`row_from_eval_json`)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        if self.path.exists():
            check_store(self.path)  # before anything is written to it: a damaged page would show up mid-sweep
        else:
            _create(self.path)
        with self._connect() as db:
            db.execute("PRAGMA journal_mode=WAL")
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")  # one writer creates or upgrades; a second sweep waits, then sees it done
            version = db.execute("PRAGMA user_version").fetchone()[0]
            old = db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'results'").fetchone()
            for statement in _tables():
                db.execute(statement)
            if version == 5:  # evaluations without the data's identity: the column, empty
                db.execute("ALTER TABLE evaluations ADD COLUMN dataset TEXT")
            if old and version < 5:  # one row per experiment and evaluation -> evaluations + memberships
                db.row_factory = sqlite3.Row
                rows = [_upgraded(dict(r)) for r in db.execute("SELECT * FROM results ORDER BY id")]
                db.row_factory = None
                for row in rows:
                    self._insert(db, row, [row.pop("experiment")])
                db.execute("DROP TABLE results")
            db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")

    @contextmanager
    def _connect(self, read_only: bool = False) -> Iterator[sqlite3.Connection]:
        """A connection for one transaction (committed, then closed); SQLite's errors (a damaged
        file, a lock held too long) become one-line errors that name the file."""
        try:
            db = (sqlite3.connect(f"file:{self.path}?mode=ro", uri=True, timeout=60.0) if read_only
                  else sqlite3.connect(self.path, timeout=60.0))
            try:
                with db:
                    yield db
            finally:
                db.close()
        except sqlite3.DatabaseError as e:
            raise BridgeplanError(f"cannot use results store {self.path}: {e}") from None

    @staticmethod
    def _insert(db: sqlite3.Connection, row: dict, experiments: Iterable[str]) -> bool:
        """Insert the evaluation ``row`` unless one with its KEY is there, and make it a member of ``experiments``;
        True when the evaluation is new."""
        names = [k for k in COLUMNS if k in row]
        cursor = db.execute(f"INSERT OR IGNORE INTO evaluations ({', '.join(names)}) "
                            f"VALUES ({', '.join('?' * len(names))})", [row[k] for k in names])
        where = " AND ".join(f"{k} = ?" for k in KEY)
        (evaluation,) = db.execute(f"SELECT id FROM evaluations WHERE {where}", key_of(row)).fetchone()
        db.executemany("INSERT OR IGNORE INTO memberships (experiment, evaluation) VALUES (?, ?)",
                       [(name, evaluation) for name in experiments])
        return cursor.rowcount == 1

    def has(self, key: tuple, experiment: str | None = None) -> bool:
        """Whether the evaluation with :data:`KEY` values ``key`` is stored (and, with ``experiment``, a member
        of it)."""
        where = " AND ".join(f"e.{k} = ?" for k in KEY)
        query = f"SELECT 1 FROM evaluations e WHERE {where}"
        if experiment is not None:
            query = (f"SELECT 1 FROM evaluations e JOIN memberships m ON m.evaluation = e.id "
                     f"WHERE {where} AND m.experiment = ?")
        with self._connect() as db:
            return db.execute(query, [*key, *([experiment] if experiment is not None else [])]).fetchone() is not None

    def add(self, row: dict, experiments: Iterable[str] = ()) -> bool:
        """Insert the evaluation ``row`` as a member of ``experiments``; False (the evaluation unchanged, the
        memberships added) when one with its KEY is there already (another experiment or sweep evaluated the same
        thing first: the evaluations are seeded, so it holds the same numbers)."""
        row = dict(row, created=row.get("created", time.time()))
        if isinstance(row.get("config"), dict):
            row["config"] = json.dumps(row["config"], sort_keys=True)
        with self._connect() as db:
            return self._insert(db, row, experiments)

    def link(self, key: tuple, experiment: str) -> None:
        """Make the stored evaluation ``key`` a member of ``experiment`` (no evaluation is computed again)."""
        where = " AND ".join(f"{k} = ?" for k in KEY)
        with self._connect() as db:
            db.execute(f"INSERT OR IGNORE INTO memberships (experiment, evaluation) "
                       f"SELECT ?, id FROM evaluations WHERE {where}", [experiment, *key])

    def rows(self, experiment: str | None = None) -> list[dict]:
        """The evaluations, each with ``experiments`` (its memberships, space-separated, sorted); with
        ``experiment``, those of that experiment, each with ``experiment`` set to it."""
        order = " ORDER BY e.run_name, e.nfe, e.sampler, e.execution, e.multi_task, e.step"
        with self._connect() as db:
            db.row_factory = sqlite3.Row
            if experiment is not None:
                return [dict(r) for r in db.execute(
                    "SELECT m.experiment AS experiment, e.* FROM evaluations e JOIN memberships m "
                    f"ON m.evaluation = e.id WHERE m.experiment = ?{order}", [experiment])]
            return [dict(r) for r in db.execute(
                "SELECT e.*, (SELECT group_concat(experiment, ' ') FROM (SELECT experiment FROM memberships "
                "WHERE evaluation = e.id ORDER BY experiment)) AS experiments FROM evaluations e ORDER BY e.id")]

    def experiments(self) -> list[str]:
        with self._connect() as db:
            return [r[0] for r in db.execute("SELECT DISTINCT experiment FROM memberships ORDER BY experiment")]

    def export_csv(self, path: Path) -> int:
        """Every evaluation, in the order it was stored: ``id``, ``experiments``, then :data:`COLUMNS`."""
        rows = self.rows()
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=["id", "experiments", *COLUMNS], lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        atomic_write_text(Path(path), buf.getvalue())
        return len(rows)

    def import_rows(self, rows: list[tuple[dict, list[str]]]) -> tuple[int, int]:
        """Rows of a results CSV (:func:`read_csv_rows`) into the store, in one transaction, nothing recomputed; an
        evaluation already stored keeps its numbers and gains the row's experiments. Returns (evaluations given,
        evaluations new)."""
        with self._connect() as db:
            new = sum(self._insert(db, row, experiments) for row, experiments in rows)
        return len({key_of(r) for r, _ in rows}), new


def row_from_eval_json(d: dict, split: str = "test") -> dict:
    """The store row of an evaluation JSON (``EvalResult.to_dict``, what ``bridgeplan eval --json`` writes) made on
    ``split``'s episodes: the run named as its config names it, the sampling tag from the process as sampled and the
    correction, the execution's tag from its settings."""
    from bridgeplan import config as cfg
    from bridgeplan.consistency import Correction, sampling_tag
    from bridgeplan.processes import process_from_dict
    from bridgeplan.replan import Execution

    check_choice("split", split, SPLITS)
    config = cfg.from_dict(cfg.TrainConfig, d["config"])
    c = d.get("correction")
    correction = None if not c else Correction(tuple(sorted(c["steps"].items())), form=c["form"])
    latency = d.get("decision_ms_batch1") or {}
    residuals = d.get("plan_residuals") or {}
    score = d["score"]
    return {
        "run_name": config.run_name(), "dataset": d.get("dataset") or None, "maze": d["maze"],
        "process": d["process"], "prior": d["prior"], "diffusion_steps": d["diffusion_steps"], "seed": config.seed,
        "step": d["step"],
        "train_seconds": d.get("train_seconds"), "nfe": d["nfe"], "episodes": d["episodes"], "eval_seed": d["seed"],
        "split": split, "score_minari": score["minari"]["mean"], "score_minari_se": score["minari"]["se"],
        "score_d4rl": score["d4rl"]["mean"], "score_d4rl_se": score["d4rl"]["se"],
        "success_rate": d["success_rate"]["mean"], "plan_ms": d["plan_ms_per_plan"], "prior_ms": d["prior_ms_per_plan"],
        "floor_minari": d["floor_line"]["score"]["minari"]["mean"],
        "sampler": sampling_tag(process_from_dict(d["process_params"]).sampling_tag(), correction),
        "execution": Execution.from_dict(d.get("execution")).tag(), "multi_task": int(d["multi_task"]),
        "calls_per_episode": d.get("calls_per_episode"), "decision_ms_p50": latency.get("p50"),
        "decision_ms_p95": latency.get("p95"),
        "network_calls_per_plan": d.get("network_call_equivalents_per_plan"),
        "plan_kinematics_rms": residuals.get("kinematics_rms", {}).get("mean"),
        "plan_dynamics_rms": residuals.get("dynamics_rms", {}).get("mean"),
        "config": d["config"], "code_version": d["environment"]["code_version"],
    }


def read_eval_json_rows(paths: Iterable[Path], experiment: str) -> list[tuple[dict, list[str]]]:
    """Evaluation JSONs as rows of ``experiment`` (its split from its name), as :func:`read_csv_rows` gives them."""
    out = []
    for path in paths:
        try:
            row = row_from_eval_json(json.loads(Path(path).read_text()), split_of(experiment))
        except OSError as e:
            raise BridgeplanError(f"cannot read evaluation JSON {path}: {e.strerror}") from None
        except (KeyError, TypeError, ValueError) as e:
            raise BridgeplanError(f"{path}: not an evaluation JSON ({type(e).__name__}: {e})") from None
        row["config"] = json.dumps(row["config"], sort_keys=True)
        out.append((row, [experiment]))
    return out


_INTEGER = {k for k, v in COLUMNS.items() if v.startswith("INTEGER")}
_REAL = {k for k, v in COLUMNS.items() if v.startswith("REAL")}


def read_csv_rows(path: Path) -> list[tuple[dict, list[str]]]:
    """Each row of a results CSV (any schema) as (store row, its experiments), in the file's order. An older CSV
    without a ``sampler`` column gets the sampling tag of the process in its config, as the analysis reads it."""
    from bridgeplan.processes import process_from_dict

    path = Path(path)
    out = []
    try:
        with path.open(newline="") as f:
            for i, r in enumerate(csv.DictReader(f)):
                where = f"{path} row {r.get('id') or i + 1}"
                if "experiments" in r:
                    experiments = (r["experiments"] or "").split()
                elif "experiment" in r:
                    experiments = [r["experiment"]]
                else:
                    raise BridgeplanError(f"{where}: not a results CSV (no experiment or experiments column)")
                row = {}
                for k in COLUMNS:
                    value = r.get(k)
                    if value is None:
                        continue
                    if k in _INTEGER:
                        value = int(value)
                    elif k in _REAL:
                        value = float(value) if value != "" else None
                    row[k] = value
                if "split" not in r:
                    row["split"] = split_of(experiments[0])
                if "sampler" not in r:
                    row["sampler"] = process_from_dict(json.loads(r["config"])["process"]).sampling_tag()
                if row["split"] not in SPLITS:
                    raise BridgeplanError(f"{where}: split {row['split']!r}: choose from {', '.join(SPLITS)}")
                missing = [k for k in KEY if k not in row and k not in ("sampler", "execution", "multi_task")]
                if missing:
                    raise BridgeplanError(f"{where}: no {missing[0]} column")
                row.setdefault("execution", "")
                row.setdefault("multi_task", 0)
                out.append((row, experiments))
    except OSError as e:
        raise BridgeplanError(f"cannot read results CSV {path}: {e.strerror}") from None
    except (KeyError, ValueError, json.JSONDecodeError) as e:
        raise BridgeplanError(f"{path}: not a results CSV ({type(e).__name__}: {e})") from None
    return out
