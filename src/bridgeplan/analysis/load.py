"""Committed results into one row form: :class:`Row` (one evaluation of one training seed's snapshot) with its
:class:`~bridgeplan.analysis.keys.MethodKey`, and :class:`Results`, rows indexed by key, split, step, NFE and seed.

Sources:

- the stores' CSVs (``bridgeplan report --csv``): today's (one row per evaluation, with its ``split`` and its
  ``experiments``) and the older ones, one row per experiment and evaluation (``experiment``): version 1 (no
  ``execution``, ``multi_task``, ``calls_per_episode`` or decision-latency columns: open loop, single-task, one call
  per NFE), version 2 (those columns) and version 2 with a ``sampler`` column (the sampling tag; without it the
  config's process says how it was sampled). The method comes from the row's ``config`` JSON (the run's
  ``TrainConfig``), checked against the ``process``, ``prior`` and ``diffusion_steps`` columns; the execution
  from its tag;
- evaluation JSONs (``bridgeplan eval --json``): the same fields, the method from ``process_params`` and
  ``config``, the execution from its settings.

In the older CSVs, a row whose experiment ends in ``-validation`` was made on the validation episodes (split
``validation``), any other on the test episodes (``test``).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from bridgeplan.analysis.keys import MethodKey, key_of, parse_execution
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.experiments.store import SPLITS, split_of
from bridgeplan.processes import process_from_dict
from bridgeplan.replan import Execution


@dataclass(frozen=True)
class Row:
    """One evaluation: a training seed's snapshot, one NFE, one execution, one task set, many episodes."""

    key: MethodKey
    split: str
    """``test`` or ``validation`` (which evaluation episodes)."""
    seed: int
    """The training seed."""
    step: int
    """The snapshot's training step."""
    nfe: int
    score: float
    """Minari score, mean over the episodes."""
    score_se: float
    """Its standard error over the episodes."""
    floor: float
    """The straight line, tracked alone, on the same episodes (Minari score)."""
    success: float
    calls: float
    """Network calls per episode."""
    plan_ms: float
    """Milliseconds per plan, planned in one batch with the other episodes."""
    decision_ms: tuple[float, float] | None = None
    """Closed loop: a decision's p50 and p95 milliseconds at batch 1 (None open loop)."""
    maze: str = ""
    experiment: str = ""
    """The experiments that show the evaluation (space-separated)."""
    run_name: str = ""
    episodes: int = 0
    eval_seed: int = 0
    code_version: str = ""
    score_d4rl: float | None = None
    network_calls: float | None = None
    """Network-call equivalents per plan (NFE, plus 2 per backward pass of a deep correction); None in rows made
    before the store recorded it."""
    plan_kinematics: float | None = None
    """RMS kinematics residual of the plans as sampled (m/s), open loop; None where not recorded."""
    plan_dynamics: float | None = None
    """RMS dynamics residual of the plans as sampled (m/s), open loop; None where not recorded."""
    floor_learned: float | None = None
    """The learned prior tracked alone on the same episodes, where the evaluation measured it."""
    train_seconds: float | None = None
    """Wall-clock seconds the run had trained when the snapshot was taken; None where not recorded."""
    source: str = ""
    """The file the row was read from."""


class _Keys:
    """Memo of config JSON -> method key parts (thousands of rows share a few configs)."""

    def __init__(self):
        self._memo: dict[str, tuple] = {}

    def trained(self, config_text: str):
        if config_text not in self._memo:
            config = json.loads(config_text)
            self._memo[config_text] = (process_from_dict(config["process"]), config.get("prior", "gaussian"),
                                       float(config.get("hold_share") or 0.0))
        return self._memo[config_text]


def _float(text: str | None) -> float | None:
    return float(text) if text not in (None, "") else None


