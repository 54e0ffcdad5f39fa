"""The results store: one SQLite row per evaluation, safe for concurrent sweeps.

WAL journaling and a busy timeout let two sweeps write at once; every insert is one transaction,
so an interrupted sweep keeps everything it finished. ``PRAGMA user_version`` holds the schema
version: a database from a newer bridgeplan is refused, untouched; one from an older one is upgraded in
place, in one transaction (version 1 had no execution or multi-task columns: its rows were open loop,
single-task; version 2 had no sampler column: its rows were sampled as their processes are by default; version 3
had no plan-cost columns: ``network_calls_per_plan`` and the plans' residuals are empty there).
"""

from __future__ import annotations

import csv
import io
import json
import sqlite3
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_text

SCHEMA_VERSION = 4

COLUMNS = {
    "experiment": "TEXT NOT NULL",
    "run_name": "TEXT NOT NULL",
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
KEY = ("experiment", "run_name", "step", "nfe", "sampler", "execution", "multi_task", "episodes", "eval_seed")
"""What makes an evaluation: ``sampler`` is ``consistency.sampling_tag``: ``Process.sampling_tag()`` ('' as the
process samples by default) and the consistency correction's tag, if any;
``execution`` is ``replan.Execution.tag()`` ('' for open loop), ``multi_task`` 0/1."""


def _table_columns() -> str:
    cols = ", ".join(f"{k} {v}" for k, v in COLUMNS.items())
    return f"id INTEGER PRIMARY KEY, {cols}, UNIQUE ({', '.join(KEY)})"


class ResultsStore:
    """The store file (``layout.store_path(results_dir)``); rows come from ``EvalResult.to_row``."""

    def __init__(self, path: Path):
        self.path = Path(path)
        if self.path.exists():
            self._check_version()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self._connect() as db:
            db.execute("PRAGMA journal_mode=WAL")
        with self._connect() as db:
            db.execute("BEGIN IMMEDIATE")  # one writer creates or upgrades; a second sweep waits, then sees it done
            version = db.execute("PRAGMA user_version").fetchone()[0]
            exists = db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'results'").fetchone()
            if exists and version < SCHEMA_VERSION:  # the old table's rows into today's, keyed by today's KEY
                db.execute("ALTER TABLE results RENAME TO results_old")
                db.execute(f"CREATE TABLE results ({_table_columns()})")
                old = [r[1] for r in db.execute("PRAGMA table_info(results_old)") if r[1] in COLUMNS]
                db.execute(f"INSERT INTO results ({', '.join(old)}) SELECT {', '.join(old)} FROM results_old")
                db.execute("DROP TABLE results_old")
            db.execute(f"CREATE TABLE IF NOT EXISTS results ({_table_columns()})")
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

    def _check_version(self) -> None:
        with self._connect(read_only=True) as db:
            # before anything is written to it: a damaged page would otherwise show up mid-sweep
            problems = [" ".join(r[0].split()) for r in db.execute("PRAGMA quick_check")]
            version = db.execute("PRAGMA user_version").fetchone()[0]
        if problems != ["ok"]:
            raise BridgeplanError(f"results store {self.path} is corrupted ({problems[0]}); left as it is")
        if version > SCHEMA_VERSION:
            raise BridgeplanError(f"{self.path} has schema version {version}, newer than this bridgeplan "
                                  f"understands ({SCHEMA_VERSION}); upgrade bridgeplan")

    def has(self, **key) -> bool:
        where = " AND ".join(f"{k} = ?" for k in KEY)
        with self._connect() as db:
            return db.execute(f"SELECT 1 FROM results WHERE {where}", [key[k] for k in KEY]).fetchone() is not None

    def add(self, row: dict) -> bool:
        """Insert ``row``; False (and the store unchanged) when a row with its KEY is there already (another
        sweep evaluated the same thing first: the evaluations are seeded, so it holds the same numbers)."""
        row = dict(row, created=row.get("created", time.time()))
        if isinstance(row.get("config"), dict):
            row["config"] = json.dumps(row["config"], sort_keys=True)
        names = [k for k in COLUMNS if k in row]
        with self._connect() as db:
            cursor = db.execute(f"INSERT OR IGNORE INTO results ({', '.join(names)}) "
                                f"VALUES ({', '.join('?' * len(names))})", [row[k] for k in names])
            return cursor.rowcount == 1

    def rows(self, experiment: str | None = None) -> list[dict]:
        with self._connect() as db:
            db.row_factory = sqlite3.Row
            query = "SELECT * FROM results" + (" WHERE experiment = ?" if experiment else "")
            query += " ORDER BY experiment, run_name, nfe, sampler, execution, multi_task, step"
            return [dict(r) for r in db.execute(query, [experiment] if experiment else [])]

    def experiments(self) -> list[str]:
        with self._connect() as db:
            return [r[0] for r in db.execute("SELECT DISTINCT experiment FROM results ORDER BY experiment")]

    def export_csv(self, path: Path) -> int:
        rows = self.rows()
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=["id", *COLUMNS])
        writer.writeheader()
        writer.writerows(rows)
        atomic_write_text(Path(path), buf.getvalue())
        return len(rows)
