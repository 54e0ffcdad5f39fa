"""From a study to the experiments runner: the sweeps it runs, what is missing from its store, its cost.

Each ``[[experiments]]`` entry and split becomes one :class:`~bridgeplan.experiments.grids.Experiment` with its
:class:`~bridgeplan.experiments.runner.SweepSettings`, whose trained runs are units of work
(:func:`~bridgeplan.experiments.runner.grid_units`: finished runs and evaluations are skipped, runs are locked while
trained); ``[[evaluations]]`` become the jobs of :mod:`bridgeplan.studies.jobs`, a unit per training seed and the runs
it reads. ``study run`` runs them all in one executor (``--workers``, or the Ray backend).
"""

from __future__ import annotations

import dataclasses
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from bridgeplan.errors import BridgeplanError
from bridgeplan.studies.jobs import evaluation_units, jobs, needed_runs, train_config
from bridgeplan.studies.spec import ExperimentSpec, Study, StudyError, committed_csv

TRAIN_STEPS_PER_SECOND = 18.6
"""Training rate of one run (optimizer steps per second) assumed where the committed throughput bench has no
figure for the study's maze and preset (:func:`training_rate`): cpu-small umaze at one torch thread on a quiet
core, docs/results/bench.md."""
THROUGHPUT_BENCH = Path("docs/results/throughput/bench.json")
"""The committed training-throughput bench (``bridgeplan bench``) that costs are sized from, unless one of
:data:`THROUGHPUT_BENCHES` was made on this machine's CPU."""
THROUGHPUT_BENCHES = "docs/results/throughput*/bench.json"
"""The committed benches, each made on one CPU (its ``machine.cpu``)."""
EVAL_SECONDS_PER_EPISODE = 0.05
"""Assumed cost of one evaluation episode (planning in a batch with the others and simulating), CPU, cpu-small:
a rough figure, not measured per maze (replanned episodes cost more)."""


