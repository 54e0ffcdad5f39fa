"""Study files (``studies/NAME.toml``) parsed into frozen dataclasses, every key checked.

A study is one campaign: a maze, a dataset, how its runs are trained, the experiments it evaluates (a grid of
:mod:`bridgeplan.experiments.grids` with the process compared with DDPM, or series of declared methods), and the
reports it makes. A study may read the results of others (``uses``) instead of training anything itself.

Example (the keys and their defaults: the dataclasses below)::

    name = "medium-v2-curves"            # default: the file's stem
    title = "medium, data version 2: DDPM, the bridges and flow matching across training"
    uses = []                            # other studies (names) whose results its reports read
    data = "medium-v2-curves"            # committed results folder under docs/results (results.csv, report.md)

    [dataset]
    maze = "medium"
    steps = 1_000_000                    # transitions `bridgeplan data generate` makes
    seed = 123
    # piece_steps = 200                  # as independent pieces of 200 steps (a stitching dataset)
    version = 2                          # the generator's data version (bridgeplan.envs.maze2d.generate.DATA_VERSION)
    # generator = "ogbench"              # OGBench's recipe instead; maze = "pointmaze-medium-navigate-v0"

    [training]
    preset = "cpu-small"
    steps = 8000                         # optimizer steps per run (the last stage's)
    checkpoint_every = 2000              # snapshot (evaluation) interval
    prior_steps = 2000                   # the learned prior's optimizer steps
    seeds = [0, 1, 2]
    diffusion_steps = 16
    stages = []                          # earlier [steps, checkpoint_every] passes the runs were trained in
    # any other TrainConfig field (batch_size, lr, horizon, stride, hold_share, model = {dim = 8}, ...)

    [evaluation]
    episodes = 200
    workers = 2

    [[experiments]]                      # a thesis grid, with the process compared with DDPM
    grid = "nfe-curves"
    process = "bridge"
    params = { consistent = true }       # that process's parameters
    splits = ["test", "validation"]      # validation: each run's final snapshot on other tasks
    seeds = [0]                          # default: the training seeds
    hold_share = 0.5                     # training windows that wait (default: [training]'s)

    [methods.bridge-line]                # a declared method, for series of one's own
    process = "bridge"
    prior = "line"

    [[experiments]]
    name = "mine"
    last_snapshot_only = true
    series = [{ method = "bridge-line", nfe = [1, 2], controller = "pursuit", lookahead = 1.0,
                replan_every = 32, warm = true, multi_task = [false, true], sampler = "mean" }]
    series = [{ method = "bridge-line", nfe = [1, 2], correction = ["none", "dynamics=1e-4"],
                correction_form = "x0" }]  # consistency corrections (CDDB) of x0 (default) or deep form

    [runs.high-ddpm-k12]                 # a named run, for evaluations that are one command each
    process = "ddpm"                     # (bridgeplan.studies.jobs: eval, hierarchy eval, graph,
    horizon = 32                         #  each writing one JSON, exported to docs/results; prior = "learned"
    stride = 12                          #  trains its prior first, for prior_steps)

    [runs.gcbc]                          # trainer = "gcbc": `gcbc train`'s run (GCBCConfig fields)
    trainer = "gcbc"
    maze = "medium"

    [[evaluations]]
    command = "eval"                     # or hierarchy eval, graph, oracle (any environment's)
    runs = ["high-ddpm-k12"]
    args = { nfe = 16, replan_every = 48, controller = "pursuit", lookahead = 1.5 }
    out = "large-hierarchy-flat/high-ddpm-k12-nfe16-replan48/{tasks}-seed{eval_seed}.json"
    splits = ["test", "validation"]
    task_sets = ["single", "multi"]

    [[reports]]
    generator = "findings"               # the repository's studies/reports (bridgeplan.studies.generators)
    output = "findings.md"               # relative to docs/results

Any other key, an unknown grid, process, parameter, method, sampler or generator, or a report whose generator
reads a method that neither the study nor the studies it uses train: one ``error: FILE: KEY: ...`` line.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridgeplan.errors import BridgeplanError
from bridgeplan.eval_commands import STUDY_COMMANDS, plan_options
from bridgeplan.options import options_from_dict

SPLITS = ("test", "validation")
EXECUTION_FIELDS = ("controller", "lookahead", "replan_every", "warm", "arrival", "tolerance", "candidates", "select")


class StudyError(BridgeplanError):
    """A bad study file: the message names the file and the key."""

    def __init__(self, file: Path | str, key: str, message: str):
        super().__init__(f"{file}: {key}: {message}")


@dataclass(frozen=True)
class Dataset:
    maze: str
    steps: int = 1_000_000
    """Transitions of the generated dataset (`bridgeplan data generate --steps`)."""
    seed: int = 123
    generator: str = ""
    """The maze's family's recipe (``Family.generator``; '' says so too): ``expert``, Maze2D's noisy expert stream
    (`bridgeplan data generate`, Minari's D4RL recipe); ``ogbench``, OGBench's recipe (``maze`` is then the
    dataset's name, e.g. ``pointmaze-medium-navigate-v0``, its size the recipe's)."""
    version: int = 2
    """The data version the generator must have, where the family's data has versions
    (``bridgeplan.envs.maze2d.generate.DATA_VERSION``)."""
    piece_steps: int = 0
    """The expert's data as independent pieces of this many steps (`data generate --piece-steps`; 0: one stream)."""
    path: str = ""
    """Dataset directory (or file), relative to the repository root; default the family's
    (``Family.default_dataset``: ``datasets/<maze>-<steps>-v<version>``, ``datasets/ogbench/<name>.npz``; ``datasets``
    being ``$BRIDGEPLAN_DATASETS`` where set), generated there when absent, as the campaigns did."""

    @property
    def family(self):
        from bridgeplan.envs import family_of

        return family_of(self.maze)

    def directory(self) -> str:
        return self.path or self.family.default_dataset(self.maze, self.steps, self.piece_steps, self.version)


@dataclass(frozen=True)
class Training:
    preset: str = "cpu-small"
    steps: int = 3000
    """Optimizer steps per planner run (the final stage's)."""
    checkpoint_every: int = 500
    prior_steps: int = 2000
    seeds: tuple[int, ...] = (0,)
    diffusion_steps: int = 16
    stages: tuple[tuple[int, int], ...] = ()
    """Earlier passes ``(steps, checkpoint_every)``: the runs were trained to ``steps`` first, snapshotting every
    ``checkpoint_every``, then resumed to :attr:`steps` (the committed snapshot steps come from that history)."""
    overrides: tuple[tuple[str, Any], ...] = ()
    """Other TrainConfig fields, sorted by name."""

    def all_stages(self) -> tuple[tuple[int, int], ...]:
        return (*self.stages, (self.steps, self.checkpoint_every))


VALIDATIONS = ("other-tasks", "test-tasks-reseeded")


@dataclass(frozen=True)
class Evaluation:
    episodes: int | None = None
    """Episodes per task (None: the environment family's, Maze2D 200 in all, OGBench 50 per task)."""
    workers: int = 1
    """Parallel jobs of the local backend (cores divided among them)."""
    validation: str = "other-tasks"
    """What the validation split evaluates in a family with validation tasks of its own (``Family.validation_tasks``:
    OGBench's, ``protocol.validation_tasks``, other cells than the test tasks'): ``other-tasks``, those;
    ``test-tasks-reseeded``, the test tasks themselves with other noise (the training seed + 1000), the draw the
    studies made before them, which they pin so that their committed rows keep reproducing. A family without them
    draws its validation episodes by the seed alone."""


@dataclass(frozen=True)
class Method:
    """A declared method: a process with its parameters, from a prior."""

    name: str
    process: str
    prior: str = "gaussian"
    params: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class SeriesSpec:
    method: str
    nfe: tuple[int, ...]
    multi_task: tuple[bool, ...] = (False,)
    sampler: str | None = None
    execution: tuple[tuple[str, Any], ...] = ()
    """``replan.Execution`` fields (controller, lookahead, replan_every, warm, arrival, ...)."""
    correction: tuple[Any, ...] = (None,)
    """``consistency.Correction`` (None: uncorrected), one series each: ``correction = ["none", "dynamics=1e-4",
    "dynamics=1e-4,kinematics=1e-4"]`` (residuals of one correction joined by commas) at ``correction_form``."""


@dataclass(frozen=True)
class ExperimentSpec:
    name: str
    """The grid's name, or the declared experiment's (the store's ``experiment`` column)."""
    grid: str = ""
    """A thesis grid (``experiments.grids.EXPERIMENTS``); '' for declared series."""
    process: str = "bridge"
    """Grid: the process compared with DDPM from each prior."""
    params: tuple[tuple[str, Any], ...] = ()
    series: tuple[SeriesSpec, ...] = ()
    title: str = ""
    last_snapshot_only: bool = False
    splits: tuple[str, ...] = ("test",)
    seeds: tuple[int, ...] | None = None
    """Default: the training seeds."""
    hold_share: float | None = None
    """Default: the training's (``hold_share`` in [training], else 0)."""


@dataclass(frozen=True)
class ReportSpec:
    generator: str
    output: str
    """Relative to docs/results."""


@dataclass(frozen=True)
class Study:
    name: str
    file: Path
    title: str = ""
    data: str = ""
    """The committed results folder under docs/results (its results.csv); default the study's name."""
    uses: tuple[str, ...] = ()
    dataset: Dataset | None = None
    training: Training = Training()
    evaluation: Evaluation = Evaluation()
    methods: tuple[Method, ...] = ()
    experiments: tuple[ExperimentSpec, ...] = ()
    runs: tuple[NamedRun, ...] = ()
    """Named runs for :attr:`evaluations` (``studies.jobs``)."""
    evaluations: tuple[CommandEvaluation, ...] = ()
    """Evaluation JSONs, one command each (``studies.jobs``)."""
    reports: tuple[ReportSpec, ...] = ()

    @property
    def data_dir(self) -> str:
        return self.data or self.name

    @property
    def episodes(self) -> int:
        """Episodes per task of its evaluations: its [evaluation]'s, else its environment family's."""
        return self.evaluation.episodes or self.dataset.family.episodes


# --- parsing ----------------------------------------------------------------------------------------------------

def _table(file, key: str, value, allowed: set[str], required: tuple[str, ...] = ()) -> dict:
    if not isinstance(value, dict):
        raise StudyError(file, key, f"expected a table, got {type(value).__name__}")
    unknown = sorted(set(value) - allowed)
    if unknown:
        raise StudyError(file, f"{key}.{unknown[0]}" if key else unknown[0],
                         f"unknown key (known: {', '.join(sorted(allowed))})")
    for name in required:
        if name not in value:
            raise StudyError(file, f"{key}.{name}" if key else name, "required")
    return value


def _typed(file, key: str, value, kind, positive: bool = False):
    ok = isinstance(value, kind) and not (kind in (int, float) and isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value, ok = float(value), True
    if not ok:
        raise StudyError(file, key, f"expected {kind.__name__}, got {value!r}")
    if positive and value <= 0:
        raise StudyError(file, key, f"must be positive, got {value!r}")
    return value


def _ints(file, key: str, value, minimum: int = 0) -> tuple[int, ...]:
    if isinstance(value, int) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value or any(not isinstance(v, int) or isinstance(v, bool) or v < minimum
                                                        for v in value):
        raise StudyError(file, key, f"expected a non-empty list of integers >= {minimum}, got {value!r}")
    return tuple(value)


def _dataclass_fields(cls, value: dict, file, key: str) -> dict:
    """``value``'s keys that ``cls`` has, type-checked against the defaults' types."""
    out = {}
    for f in dataclasses.fields(cls):
        if f.name in value:
            default = f.default if f.default is not dataclasses.MISSING else None
            kind = (type(default) if isinstance(default, (int, float, str, bool)) else
                    int if str(f.type).startswith("int") else str)
            out[f.name] = _typed(file, f"{key}.{f.name}", value[f.name], kind, positive=kind in (int,) and
                                 f.name in ("steps", "episodes", "workers", "checkpoint_every", "prior_steps",
                                            "diffusion_steps", "piece_steps"))
    return out


def _process_params(file, key: str, process: str, params) -> tuple[tuple[str, Any], ...]:
    from bridgeplan.processes import PROCESSES, make_process

    if process not in PROCESSES:
        raise StudyError(file, key, f"unknown process {process!r} (choose from {', '.join(PROCESSES)})")
    params = _table(file, f"{key}.params", params or {}, set(params or {}))
    try:
        make_process(process, **params)
    except (BridgeplanError, TypeError, ValueError) as e:
        raise StudyError(file, f"{key}.params", str(e)) from None
    return tuple(sorted(params.items()))


def _frozen(value):
    """TOML lists as tuples (``dim_mults = [1, 2]``), inside tables too, as the configs hold them."""
    if isinstance(value, list):
        return tuple(_frozen(v) for v in value)
    if isinstance(value, dict):
        return {k: _frozen(v) for k, v in value.items()}
    return value


def _training(file, raw: dict) -> Training:
    from bridgeplan import config as cfg

    own = {f.name for f in dataclasses.fields(Training)} - {"overrides"}
    taken = {"maze", "dataset", "preset", "process", "prior", "prior_run", "steps", "checkpoint_every", "seed"}
    train_fields = {f.name for f in dataclasses.fields(cfg.TrainConfig)} - taken
    _table(file, "training", raw, own | train_fields)
    values = _dataclass_fields(Training, {k: v for k, v in raw.items() if k not in ("seeds", "stages")}, file,
                               "training")
    if "seeds" in raw:
        values["seeds"] = _ints(file, "training.seeds", raw["seeds"])
    if "stages" in raw:
        stages = raw["stages"]
        if not isinstance(stages, list) or any(not isinstance(s, list) or len(s) != 2 for s in stages):
            raise StudyError(file, "training.stages", f"expected a list of [steps, checkpoint_every], got {stages!r}")
        values["stages"] = tuple(tuple(_ints(file, "training.stages", s, minimum=1)) for s in stages)
    overrides = tuple(sorted((k, _frozen(v)) for k, v in raw.items() if k in train_fields))
    return Training(**values, overrides=overrides)


def _series(file, key: str, raw, methods: dict[str, Method]) -> SeriesSpec:
    raw = _table(file, key, raw, {"method", "nfe", "multi_task", "sampler", "correction", "correction_form",
                                  *EXECUTION_FIELDS}, ("method", "nfe"))
    if raw["method"] not in methods:
        raise StudyError(file, f"{key}.method", f"unknown method {raw['method']!r} (declared: "
                                                f"{', '.join(methods) or 'none'}; see [methods.NAME])")
    multi = raw.get("multi_task", [False])
    multi = [multi] if isinstance(multi, bool) else multi
    if not isinstance(multi, list) or not multi or any(not isinstance(m, bool) for m in multi):
        raise StudyError(file, f"{key}.multi_task", f"expected true, false or a list of them, got {multi!r}")
    sampler = raw.get("sampler")
    if sampler is not None:
        _typed(file, f"{key}.sampler", sampler, str)
    execution = tuple(sorted((k, v) for k, v in raw.items() if k in EXECUTION_FIELDS))
    from bridgeplan.replan import Execution

    try:
        Execution(**dict(execution))
    except (BridgeplanError, TypeError, ValueError) as e:
        raise StudyError(file, key, f"not an execution: {e}") from None
    return SeriesSpec(method=raw["method"], nfe=_ints(file, f"{key}.nfe", raw["nfe"], minimum=1),
                      multi_task=tuple(multi), sampler=sampler, execution=execution,
                      correction=_corrections(file, key, raw))


def _corrections(file, key: str, raw: dict) -> tuple:
    """A series' ``correction`` (a string or a list: "none", or ``RESIDUAL=STEP[,RESIDUAL=STEP...]``) at its
    ``correction_form`` (x0 or deep, default x0) as ``Correction``s, None for "none"."""
    from bridgeplan.consistency import FORMS, Correction

    form = raw.get("correction_form")
    if form is not None and (not isinstance(form, str) or form not in FORMS):
        raise StudyError(file, f"{key}.correction_form", f"expected one of {', '.join(FORMS)}, got {form!r}")
    if "correction" not in raw:
        if form is not None:
            raise StudyError(file, f"{key}.correction_form", "needs correction = [\"RESIDUAL=STEP\", ...]")
        return (None,)
    values = raw["correction"]
    values = [values] if isinstance(values, str) else values
    if not isinstance(values, list) or not values or any(not isinstance(v, str) for v in values):
        raise StudyError(file, f"{key}.correction", f"expected \"none\", \"RESIDUAL=STEP\" or a list of them, "
                                                    f"got {raw['correction']!r}")
    out = []
    for i, text in enumerate(values):
        try:
            out.append(None if text.strip() == "none" else
                       Correction.parse([part for part in text.split(",") if part.strip()], form or "x0"))
        except BridgeplanError as e:
            raise StudyError(file, f"{key}.correction[{i}]", str(e)) from None
    if len(set(out)) != len(out):
        raise StudyError(file, f"{key}.correction", f"a correction is listed twice: {values!r}")
    return tuple(out)


def _experiment(file, key: str, raw, methods: dict[str, Method]) -> ExperimentSpec:
    from bridgeplan.experiments.grids import EXPERIMENTS

    common = {"title", "last_snapshot_only", "splits", "seeds", "hold_share"}
    if not isinstance(raw, dict):
        raise StudyError(file, key, "expected a table")
    if "grid" in raw:
        raw = _table(file, key, raw, common | {"grid", "process", "params"})
        if raw["grid"] not in EXPERIMENTS:
            raise StudyError(file, f"{key}.grid",
                             f"unknown grid {raw['grid']!r} (choose from {', '.join(EXPERIMENTS)})")
        process = _typed(file, f"{key}.process", raw.get("process", "bridge"), str)
        values: dict[str, Any] = dict(name=raw["grid"], grid=raw["grid"], process=process,
                                      params=_process_params(file, key, process, raw.get("params")))
    else:
        raw = _table(file, key, raw, common | {"name", "series"}, ("name", "series"))
        series = raw["series"]
        if not isinstance(series, list) or not series:
            raise StudyError(file, f"{key}.series", "expected a non-empty list of series tables")
        values = dict(name=_typed(file, f"{key}.name", raw["name"], str),
                      series=tuple(_series(file, f"{key}.series[{i}]", s, methods) for i, s in enumerate(series)))
    if "title" in raw:
        values["title"] = _typed(file, f"{key}.title", raw["title"], str)
    if "last_snapshot_only" in raw:
        values["last_snapshot_only"] = _typed(file, f"{key}.last_snapshot_only", raw["last_snapshot_only"], bool)
    if "splits" in raw:
        splits = raw["splits"]
        if not isinstance(splits, list) or not splits or any(s not in SPLITS for s in splits):
            raise StudyError(file, f"{key}.splits", f"expected a list of {', '.join(SPLITS)}, got {splits!r}")
        values["splits"] = tuple(dict.fromkeys(splits))
    if "seeds" in raw:
        values["seeds"] = _ints(file, f"{key}.seeds", raw["seeds"])
    if "hold_share" in raw:
        values["hold_share"] = _typed(file, f"{key}.hold_share", raw["hold_share"], float)
    return ExperimentSpec(**values)


# --- evaluations of one command each (bridgeplan.studies.jobs runs them) -----------------------------------

TRAINERS = ("planner", "gcbc")
"""What trains a named run: ``bridgeplan train`` (a planner), or ``bridgeplan gcbc train`` (GCBC, the calibration
baseline)."""
SET_BY_THE_RUNNER = {"seed", "out", "multi_task", "threads", "json", "no_progress", "dataset"}
TASK_SETS = ("single", "multi")


@dataclass(frozen=True)
class NamedRun:
    name: str
    fields: tuple[tuple[str, Any], ...]
    """TrainConfig fields over the study's [training] (process: its name, with ``params``; prior, horizon, stride,
    subgoal_every, ...); a GCBC run's GCBCConfig fields (maze, log_every, batch_size, ...)."""
    trainer: str = "planner"
    """:data:`TRAINERS`: which command trains it."""


@dataclass(frozen=True)
class CommandEvaluation:
    command: str
    runs: tuple[str, ...]
    out: str
    """The JSON's path under the study's results directory and, exported, under docs/results; it may name ``{seed}``,
    ``{eval_seed}`` and ``{tasks}``; two training seeds, splits or evaluations writing one path is a study error."""
    args: tuple[tuple[str, Any], ...] = ()
    splits: tuple[str, ...] = ("test",)
    task_sets: tuple[str, ...] = ("single",)
    seeds: tuple[int, ...] | None = None
    """Default: the training seeds."""
    task_seed: int | None = None
    """The test episodes' seed, the same for every training seed (OGBench's protocol: its fixed tasks); validation
    adds 1000. None: the training seed's, as Maze2D's evaluations."""


def parse_runs(file, raw) -> tuple[NamedRun, ...]:
    from bridgeplan import config as cfg
    from bridgeplan.gcbc import GCBCConfig

    taken = {"dataset", "steps", "checkpoint_every", "seed"}
    allowed = {f.name for f in dataclasses.fields(cfg.TrainConfig)} - taken - {"maze", "preset", "prior_run"}
    gcbc_allowed = {f.name for f in dataclasses.fields(GCBCConfig)} - taken
    runs = []
    for name, fields in _table(file, "runs", raw, set(raw)).items():
        key = f"runs.{name}"
        trainer = fields.get("trainer", "planner") if isinstance(fields, dict) else "planner"
        if trainer not in TRAINERS:
            raise StudyError(file, f"{key}.trainer", f"unknown trainer {trainer!r} (choose from {', '.join(TRAINERS)})")
        if trainer == "gcbc":
            fields = dict(_table(file, key, fields, gcbc_allowed | {"trainer"}))
            runs.append(NamedRun(name, tuple(sorted((k, _frozen(v)) for k, v in fields.items() if k != "trainer")),
                                 trainer))
            continue
        fields = dict(_table(file, key, fields, allowed | {"params", "trainer"}, ("process",)))
        fields.pop("trainer", None)
        process = _typed(file, f"{key}.process", fields["process"], str)
        fields["params"] = _process_params(file, key, process, fields.get("params"))
        runs.append(NamedRun(name, tuple(sorted((k, _frozen(v)) for k, v in fields.items()))))
    return tuple(runs)


def parse_evaluations(file, raw, runs: tuple[NamedRun, ...]) -> tuple[CommandEvaluation, ...]:
    if not isinstance(raw, list):
        raise StudyError(file, "evaluations", "expected an array of tables ([[evaluations]])")
    trainers = {r.name: r.trainer for r in runs}
    out = []
    for i, e in enumerate(raw):
        key = f"evaluations[{i}]"
        e = _table(file, key, e, {"command", "runs", "out", "args", "splits", "task_sets", "seeds", "task_seed"},
                   ("command", "runs", "out"))
        command = _typed(file, f"{key}.command", e["command"], str)
        if command not in STUDY_COMMANDS:
            raise StudyError(file, f"{key}.command", f"unknown command {command!r} (choose from "
                                                     f"{', '.join(STUDY_COMMANDS)})")
        levels = e["runs"]
        runs_of = STUDY_COMMANDS[command].runs
        counts = (0, len(runs_of)) if STUDY_COMMANDS[command].optional_runs else (len(runs_of),)
        if (not isinstance(levels, list) or len(levels) not in counts
                or any(not isinstance(r, str) for r in levels)):
            raise StudyError(file, f"{key}.runs", f"{command} takes {' or '.join(map(str, counts))} run name(s), got "
                                                  f"{levels!r}")
        for r in levels:
            if r not in trainers:
                raise StudyError(file, f"{key}.runs", f"unknown run {r!r} (declared: "
                                                      f"{', '.join(sorted(trainers)) or 'none'}; see [runs.NAME])")
        args = _table(file, f"{key}.args", e.get("args", {}), set(e.get("args", {})))
        for name in sorted(set(args) & (SET_BY_THE_RUNNER | {STUDY_COMMANDS[command].seed, *runs_of})):
            raise StudyError(file, f"{key}.args.{name}", "set by the runner (the seed and split, the task set, the "
                                                          "output path, one thread, the runs)")
        splits = tuple(e.get("splits", ["test"]))
        if not splits or any(s not in SPLITS for s in splits):
            raise StudyError(file, f"{key}.splits", f"expected a list of {', '.join(SPLITS)}, got {e.get('splits')!r}")
        task_sets = tuple(e.get("task_sets", ["single"]))
        if not task_sets or any(t not in TASK_SETS for t in task_sets):
            raise StudyError(file, f"{key}.task_sets", f"expected a list of single, multi, got {e.get('task_sets')!r}")
        evaluation = CommandEvaluation(command, tuple(levels), _typed(file, f"{key}.out", e["out"], str),
                                       tuple(sorted(args.items())), splits, task_sets,
                                       _ints(file, f"{key}.seeds", e["seeds"]) if "seeds" in e else None,
                                       _ints(file, f"{key}.task_seed", e["task_seed"])[0] if "task_seed" in e else None)
        try:
            evaluation.out.format(seed=0, eval_seed=0, tasks="single")
        except (KeyError, IndexError, ValueError) as err:
            raise StudyError(file, f"{key}.out", f"names only {{seed}}, {{eval_seed}} and {{tasks}} ({err})") from None
        _check_flags(file, key, evaluation)
        if command == "eval" and trainers[levels[0]] == "gcbc":
            for name in sorted(set(args) & {leaf.name for leaf in plan_options()}):
                raise StudyError(file, f"{key}.args.{name}", f"run {levels[0]!r} is a GCBC/GCIQL policy: a plan's "
                                                              f"option does not apply")
        out.append(evaluation)
    return tuple(out)


def command_options(command: str, runs: list[str], args: tuple[tuple[str, Any], ...] | dict):
    """The options of ``command`` on ``runs`` (filling the options :data:`STUDY_COMMANDS` names) with ``args``; a
    bad one: :class:`BridgeplanError` naming it."""
    spec = STUDY_COMMANDS[command]
    return options_from_dict(spec.options, {**dict(args), **dict(zip(spec.runs, runs))},
                             unlisted=SET_BY_THE_RUNNER | {spec.seed, *spec.runs})


def _check_flags(file, key: str, evaluation: CommandEvaluation) -> None:
    """The command's options read ``args`` (an unknown option or a bad value: one error naming the key)."""
    try:
        command_options(evaluation.command, ["RUN"] * len(evaluation.runs), evaluation.args)
    except BridgeplanError as e:
        raise StudyError(file, f"{key}.args", str(e)) from None


def read_study(path: Path | str, shown: Path | str | None = None, generators: dict | None = None) -> Study:
    """The study in ``path`` (TOML), its format checked (``bridgeplan.studies.parse_study`` checks the rest);
    :class:`StudyError` names the file (as ``shown``, default ``path``) and the key of the first problem."""
    generators = generators or {}
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise BridgeplanError(f"cannot read study {path}: {e.strerror or e}") from None
    stem = Path(path).stem
    path = Path(shown or path)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise StudyError(path, "(encoding)", f"not UTF-8 text (TOML is): byte {e.start} is "
                                             f"{data[e.start:e.start + 1]!r}") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise StudyError(path, "(syntax)", str(e)) from None
    if not raw:
        raise StudyError(path, "(file)", "empty: a study declares what it trains and evaluates ([dataset], "
                                         "[[experiments]] or [[evaluations]]), or the studies it reads (uses) and "
                                         "its [[reports]]")
    top = {"name", "title", "data", "uses", "dataset", "training", "evaluation", "methods", "experiments", "runs",
           "evaluations", "reports"}
    _table(path, "", raw, top)
    name = _typed(path, "name", raw.get("name", stem), str)
    uses = raw.get("uses", [])
    if not isinstance(uses, list) or any(not isinstance(u, str) for u in uses):
        raise StudyError(path, "uses", f"expected a list of study names, got {uses!r}")
    dataset = None
    if "dataset" in raw:
        d = _table(path, "dataset", raw["dataset"], {f.name for f in dataclasses.fields(Dataset)}, ("maze",))
        dataset = Dataset(**_dataclass_fields(Dataset, d, path, "dataset"))
        try:
            family = dataset.family
        except BridgeplanError as e:
            raise StudyError(path, "dataset.maze", str(e)) from None
        if dataset.generator not in ("", family.generator):
            raise StudyError(path, "dataset.generator", f"{dataset.maze} is a {family.title} environment: its data "
                                                        f"is made by {family.generator!r}, not {dataset.generator!r}")
    training = _training(path, raw.get("training", {}))
    fields = {f.name for f in dataclasses.fields(Evaluation)}
    evaluation = Evaluation(**_dataclass_fields(
        Evaluation, _table(path, "evaluation", raw.get("evaluation", {}), fields), path, "evaluation"))
    if evaluation.validation not in VALIDATIONS:
        raise StudyError(path, "evaluation.validation", f"expected one of {', '.join(VALIDATIONS)}, "
                                                        f"got {evaluation.validation!r}")
    methods = {}
    for mname, m in _table(path, "methods", raw.get("methods", {}), set(raw.get("methods", {}))).items():
        key = f"methods.{mname}"
        m = _table(path, key, m, {"process", "prior", "params"}, ("process",))
        process = _typed(path, f"{key}.process", m["process"], str)
        methods[mname] = Method(mname, process, _typed(path, f"{key}.prior", m.get("prior", "gaussian"), str),
                                _process_params(path, key, process, m.get("params")))
    experiments = raw.get("experiments", [])
    if not isinstance(experiments, list):
        raise StudyError(path, "experiments", "expected an array of tables ([[experiments]])")
    experiments = tuple(_experiment(path, f"experiments[{i}]", e, methods) for i, e in enumerate(experiments))
    runs = parse_runs(path, raw.get("runs", {}))
    evaluations = parse_evaluations(path, raw.get("evaluations", []), runs)
    reports = []
    for i, r in enumerate(raw.get("reports", [])):
        key = f"reports[{i}]"
        r = _table(path, key, r, {"generator", "output"}, ("generator",))
        if r["generator"] not in generators:
            raise StudyError(path, f"{key}.generator",
                             f"unknown generator {r['generator']!r} (the repository's studies/reports has: "
                             f"{', '.join(generators) or 'none'})")
        output = _typed(path, f"{key}.output", r.get("output", generators[r["generator"]].output), str)
        reports.append(ReportSpec(r["generator"], output))
    study = Study(name=name, file=path, title=_typed(path, "title", raw.get("title", ""), str),
                  data=_typed(path, "data", raw.get("data", ""), str), uses=tuple(uses), dataset=dataset,
                  training=training, evaluation=evaluation, methods=tuple(methods.values()),
                  experiments=experiments, runs=runs, evaluations=evaluations, reports=tuple(reports))
    if not (experiments or evaluations or reports or uses):
        raise StudyError(path, "(file)", "declares nothing to run or report: add [[experiments]] or [[evaluations]] "
                                         "(with a [dataset]), or [[reports]] of the studies it uses")
    if (experiments or evaluations) and dataset is None:
        raise StudyError(path, "dataset", "required: the study trains runs (it has experiments or evaluations)")
    if experiments and not dataset.family.sweeps:
        raise StudyError(path, "experiments", f"the thesis's grids and declared series run in Maze2D; a "
                                              f"{dataset.family.title} study declares [runs.NAME] and [[evaluations]]")
    for i, e in enumerate(evaluations):
        missing = set(e.task_sets) - set(dataset.family.task_sets)
        if missing:
            raise StudyError(path, f"evaluations[{i}].task_sets", f"{dataset.family.title} has the task sets "
                                                                  f"{', '.join(dataset.family.task_sets)}, not "
                                                                  f"{', '.join(sorted(missing))}")
    return study


def committed_csv(study: Study, root: Path) -> Path:
    """Where a grid study's committed rows lie: docs/results/DATA/results.csv."""
    return Path(root) / "docs" / "results" / study.data_dir / "results.csv"
