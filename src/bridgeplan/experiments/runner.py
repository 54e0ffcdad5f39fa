"""Running a sweep: train what is missing, evaluate what is not in the store yet.

Work is split into units, one per trained run (train or resume it, in a study's stages first, then evaluate its
snapshots for every series of every experiment and split that shows it: :func:`grid_units`). A run from the learned
prior trains its prior first, under the prior's lock (the units of one seed share it: one trains it, the others wait).
The units run in a :class:`~bridgeplan.workers.Executor` (this process, worker processes or Ray tasks), beside a study's
declared evaluations.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from bridgeplan import config as cfg
from bridgeplan import paths
from bridgeplan.checkpoint import load_checkpoint
from bridgeplan.experiments.grids import Experiment, RunSpec
from bridgeplan.experiments.store import VALIDATION_SUFFIX, ResultsStore, row_from_eval_json
from bridgeplan.locks import run_lock
from bridgeplan.processes import DDPM
from bridgeplan.workers import Executor, Unit


@dataclass(frozen=True)
class SweepSettings:
    """How a sweep trains and evaluates; the grid itself comes from the experiments."""

    maze: str = "umaze"
    dataset: str = ""
    """Dataset directory; generated under ``results_dir/data`` when empty."""
    dataset_steps: int = 200_000
    """Transitions to generate when no dataset is given."""
    preset: str = "cpu-small"
    train_steps: int = 3000
    """Optimizer steps per planner run."""
    prior_steps: int = 2000
    """Optimizer steps for the learned prior."""
    checkpoint_every: int = 500
    """Snapshot interval: the x-axis of the figures."""
    episodes: int = 200
    seeds: tuple[int, ...] = (0,)
    results_dir: str = "results"
    overrides: dict = field(default_factory=dict)
    """Extra TrainConfig fields (e.g. a tiny model for tests)."""
    validation: bool = False
    """Evaluate on validation episodes (task seed + ``evaluate.VALIDATION_SEED_OFFSET``), each run's final
    snapshot only, into the experiment ``<name>-validation``: where settings (NFE, sampler) are chosen, to be
    reported on the test episodes of ``<name>``."""
    only_runs: tuple[str, ...] | None = None
    """Train and evaluate only these runs (and the learned priors they need): a study's plan names those it has
    evaluations to compute for, so that rows imported into its store are not made again; None: every run."""


def _train_config(s: SweepSettings, spec: RunSpec, seed: int, prior_run: str) -> cfg.TrainConfig:
    process = spec.process
    if process.distills:  # its teacher: the sweep's DDPM run of the same seed (trained first, by run_job)
        teacher = _teacher_config(s, spec, seed)
        where = (paths.runs_dir(s.results_dir) / teacher.run_name()).resolve()  # found from anywhere, as the data
        process = dataclasses.replace(process, teacher=str(where))
    return cfg.preset_config(
        s.maze, s.preset, **s.overrides, dataset=s.dataset, steps=s.train_steps, seed=seed,
        checkpoint_every=s.checkpoint_every, process=process, prior=spec.prior,
        prior_run=prior_run if spec.prior == "learned" else "")


def _teacher_config(s: SweepSettings, spec: RunSpec, seed: int) -> cfg.TrainConfig:
    """The DDPM run a distilling ``spec`` learns from at ``seed``: the sweep's own, with the student's steps."""
    return _train_config(s, RunSpec(DDPM(steps=spec.process.steps), "gaussian"), seed, "")


def _prior_config(s: SweepSettings, seed: int, planner: cfg.TrainConfig) -> cfg.PriorTrainConfig:
    """The learned prior for the planners of ``s``: trained on their windows (horizon and stride)."""
    return cfg.learned_prior_config(planner, s.prior_steps, dataset=s.dataset, seed=seed)


def _trained_step(run_dir: Path) -> int:
    """Optimizer steps a run has done (-1: not started)."""
    ckpt = paths.checkpoint_path(run_dir)
    return load_checkpoint(ckpt)["step"] if ckpt.exists() else -1


def train_to(trainer, config, run_dir: Path, progress: bool) -> None:
    """Train (or resume) the run in ``run_dir`` to ``config.steps`` with ``trainer`` (``train.train``,
    ``train.train_prior``, ``gcbc.train_gcbc``); nothing when it is there. Another sweep or worker training the
    same run holds its lock: wait for it, then see what is left. A worker says which (:func:`doing`)."""
    from bridgeplan.workers import doing

    with run_lock(run_dir):
        done = _trained_step(run_dir)
        if done < config.steps:
            doing(f"training {run_dir}")
            trainer(config, run_dir, resume=done >= 0, progress=progress)
        else:
            doing(f"found {run_dir} trained")


def _train(settings: SweepSettings, spec: RunSpec, seed: int, prior_run: str, progress: bool) -> cfg.TrainConfig:
    """Train (or finish) ``spec``'s run of ``seed`` to ``settings.train_steps``, a distilling run's teacher first
    (another unit may be training it: :func:`train_to` waits for it); its config."""
    from bridgeplan.train import train

    config = _train_config(settings, spec, seed, prior_run)
    if config.process.distills:
        train_to(train, _teacher_config(settings, spec, seed), Path(config.process.teacher), progress)
    train_to(train, config, paths.runs_dir(settings.results_dir) / config.run_name(), progress)
    return config


def run_job(work: list[tuple[SweepSettings, list[Experiment]]], spec: RunSpec, seed: int,
            prior: cfg.PriorTrainConfig | None, stages: tuple[tuple[int, int], ...] = (), threads: int = 0,
            progress: bool = True) -> int:
    """Train (or finish) one run, its learned ``prior`` first (None: it samples from another prior), in ``stages``
    first ((steps, checkpoint interval) of earlier passes, as a study's committed runs were trained), then evaluate
    every (snapshot, series) that each of ``work``'s sweeps (its settings, its experiments: the splits and
    experiments that show this run) needs of it; returns the new rows.

    Each snapshot is loaded once per sweep and evaluated for every series (NFE, sampler, correction, execution, task
    set) whose evaluation is missing from the store (its ``store.KEY``, with ``Series.sampling_tag`` as the row
    writes it); an evaluation stored already, for another experiment, is only linked to this one. The floors are
    computed once per task set and controller for the sweep.
    """
    from bridgeplan.device import configure_threads
    from bridgeplan.train import train_prior

    first = work[0][0]
    prior_run = "" if prior is None else str(paths.runs_dir(first.results_dir) / prior.run_name())
    configure_threads(threads or _train_config(first, spec, seed, prior_run).threads)
    if prior is not None:
        train_to(train_prior, prior, Path(prior_run), progress)
    for steps, every in stages:
        _train(dataclasses.replace(first, train_steps=steps, checkpoint_every=every), spec, seed, prior_run, progress)
    config = _train(first, spec, seed, prior_run, progress)
    return sum(_evaluate(settings, experiments, spec, seed, config) for settings, experiments in work)


def _evaluate(settings: SweepSettings, experiments: list[Experiment], spec: RunSpec, seed: int,
              config: cfg.TrainConfig) -> int:
    """:func:`run_job`'s evaluations for one sweep; the rows added."""
    from bridgeplan.envs import family_of
    from bridgeplan.evaluate import VALIDATION_SEED_OFFSET, evaluate_planner, floors, make_tasks
    from bridgeplan.runs import load_planner
    from bridgeplan.workers import doing

    run_dir = paths.runs_dir(settings.results_dir) / config.run_name()
    store = ResultsStore(paths.store_path(settings.results_dir))
    suffix = VALIDATION_SUFFIX if settings.validation else ""
    split = "validation" if settings.validation else "test"
    wanted = [(exp.name + suffix, series) for exp in experiments for series in exp.series if series.run == spec]
    last_only = {exp.name + suffix for exp in experiments if exp.last_snapshot_only or settings.validation}
    task_seed = seed + VALIDATION_SEED_OFFSET if settings.validation else seed
    tasks = {multi: make_tasks(settings.maze, settings.episodes, task_seed, multi) for multi in (False, True)}
    sweep_floors = {}  # per task set and controller, once for the sweep (same prior, same tasks at every snapshot)
    added = 0
    steps = [s for s in paths.snapshot_steps(run_dir) if s <= config.steps]
    for step in steps:
        todo = []
        for name, series in wanted:
            if step != steps[-1] and name in last_only:
                continue
            key = (config.run_name(), step, series.nfe, series.sampling_tag(), series.execution.tag(),
                   int(series.multi_task), settings.episodes, task_seed)
            if store.has(key):  # evaluated for another experiment (or by another sweep): shown, not recomputed
                store.link(key, name)
            else:
                todo.append((name, series, key))
        if not todo:
            continue
        doing(f"evaluating {run_dir} at step {step}")
        planner, info = load_planner(run_dir, snapshot=step, device=config.device)
        for name, series, key in todo:
            if store.has(key):  # another experiment of this sweep named the same evaluation
                store.link(key, name)
                continue
            task_set = tasks[series.multi_task]
            family = family_of(settings.maze)
            ex = series.execution.resolved(family, settings.maze)
            floors_key = (series.multi_task, ex.controller, ex.lookahead)
            if floors_key not in sweep_floors:
                sweep_floors[floors_key] = floors(planner, family, task_set, ex)
            sampled = planner if series.sampler is None else planner.with_sampler(series.sampler)
            sampled = sampled.with_correction(series.correction)
            row = row_from_eval_json(evaluate_planner(sampled, task_set, series.nfe, run=info, execution=ex,
                                                      precomputed_floors=sweep_floors[floors_key]).to_dict(), split)
            added += store.add(row, [name])  # a concurrent sweep may have added it meanwhile
    return added