@dataclass(frozen=True)
class Scale:
    """How much of a study to run: ``committed`` as its file says, ``quick`` a look at a smaller scale."""

    name: str = "committed"

    @property
    def committed(self) -> bool:
        return self.name == "committed"

    def apply(self, study: Study) -> Study:
        """The study at this scale. Quick: the first two seeds, a tenth of the training steps (two snapshots),
        a tenth of the learned prior's, at most 20 episodes per evaluation (4 per task on OGBench), at most
        100 000 transitions of Maze2D data."""
        if self.committed:
            return study
        t = study.training
        steps = max(1, t.steps // 10)
        training = dataclasses.replace(t, steps=steps, checkpoint_every=max(1, steps // 2), stages=(),
                                       prior_steps=max(1, t.prior_steps // 10), seeds=t.seeds[:2])
        episodes = (study.evaluation.episodes if study.dataset is None else
                    min(study.episodes, study.dataset.family.quick_episodes))
        evaluation = dataclasses.replace(study.evaluation, episodes=episodes)
        experiments = tuple(dataclasses.replace(e, seeds=e.seeds[:2]) if e.seeds else e for e in study.experiments)
        evaluations = tuple(dataclasses.replace(e, seeds=e.seeds[:2]) if e.seeds else e for e in study.evaluations)
        dataset = study.dataset
        if dataset is not None and not dataset.path and dataset.family.sized_data:  # else the recipe's size
            n = min(dataset.steps, 100_000)
            dataset = dataclasses.replace(dataset, steps=n, path=f"results/quick/datasets/{dataset.maze}-{n}-v"
                                                                 f"{dataset.version}")
        return dataclasses.replace(study, training=training, evaluation=evaluation, experiments=experiments,
                                   evaluations=evaluations, dataset=dataset)


QUICK_NOTE = "QUICK SCALE (`--quick`): fewer seeds, steps and episodes; NOT the committed scale, not comparable"


def results_dir(study: Study, root: Path, scale: Scale) -> Path:
    """Where the study's store and runs live: ``results/NAME`` (as the campaigns' RESULTS), or
    ``results/quick/NAME`` at the quick scale."""
    return Path(root) / "results" / ("" if scale.committed else "quick") / study.name


def _informed(study: Study, exp: ExperimentSpec):
    from bridgeplan.processes import make_process

    return make_process(exp.process, **dict(exp.params))


def build_experiment(study: Study, index: int):
    """The :class:`Experiment` of ``study.experiments[index]``."""
    from bridgeplan.experiments.grids import Experiment, RunSpec, Series, build_experiments
    from bridgeplan.processes import make_process
    from bridgeplan.replan import Execution

    exp = study.experiments[index]
    key = f"experiments[{index}]"
    steps = study.training.diffusion_steps
    try:
        if exp.grid:
            experiment = build_experiments(steps, 4, _informed(study, exp))[exp.grid]
            if exp.title or exp.last_snapshot_only:
                experiment = dataclasses.replace(experiment, title=exp.title or experiment.title,
                                                 last_snapshot_only=exp.last_snapshot_only
                                                 or experiment.last_snapshot_only)
        else:
            methods = {m.name: m for m in study.methods}
            series = []
            for s in exp.series:
                m = methods[s.method]
                run = RunSpec(make_process(m.process, steps=steps, **dict(m.params)), m.prior)
                execution = Execution(**dict(s.execution)).resolved(study.dataset.family, study.dataset.maze)
                for nfe in s.nfe:
                    for multi in s.multi_task:
                        for correction in s.correction:
                            tag = " ".join(t for t in (execution.tag(), s.sampler or "",
                                                       correction.tag() if correction else "",
                                                       "Multi2D" if multi else "") if t)
                            series.append(Series(f"{run.label()} NFE {nfe}{' ' + tag if tag else ''}", run, nfe,
                                                 execution, multi, s.sampler, correction))
            experiment = Experiment(exp.name, exp.title or exp.name, tuple(series), exp.last_snapshot_only)
        experiment.validate()
    except BridgeplanError as e:
        raise StudyError(study.file, key, str(e)) from None
    return experiment


@dataclass(frozen=True)
class Sweep:
    """One experiment of the study on one split, with the runner's settings."""

    experiment: object
    settings: object
    stages: tuple[tuple[int, int], ...]


def sweeps(study: Study, root: Path, scale: Scale = Scale()) -> list[Sweep]:
    """The study's sweeps, in file order (test before validation within an entry)."""
    from bridgeplan.experiments.runner import SweepSettings

    study = scale.apply(study)
    t = study.training
    out = []
    base = dict(t.overrides)
    for i, exp in enumerate(study.experiments):
        experiment = build_experiment(study, i)
        overrides = dict(base)
        if exp.hold_share is not None:
            overrides["hold_share"] = exp.hold_share
        for split in exp.splits:
            settings = SweepSettings(
                maze=study.dataset.maze, dataset=str((Path(root) / study.dataset.directory()).resolve()),
                dataset_steps=study.dataset.steps, preset=t.preset, train_steps=t.steps, prior_steps=t.prior_steps,
                checkpoint_every=t.checkpoint_every, episodes=study.episodes,
                seeds=exp.seeds or t.seeds, results_dir=str(results_dir(study, root, scale)), overrides=overrides,
                validation=split == "validation")
            out.append(Sweep(experiment, settings, t.all_stages()))
    return out


def check_study(study: Study) -> None:
    """Everything that can be checked without the other studies: the grids and series, the preset and the
    training fields against the maze."""
    from bridgeplan import config as cfg

    if study.dataset is not None:
        try:
            cfg.preset_config(study.dataset.maze, study.training.preset, **dict(study.training.overrides))
        except (BridgeplanError, TypeError, ValueError) as e:
            raise StudyError(study.file, "training", str(e)) from None
    for i in range(len(study.experiments)):
        build_experiment(study, i)
    configs = {}
    for run in study.runs:
        try:
            configs[run.name] = train_config(study, run, 0, Path("dataset"))
        except (BridgeplanError, TypeError, ValueError) as e:
            raise StudyError(study.file, f"runs.{run.name}", str(e)) from None
    for i, e in enumerate(study.evaluations):
        check_nfes(study, i, e, configs)
    written: dict[Path, int] = {}
    for i, e in enumerate(study.evaluations):
        for job in jobs(dataclasses.replace(study, evaluations=(e,)), Path("results"), Path("."), quick=False):
            if job.path in written:
                raise StudyError(study.file, f"evaluations[{i}].out",
                                 f"{job.path} is written twice (by evaluations[{written[job.path]}] and [{i}], for "
                                 f"two training seeds or splits): name {{seed}} or {{eval_seed}} in it, or give an "
                                 f"evaluation of no run seeds = [0]")
            written[job.path] = i


NFE_OF = {"run": "nfe", "low": "nfe_low", "high": "nfe_high"}
"""The NFE option of the run each evaluation command's run option names."""


def check_nfes(study: Study, i: int, e, configs: dict) -> None:
    """Evaluation ``i``'s NFEs against the processes of the planners it samples (``configs``: the study's run configs
    by name), refused before anything is trained: a bridge of N steps takes at most N - 1."""
    from bridgeplan.eval_commands import STUDY_COMMANDS

    args = dict(e.args)
    for option, name in zip(STUDY_COMMANDS[e.command].runs, e.runs):
        nfe, process = args.get(NFE_OF.get(option)), getattr(configs.get(name), "process", None)
        if nfe is not None and process is not None:
            try:
                process.validate_nfe(nfe)
            except BridgeplanError as err:
                raise StudyError(study.file, f"evaluations[{i}].args.{NFE_OF[option]}", f"{name}: {err}") from None


def trained_methods(study: Study) -> set:
    """The trained methods (``MethodKey`` at default sampler, open loop, single-task) of the study's runs."""
    from bridgeplan.analysis.keys import key_of

    out = set()
    for i, exp in enumerate(study.experiments):
        hold = exp.hold_share if exp.hold_share is not None else dict(study.training.overrides).get("hold_share", 0.0)
        for run in build_experiment(study, i).runs():
            out.add(key_of(run.process, run.prior, hold_share=hold, sampler=""))
    return out


def check_reports(study: Study, studies: dict[str, Study], generators: dict) -> None:
    """Its ``uses`` name known studies that parse, with no cycle through them (itself included), and each report's
    generator reads only methods that the study or the studies it uses train."""
    from bridgeplan.analysis.keys import label

    broken = getattr(studies, "broken", {})
    for i, name in enumerate(study.uses):
        if name not in studies:
            bad = [file for file in broken if Path(file).stem == name]
            if bad:
                raise StudyError(study.file, f"uses[{i}]", f"study {name!r} is broken ({bad[0]}: see its own error)")
            raise StudyError(study.file, f"uses[{i}]", f"unknown study {name!r} (known: {', '.join(sorted(studies))})")
    if cycle := _cycle(study, studies):
        raise StudyError(study.file, "uses", f"a study cannot read its own results: {' -> '.join(cycle)}")
    if not study.reports:
        return
    trained = set(trained_methods(study))
    for name in study.uses:
        trained |= trained_methods(studies[name])
    for i, report in enumerate(study.reports):
        missing = [k for k in generators[report.generator].reads() if k not in trained]
        if missing:
            raise StudyError(study.file, f"reports[{i}].generator",
                             f"{report.generator} reads {label(missing[0])} (N={missing[0].steps}), which neither "
                             f"{study.name} nor the studies it uses ({', '.join(study.uses) or 'none'}) train")


def _cycle(study: Study, studies: dict[str, Study]) -> list[str]:
    """The names along a path of ``uses`` from ``study`` back to itself ([] when there is none)."""
    def walk(uses: tuple[str, ...], path: list[str], seen: set[str]) -> list[str]:
        for used in uses:
            if used == study.name:
                return [*path, used]
            if used not in seen and used in studies:
                seen.add(used)
                if found := walk(studies[used].uses, [*path, used], seen):
                    return found
        return []

    return walk(study.uses, [study.name], set())


# --- what is missing ---------------------------------------------------------------------------------------------

def _planned_snapshots(run_dir: Path, stages) -> list[int]:
    from bridgeplan import paths

    steps = set(paths.snapshot_steps(run_dir)) if run_dir.exists() else set()
    start = 0
    for total, every in stages:
        steps |= {s for s in range(start + 1, total + 1) if s % every == 0 or s == total}
        start = total
    return sorted(s for s in steps if s <= stages[-1][0])


@dataclass(frozen=True)
class Missing:
    trains: tuple[tuple[str, int, int], ...]
    """(run name, steps to train, steps done) per run that is not finished and has evaluations to compute, learned
    priors included."""
    evaluations: Counter
    """Evaluations to compute (absent from the store), each counted once, under the first experiment that names
    it (``-validation`` for the validation split)."""
    episodes: int
    """Episodes per evaluation."""
    corrections: Counter = dataclasses.field(default_factory=Counter)
    """Evaluations to compute by experiment name and consistency correction (its tag; '' uncorrected)."""
    wanted: dict[str, set[tuple]] = dataclasses.field(default_factory=dict)
    """Per experiment, the evaluations (``store.KEY``) it shows and is not yet linked to in the store: computed, or
    only linked where another experiment's evaluation is stored already."""
    declared: dict[str, set[tuple]] = dataclasses.field(default_factory=dict)
    """Per experiment, every evaluation (``store.KEY``) it shows, stored or not."""
    jsons: tuple = ()
    """The evaluation JSONs of the study's ``[[evaluations]]`` not written yet (``commands.Job``)."""

    def eval_seconds(self, per_json: dict[str, float] | None = None) -> float:
        """Seconds of the evaluations to compute: :data:`EVAL_SECONDS_PER_EPISODE` per episode, but a JSON of a
        command in ``per_json`` (:func:`measured_json_seconds`) at its figure."""
        per_json = per_json or {}
        guessed = sum(self.evaluations.values()) + sum(j.command not in per_json for j in self.jsons)
        return guessed * self.episodes * EVAL_SECONDS_PER_EPISODE + sum(per_json.get(j.command, 0.0)
                                                                          for j in self.jsons)


def training_rate(root: Path, maze: str, config, cpu: str | None = None) -> tuple[float, str]:
    """Steps per second of one run of ``config`` (its preset, batch and precision) in ``maze`` as a sweep runs it,
    one torch thread beside a second job (two jobs of ``--workers 2``), from a committed throughput bench: the one
    made on this machine's ``cpu`` (``device.cpu_model``; the same code trains 2-3x slower on one x86 CPU
    than on another) where one has the figure, else :data:`THROUGHPUT_BENCH`; ``TRAIN_STEPS_PER_SECOND`` where
    neither has it. A bench's two-jobs figure (the other core training) is preferred to its throughput table's
    (the other core spinning). Returns the rate and where it came from."""
    import json

    from bridgeplan.device import cpu_model

    cpu = cpu_model() if cpu is None else cpu
    benches = []  # (made on this CPU, path, its CPU, its figures): this CPU's first
    for path in Path(root).glob(THROUGHPUT_BENCHES):
        try:
            bench = json.loads(path.read_text())
            made_on = bench.get("machine", {}).get("cpu") or ""
            figures = (bench.get("side_by_side", []), bench["throughput"])
        except (OSError, ValueError, KeyError, AttributeError):
            continue
        if (bool(cpu) and made_on == cpu) or path == Path(root) / THROUGHPUT_BENCH:
            benches.append((not (cpu and made_on == cpu), str(path), made_on, figures))
    wanted = (config.preset, maze, config.batch_size, config.precision)
    for _, path, made_on, (side_by_side, throughput) in sorted(benches):
        where = f"{Path(path).relative_to(root)}, made on {made_on or 'an unrecorded CPU'}, one thread"
        for r in side_by_side:
            if (r["preset"], r["maze"], r["batch"], r["precision"], r["other_core"]) == (*wanted, "training"):
                return r["steps_per_s"], f"{where}, beside a second training job"
        for r in throughput:
            if (r["preset"], r["maze"], r["batch"], r["precision"], r["implementation"], r["threads"],
                    r["busy_cores"]) == (*wanted, "bridgeplan", 1, 1):
                return r["windows_per_s"] / (r["batch"] * r["grad_accum"]), f"{where}, a core busy"
    return TRAIN_STEPS_PER_SECOND, "assumed, no figure in the throughput bench"


def measured_rate(run_dir: Path) -> tuple[float, str] | None:
    """Steps per second of ``run_dir``'s run as this study's own training measured it (its steps over its elapsed
    seconds, the machine's load included: ``gcbc train``'s metrics.jsonl's last line, a planner's or prior's
    checkpoint): the run's own where it has begun, else the median of its other training seeds' beside it
    (``NAME-sK``); None where none has a figure (then :func:`training_rate`'s bench)."""
    import json
    import statistics

    from bridgeplan.checkpoint import load_checkpoint
    from bridgeplan.errors import BridgeplanError

    def rate(directory: Path) -> float | None:
        try:
            if (directory / "metrics.jsonl").exists():
                last = json.loads((directory / "metrics.jsonl").read_text().strip().splitlines()[-1])
            else:
                last = load_checkpoint(directory) if directory.is_dir() else {}
            return last["step"] / last["elapsed_seconds"] if last["elapsed_seconds"] > 0 else None
        except (OSError, ValueError, KeyError, IndexError, TypeError, BridgeplanError):
            return None

    if (own := rate(run_dir)) is not None:
        return own, "measured by this run's training so far"
    stem = re.sub(r"-s\d+$", "", run_dir.name)
    seeds = [d for d in run_dir.parent.glob(f"{stem}-s*") if re.fullmatch(rf"{re.escape(stem)}-s\d+", d.name)]
    rates = [r for d in sorted(seeds) if d != run_dir and (r := rate(d)) is not None]
    if not rates:
        return None
    return statistics.median(rates), f"measured by {len(rates)} other training seed{'s' * (len(rates) > 1)} here"


def missing(study: Study, root: Path, scale: Scale = Scale()) -> Missing:
    """What ``study run`` would train and evaluate: evaluations absent from the store, and the runs they need that are
    short of their steps (a run whose evaluations are all stored, imported say, is not trained)."""
    from bridgeplan import config as cfg
    from bridgeplan import paths
    from bridgeplan.evaluate import VALIDATION_SEED_OFFSET
    from bridgeplan.experiments.runner import _prior_config, _train_config, _trained_step
    from bridgeplan.experiments.store import VALIDATION_SUFFIX, stored_keys

    plan = sweeps(study, root, scale)
    trains: dict[str, tuple[int, int]] = {}
    evaluations: Counter = Counter()
    corrections: Counter = Counter()
    wanted: dict[str, set[tuple]] = {}
    declared: dict[str, set[tuple]] = {}
    keys, members = stored_keys(paths.store_path(results_dir(study, root, scale)))
    seen = set()
    for sweep in plan:
        s, experiment = sweep.settings, sweep.experiment
        runs = paths.runs_dir(s.results_dir)
        planner = cfg.preset_config(s.maze, s.preset, **s.overrides)
        suffix = VALIDATION_SUFFIX if s.validation else ""
        name = experiment.name + suffix
        for seed in s.seeds:
            for spec in experiment.runs():
                config = _train_config(s, spec, seed, "")
                run_dir = runs / config.run_name()
                snapshots = _planned_snapshots(run_dir, sweep.stages if scale.committed else ((s.train_steps,
                                                                                                s.checkpoint_every),))
                last_only = experiment.last_snapshot_only or s.validation
                task_seed = seed + VALIDATION_SEED_OFFSET if s.validation else seed
                for series in experiment.series:
                    if series.run != spec:
                        continue
                    for step in (snapshots[-1:] if last_only else snapshots):
                        key = (config.run_name(), step, series.nfe, series.sampling_tag(),
                               series.execution.tag(), int(series.multi_task), s.episodes, task_seed)
                        declared.setdefault(name, set()).add(key)
                        if (name, key) not in members:
                            wanted.setdefault(name, set()).add(key)
                        if key not in keys:  # its run is trained (or finished) for it
                            trains.setdefault(config.run_name(), (config.steps, _trained_step(run_dir)))
                            if spec.prior == "learned":
                                prior = _prior_config(s, seed, planner)
                                trains.setdefault(prior.run_name(), (prior.steps,
                                                                     _trained_step(runs / prior.run_name())))
                        if key not in keys and key not in seen:
                            seen.add(key)
                            evaluations[name] += 1
                            corrections[name, series.correction.tag() if series.correction else ""] += 1
    scaled, jsons = scale.apply(study), ()
    if study.evaluations:
        results = results_dir(study, root, scale)
        jsons = tuple(j for j in jobs(scaled, results, results, not scale.committed)
                      if not j.path.exists())
        for run, n, done in needed_runs(scaled, results, {(r, j.seed) for j in jsons for r in j.runs}):
            trains.setdefault(run, (n, done))
    todo = tuple((run, n, done) for run, (n, done) in sorted(trains.items()) if done < n)
    return Missing(todo, evaluations, scaled.episodes if scaled.dataset else 0, corrections, wanted, declared, jsons)


def committed_not_imported(study: Study, root: Path, m: Missing) -> str | None:
    """What of the missing ``m`` docs/results holds already (committed, not imported into results/): a run would
    compute it again. None when nothing."""
    if study.evaluations:
        results = results_dir(study, root, Scale())
        committed = sum((Path(root) / "docs" / "results" / j.path.relative_to(results)).exists() for j in m.jsons)
        if committed:
            return (f"{committed} of the {len(m.jsons)} evaluation JSONs to make are committed in docs/results: "
                    f"`bridgeplan study import {study.name}` copies them (their runs then need no training)")
    elif study.experiments and m.evaluations:
        csv = committed_csv(study, root)
        if csv.exists():
            return (f"{csv.relative_to(root)} holds this study's committed rows: `bridgeplan study import "
                    f"{study.name}` stores them (then only what they lack is computed)")
    return None


def measured_json_seconds(study: Study, root: Path) -> dict[str, float]:
    """Per command, the median seconds its evaluation JSONs committed in docs/results took where they record them
    (OGBench's families: ``protocol_seconds``, the episodes' own time, this machine's load included); a command
    with none is absent."""
    import json
    import statistics

    results = results_dir(study, root, Scale())
    seconds: dict[str, list[float]] = {}
    for job in jobs(Scale().apply(study), results, results, False):
        try:
            d = json.loads((Path(root) / "docs" / "results" / job.path.relative_to(results)).read_text())
            took = float(d["protocol_seconds"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        seconds.setdefault(job.command, []).append(took)
    return {command: statistics.median(values) for command, values in seconds.items()}


def describe_missing(study: Study, root: Path, scale: Scale = Scale()) -> list[str]:
    """``study run --dry-run``'s lines."""
    m = missing(study, root, scale)
    store = results_dir(study, root, scale) / "results.sqlite"
    scale_note = "committed scale" if scale.committed else QUICK_NOTE
    if not study.experiments and not study.evaluations:
        return [f"study {study.name} ({scale_note}): trains and evaluates nothing of its own (its reports read: "
                f"{', '.join(study.uses) or 'none'})"]
    where = (f"store {store}{'' if store.exists() else ' (absent)'}" if study.experiments else
             f"runs and evaluation JSONs under {results_dir(study, root, scale)}")
    lines = [f"study {study.name} ({scale_note}): {where}"]
    from bridgeplan import config as cfg

    rate, source = training_rate(root, study.dataset.maze, cfg.preset_config(
        study.dataset.maze, study.training.preset, **dict(study.training.overrides)))
    policies = {r.name for r in study.runs if r.trainer == "gcbc"}  # no bench figure: the planners' is not theirs
    train_s, guessed, unknown = 0.0, 0, 0
    for run, n, done in m.trains:
        left = n - max(done, 0)
        measured = measured_rate(results_dir(study, root, scale) / "runs" / run)
        line = f"  train {run}: {left} steps ({max(done, 0)} of {n} done)"
        if measured is None and re.sub(r"-s\d+$", "", run) in policies:
            unknown += 1
            lines.append(f"{line}, not estimated (a GCBC/GCIQL run: no figure until one of its seeds trains here)")
            continue
        train_s += left / (measured[0] if measured else rate)
        guessed += measured is None
        lines.append(line + (f", {_hours(left / measured[0])} at {measured[0]:.2f} steps/s ({measured[1]})"
                             if measured else ""))
    for name, count in m.evaluations.items():
        lines.append(f"  evaluate {name}: {count} evaluations x {m.episodes} episodes")
        by_correction = sorted((tag, n) for (exp, tag), n in m.corrections.items() if exp == name)
        if any(tag for tag, _ in by_correction):  # corrected series: each correction's evaluations apart
            lines.extend(f"    {tag or 'uncorrected'}: {n} evaluations" for tag, n in by_correction)
    by_command: dict[str, list] = {}
    for job in m.jsons:
        by_command.setdefault(job.command, []).append(job)
    per_json = measured_json_seconds(study, root) if scale.committed and m.jsons else {}
    for command, todo in by_command.items():
        lines.append(f"  {command}: {len(todo)} evaluation JSONs, e.g. {todo[0].path}" + (
            f", {_hours(per_json[command])} each (the committed ones' median)" if command in per_json else ""))
    if scale.committed and (note := committed_not_imported(study, root, m)):
        lines.append(f"  committed: {note}")
    shared = sum(len(keys) for keys in m.wanted.values()) - sum(m.evaluations.values())
    if shared:
        lines.append(f"  link {shared} evaluations to more experiments: stored already, or named by an earlier "
                     f"experiment above (computed once)")
    policies_note = f" (the {unknown} GCBC/GCIQL run{'s' * (unknown > 1)} not estimated)" if unknown else ""
    at = (f" at {rate:.1f} steps/s per run ({source})" if guessed and guessed == len(m.trains) - unknown else
          f" ({guessed} runs at {rate:.1f} steps/s: {source})" if guessed else "")
    lines.append(f"  total: {len(m.trains)} runs to train, {sum(m.evaluations.values()) + len(m.jsons)} evaluations; "
                 f"estimated {_hours(train_s)} of training{at}"
                 f"{policies_note} and "
                 f"{_hours(m.eval_seconds(per_json))} "
                 f"of evaluation (at {EVAL_SECONDS_PER_EPISODE} s per episode, assumed, where no committed JSON of "
                 f"its command says; one CPU core per job: divide by --workers)")
    return lines


def quick_table(study: Study, root: Path) -> list[str]:
    """After ``study run --quick``: per maze, task set and controller, the best planner of the quick rows (its last
    snapshot; chosen on the validation episodes where the study has them, else on the test episodes) beside the
    same planner's committed score (docs/results, the committed scale's last snapshot) and the line alone, a table
    shaped like the headline's; [] for a study without grid rows (its evaluations are JSON files)."""
    from bridgeplan.analysis.keys import label, tasks_label
    from bridgeplan.analysis.load import Point, Results, load_csvs, row_from_csv
    from bridgeplan.analysis.stats import mean_se
    from bridgeplan.analysis.tables import fmt_mean_se, table
    from bridgeplan.experiments.store import ResultsStore
    from bridgeplan.paths import store_path

    store = store_path(results_dir(study, root, Scale("quick")))
    if not study.experiments or not store.exists():
        return []
    quick = Results(row_from_csv({k: "" if v is None else str(v) for k, v in r.items()})  # as its CSV has them
                    for r in ResultsStore(store).rows())
    committed = load_csvs([committed_csv(study, root)])
    groups: dict[tuple, list[Point]] = {}
    for key in quick.keys():
        last = quick.steps(key)[-1]
        group = (next(iter(quick.rows(Point(key, last, quick.nfes(key, last)[0])).values())).maze,
                 tasks_label(key), "pursued" if key.execution.controller == "pursuit" else "tracked")
        groups.setdefault(group, []).extend(quick.points(key, last))
    has_validation = any(quick.keys("validation"))

    def score(results: Results, point: Point | None) -> str:
        if point is None or not results.values(point):
            return "-"
        return (f"{fmt_mean_se(results.values(point), one_seed='mean')} "
                f"({mean_se(results.values(point, field='success')).mean:.2f}), {len(results.values(point))} seeds")

    def at_last(results: Results, point: Point) -> Point | None:
        steps = [s for s in results.steps(point.key) if point.nfe in results.nfes(point.key, s)]
        return Point(point.key, steps[-1], point.nfe) if steps else None

    lines = []
    for (maze, tasks, controller), points in groups.items():
        split = "validation" if has_validation else "test"
        chosen = max(points, key=lambda q: mean_se(quick.values(q, split)).mean if quick.values(q, split) else -1e9)
        floor = fmt_mean_se(quick.values(chosen, field="floor"), one_seed="mean")
        lines.append([maze, tasks, controller,
                      f"{label(chosen.key)}, NFE {chosen.nfe}" + (f", {chosen.key.tag}" if chosen.key.tag else ""),
                      score(quick, chosen), score(committed, at_last(committed, chosen)), floor])
    chosen_on = "validation" if has_validation else "test"
    return table(["maze", "tasks", "executed", f"best planner (quick, chosen on {chosen_on})", "quick score (success)",
                  "committed score (success)", "line alone (quick)"], lines)


def _hours(seconds: float) -> str:
    return f"{seconds / 3600:.1f} h" if seconds >= 3600 else f"{seconds / 60:.1f} min"


# --- running -----------------------------------------------------------------------------------------------------

def ensure_dataset(study: Study, root: Path, progress: bool = True) -> Path:
    """The study's dataset, generated by its family's recipe (seed and steps as declared) when absent; its data
    version is checked against the generator's, where the family's data has versions."""
    from bridgeplan.envs import family_of

    d = study.dataset
    family = family_of(d.maze)
    path = (Path(root) / d.directory()).resolve()
    if family.data_version is not None and d.version != family.data_version:
        raise StudyError(study.file, "dataset.version", f"data version {d.version}, but this bridgeplan generates "
                                                        f"version {family.data_version}")
    if not path.exists():
        family.generate_dataset(d.maze, path, seed=d.seed, steps=d.steps if family.sized_data else None,
                                piece_steps=d.piece_steps or None,
                                progress=progress)
    return path


def with_used(study: Study, studies: dict[str, Study]) -> list[Study]:
    """The studies whose results ``study``'s reports read (``uses``, and theirs, each once, first) and then
    ``study``: what `study run` runs so that one command makes a report's rows."""
    out: dict[str, Study] = {}

    def visit(s: Study) -> None:
        if s.name in out:
            return
        out[s.name] = s  # placed before its uses are visited: a cycle ends here
        for name in s.uses:
            visit(studies[name])
        out[s.name] = out.pop(s.name)  # then moved after them

    visit(study)
    return list(out.values())


def check_run(chain: list[Study], root: Path, scale: Scale, backend: str = "local", dry_run: bool = False) -> None:
    """What ``study run`` refuses before any work, for every study of ``chain`` (:func:`with_used`): an unknown
    backend, and (unless a dry run, which writes nothing) a results folder or a dataset's folder that cannot be
    written."""
    from bridgeplan.files import check_writable
    from bridgeplan.workers import check_backend

    check_backend(backend)
    if dry_run:
        return
    for s in chain:
        if s.experiments or s.evaluations:
            check_writable(results_dir(s, root, scale), "results folder", folder=True)
            dataset = Path(root) / scale.apply(s).dataset.directory()
            if not dataset.exists():
                check_writable(dataset.parent, "dataset folder", folder=True)


def run_study(study: Study, root: Path, scale: Scale = Scale(), backend: str = "local", workers: int | None = None,
              ray_address: str | None = None, progress: bool = True, note=None) -> int:
    """Train and evaluate what the study is missing: its grids' runs (each trained in the study's stages, then
    evaluated for every experiment and split that shows it) and its declared evaluations' training seeds, all units
    of one executor (``backend``: :func:`bridgeplan.workers.executor`); the number of new rows and JSONs.
    ``note(text)``, when given, hears first what of it is committed but not imported
    (:func:`committed_not_imported`)."""
    from bridgeplan.experiments.runner import grid_units
    from bridgeplan.workers import executor

    if not study.experiments and not study.evaluations:
        return 0
    m = missing(study, root, scale)
    if note is not None and scale.committed and (text := committed_not_imported(study, root, m)):
        note(f"{study.name}: {text}")
    if not (m.trains or m.evaluations or m.jsons or any(m.wanted.values())):
        return 0  # all stored (imported, say): no dataset to make either
    scaled = scale.apply(study)
    with executor(backend, workers or study.evaluation.workers, ray_address,
                  dict(study.training.overrides).get("device", "auto")) as pool:
        dataset = ensure_dataset(scaled, root, progress)
        units = []
        if study.experiments:  # link what is stored already; train and evaluate only the runs something is missing of
            from bridgeplan import paths
            from bridgeplan.experiments.store import ResultsStore, stored_keys

            path = paths.store_path(results_dir(study, root, scale))
            keys, _ = stored_keys(path)
            links = [(key, name) for name, wanted in m.wanted.items() for key in wanted if key in keys]
            if links:
                store = ResultsStore(path)
                for key, name in links:
                    store.link(key, name)
            only = tuple(sorted({run for run, _, _ in m.trains} | {key[0] for wanted in m.wanted.values()
                                                                     for key in wanted if key not in keys}))
            plan = sweeps(study, root, scale)
            units += grid_units([(dataclasses.replace(sweep.settings, only_runs=only), [sweep.experiment])
                                 for sweep in plan],  # earlier passes first where the committed runs had them
                                plan[0].stages[:-1] if scale.committed else (), progress)
        if study.evaluations:
            units += evaluation_units(scaled, results_dir(study, root, scale), dataset, not scale.committed)
        return sum(pool.map(units, progress))