def row_from_csv(r: dict, keys: _Keys | None = None, source: str = "") -> Row:
    """One CSV row (``csv.DictReader``'s dict, any of the three schemas) as a :class:`Row`."""
    where = f"{source or 'results CSV'} row {r.get('id', '?')}"
    try:
        process, prior, hold = (keys or _Keys()).trained(r["config"])
        checks = [("process", process.name), ("prior", prior), ("diffusion_steps", str(process.steps))]
        for column, value in checks:
            if column in r and r[column] != value:
                raise BridgeplanError(f"{where}: column {column} is {r[column]!r}, its config says {value!r}")
        sampler = r["sampler"] if "sampler" in r else None  # None: the config's process's sampling tag
        execution = parse_execution(r.get("execution") or "")
        key = key_of(process, prior, hold_share=hold, sampler=sampler, execution=execution,
                     multi_task=bool(int(r.get("multi_task") or 0)))
        p50, p95 = _float(r.get("decision_ms_p50")), _float(r.get("decision_ms_p95"))
        experiment = r["experiments"] if "experiments" in r else r["experiment"]
        split = r["split"] if "split" in r else split_of(experiment)
        return Row(key=key, split=split, seed=int(r["seed"]), step=int(r["step"]),
                   nfe=int(r["nfe"]), score=float(r["score_minari"]), score_se=float(r["score_minari_se"]),
                   floor=float(r["floor_minari"]), success=float(r["success_rate"]),
                   calls=float(r.get("calls_per_episode") or r["nfe"]), plan_ms=float(r["plan_ms"]),
                   decision_ms=(p50, p95) if p50 is not None else None, maze=r["maze"], experiment=experiment,
                   run_name=r["run_name"], episodes=int(r["episodes"]), eval_seed=int(r["eval_seed"]),
                   code_version=r.get("code_version", ""), score_d4rl=_float(r.get("score_d4rl")),
                   network_calls=_float(r.get("network_calls_per_plan")),
                   plan_kinematics=_float(r.get("plan_kinematics_rms")),
                   plan_dynamics=_float(r.get("plan_dynamics_rms")),
                   train_seconds=_float(r.get("train_seconds")), source=source)
    except BridgeplanError as e:
        raise BridgeplanError(str(e) if str(e).startswith(where) else f"{where}: {e}") from None
    except (KeyError, ValueError, json.JSONDecodeError) as e:
        raise BridgeplanError(f"{where}: {type(e).__name__}: {e}") from None


def exported_rows(root: str | Path, folders) -> list[tuple[str, list[Row]]]:
    """``(folder, its rows)`` for each of ``folders`` under ``root`` (docs/results) with an exported results.csv, in
    their order; a study not exported yet is left out."""
    paths = [(folder, Path(root) / folder / "results.csv") for folder in folders]
    return [(folder, read_csv(path)) for folder, path in paths if path.exists()]


def read_csv(path: str | Path) -> list[Row]:
    """Every row of a results CSV, in the file's order."""
    path = Path(path)
    if not path.exists():
        raise BridgeplanError(f"no results CSV at {path}")
    keys = _Keys()
    with path.open(newline="") as f:
        return [row_from_csv(r, keys, str(path)) for r in csv.DictReader(f)]


def read_eval_json(path: str | Path, experiment: str = "") -> Row:
    """One evaluation JSON (``bridgeplan eval --json``) as a :class:`Row` (``experiment`` names its split)."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
        config = d.get("config") or {}
        process = process_from_dict(d["process_params"])
        key = key_of(process, d["prior"], hold_share=float(config.get("hold_share") or 0.0),
                     execution=Execution.from_dict(d.get("execution")), multi_task=bool(d.get("multi_task")))
        latency = d.get("decision_ms_batch1")
        learned = d.get("prior_only_learned")
        residuals = d.get("plan_residuals") or {}
        # the training seed is the run's (the JSON's seed is its evaluation's: the same only by the test split's rule)
        return Row(key=key, split=split_of(experiment), seed=int(config.get("seed", d["seed"])), step=int(d["step"]),
                   nfe=int(d["nfe"]), eval_seed=int(d["seed"]),
                   score=float(d["score"]["minari"]["mean"]), score_se=float(d["score"]["minari"]["se"]),
                   floor=float(d["floor_line"]["score"]["minari"]["mean"]) if d.get("floor_line") else float("nan"),
                   success=float(d["success_rate"]["mean"]), calls=float(d.get("calls_per_episode", d["nfe"])),
                   plan_ms=float(d.get("plan_ms_per_plan", "nan")),
                   decision_ms=(float(latency["p50"]), float(latency["p95"])) if latency else None,
                   maze=d.get("maze", ""), experiment=experiment, run_name=Path(d.get("run", "")).name,
                   episodes=int(d.get("episodes", 0)), code_version=d.get("environment", {}).get("code_version", ""),
                   score_d4rl=float(d["score"]["d4rl"]["mean"]) if "d4rl" in d["score"] else None,
                   floor_learned=float(learned["score"]["minari"]["mean"]) if learned else None,
                   network_calls=_float(d.get("network_call_equivalents_per_plan")),
                   plan_kinematics=residuals.get("kinematics_rms", {}).get("mean"),
                   plan_dynamics=residuals.get("dynamics_rms", {}).get("mean"),
                   train_seconds=_float(d.get("train_seconds")), source=str(path))
    except (KeyError, ValueError, TypeError, json.JSONDecodeError) as e:
        raise BridgeplanError(f"{path}: not an evaluation JSON ({type(e).__name__}: {e})") from None


def read_evaluation(path: str | Path) -> dict:
    """Any command's evaluation JSON as one flat dict (the form a family's success rows are read in): an
    :class:`~bridgeplan.evaluate.EvalResult`'s (``eval``, of a planner or a policy, ``hierarchy eval``, ``graph``),
    the one row of an ``oracle`` file, or an earlier ``gcbc eval``'s; its ``code_version`` at the top whichever."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise BridgeplanError(f"{path}: not an evaluation JSON ({type(e).__name__}: {e})") from None
    if "rows" in d:  # the oracle's file: its rows and the code that made them
        if len(d["rows"]) != 1:
            raise BridgeplanError(f"{path}: {len(d['rows'])} oracle rows, a study's evaluation has one")
        d = {**d["rows"][0], "code_version": d["code_version"]}
    return {"code_version": d.get("environment", {}).get("code_version"), **d}