def ensure_dataset(settings: SweepSettings) -> SweepSettings:
    """Generate the sweep's dataset once if none was given."""
    if settings.dataset:
        return settings
    from bridgeplan.envs import family_of

    path = (paths.data_dir(settings.results_dir) / f"{settings.maze}-{settings.dataset_steps}").resolve()
    if not path.exists():
        family_of(settings.maze).generate_dataset(settings.maze, path, seed=123, steps=settings.dataset_steps)
    return dataclasses.replace(settings, dataset=str(path))


def grid_units(sweeps: list[tuple[SweepSettings, list[Experiment]]], stages: tuple[tuple[int, int], ...] = (),
               progress: bool = True) -> list[Unit]:
    """The units of work of ``sweeps`` (each its settings and experiments): one per trained run, whichever
    experiments and splits show it (:func:`run_job`, in ``stages`` first, after the learned prior it samples from),
    for an :class:`Executor`; each sweep's dataset is made where none was given."""
    units: dict[str, tuple[RunSpec, int, cfg.PriorTrainConfig | None, list]] = {}
    for settings, experiments in sweeps:
        for exp in experiments:
            exp.validate()
        ResultsStore(paths.store_path(settings.results_dir))  # refuse a newer schema before any work
        settings = ensure_dataset(settings)
        planner = cfg.preset_config(settings.maze, settings.preset, **settings.overrides)
        for seed in settings.seeds:
            for spec in dict.fromkeys(r for e in experiments for r in e.runs()):
                name = _train_config(settings, spec, seed, "").run_name()
                if settings.only_runs is not None and name not in settings.only_runs:
                    continue
                if name not in units:
                    prior = _prior_config(settings, seed, planner) if spec.prior == "learned" else None
                    units[name] = (spec, seed, prior, [])
                units[name][3].append((settings, experiments))
    return [Unit(run_job, (work, spec, seed, prior, tuple(stages)), f"the worker of run {spec.label()} seed {seed}")
            for spec, seed, prior, work in units.values()]


def run_sweep(experiments: list[Experiment], settings: SweepSettings, progress: bool = True) -> int:
    """Run every unit the experiments need in this process (``bridgeplan demo``); returns the number of new rows."""
    return sum(Executor().map(grid_units([(settings, experiments)], progress=progress), progress))