@dataclass(frozen=True)
class Point:
    """Where a series of per-seed evaluations sits: a method, a snapshot step and an NFE."""

    key: MethodKey
    step: int
    nfe: int


class Results:
    """Rows indexed by (key, split) -> step -> NFE -> seed. When several rows share all five (the same
    evaluation made for several experiments, or a run retrained in a later store), the first one given is
    kept: give the stores in their order of precedence."""

    def __init__(self, rows: Iterable[Row] = ()):
        self._index: dict[tuple[MethodKey, str], dict[int, dict[int, dict[int, Row]]]] = {}
        for row in rows:
            self.add(row)

    def add(self, row: Row) -> bool:
        """Index ``row``; False (and nothing changes) when a row with its key, split, step, NFE and seed is in."""
        check_choice("split", row.split, SPLITS)
        by_seed = self._index.setdefault((row.key, row.split), {}).setdefault(row.step, {}).setdefault(row.nfe, {})
        if row.seed in by_seed:
            return False
        by_seed[row.seed] = row
        return True

    def keys(self, split: str = "test") -> list[MethodKey]:
        """The methods with rows in ``split``, in the order they were first given."""
        return [key for key, s in self._index if s == split]

    def steps(self, key: MethodKey, split: str = "test") -> list[int]:
        """The snapshot steps of ``key`` in ``split``, ascending."""
        return sorted(self._index.get((key, split), {}))

    def nfes(self, key: MethodKey, step: int, split: str = "test") -> list[int]:
        """The NFEs evaluated for ``key`` at ``step``, in the order they were first given."""
        return list(self._index.get((key, split), {}).get(step, {}))

    def points(self, key: MethodKey, step: int, split: str = "test") -> list[Point]:
        return [Point(key, step, nfe) for nfe in self.nfes(key, step, split)]

    def rows(self, point: Point, split: str = "test") -> dict[int, Row]:
        """``{seed: Row}`` at ``point`` ({} when nothing was evaluated there)."""
        return dict(self._index.get((point.key, split), {}).get(point.step, {}).get(point.nfe, {}))

    def values(self, point: Point, split: str = "test", field: str = "score") -> dict[int, float]:
        """``{seed: value}`` of a :class:`Row` field (``score``, ``floor``, ``success``, ...) at ``point``."""
        return {seed: getattr(row, field) for seed, row in self.rows(point, split).items()}

    def __iter__(self):
        for (_, _), by_step in self._index.items():
            for by_nfe in by_step.values():
                for by_seed in by_nfe.values():
                    yield from by_seed.values()

    def __len__(self) -> int:
        return sum(1 for _ in self)


def load_csvs(paths: Iterable[str | Path], missing_ok: bool = True, experiments: set[str] | None = None) -> Results:
    """The rows of several CSVs in one :class:`Results`, earlier files first (precedence); a file that does not
    exist is skipped when ``missing_ok``; with ``experiments``, only the rows these experiments show."""
    rows: list[Row] = []
    for path in map(Path, paths):
        if missing_ok and not path.exists():
            continue
        rows += [r for r in read_csv(path) if experiments is None or experiments & set(r.experiment.split())]
    return Results(rows)
