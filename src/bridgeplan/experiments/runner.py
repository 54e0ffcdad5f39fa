"""Running a sweep: train what is missing, evaluate what is not in the store yet.

Work is split into jobs, one per trained run (train or resume it, then evaluate its snapshots for
every series that uses it). The learned prior is trained first, since the runs from it need it.
The jobs run as units of a :class:`~bridgeplan.workers.Executor` (this process, worker processes
or Ray tasks), as a study's declared evaluations do.
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
from bridgeplan.workers import Executor


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
    train_only: bool = False
    """Train (or resume) the runs to ``train_steps`` and evaluate nothing: an earlier stage of a study whose runs
    were trained in passes (``studies``)."""
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


def run_job(settings: SweepSettings, experiments: list[Experiment], spec: RunSpec, seed: int,
            prior_run: str, threads: int = 0, progress: bool = True) -> list[dict]:
    """Train (or finish) one run and evaluate every (snapshot, series) its experiments need; returns new rows.

    Each snapshot is loaded once and evaluated for every series (NFE, sampler, correction, execution, task set)
    whose evaluation is missing from the store (its ``store.KEY``, with ``Series.sampling_tag`` as the row writes
    it); an evaluation stored already, for another experiment, is only linked to this one. The floors are computed
    once per task set and controller for the job.
    """
    from bridgeplan.device import configure_threads
    from bridgeplan.envs import family_of
    from bridgeplan.evaluate import VALIDATION_SEED_OFFSET, evaluate_planner, floors, make_tasks
    from bridgeplan.runs import load_planner
    from bridgeplan.train import train
    from bridgeplan.workers import doing

    config = _train_config(settings, spec, seed, prior_run)
    if settings.only_runs is not None and config.run_name() not in settings.only_runs:
        return []
    configure_threads(threads or config.threads)
    run_dir = paths.runs_dir(settings.results_dir) / config.run_name()
    if config.process.distills:  # the teacher first (another job may be training it: train_to waits for it)
        teacher = _teacher_config(settings, spec, seed)
        train_to(train, teacher, Path(config.process.teacher), progress)
    train_to(train, config, run_dir, progress)
    if settings.train_only:
        return []
    store = ResultsStore(paths.store_path(settings.results_dir))
    suffix = VALIDATION_SUFFIX if settings.validation else ""
    split = "validation" if settings.validation else "test"
    wanted = [(exp.name + suffix, series) for exp in experiments for series in exp.series if series.run == spec]
    last_only = {exp.name + suffix for exp in experiments if exp.last_snapshot_only or settings.validation}
    task_seed = seed + VALIDATION_SEED_OFFSET if settings.validation else seed
    tasks = {multi: make_tasks(settings.maze, settings.episodes, task_seed, multi) for multi in (False, True)}
    job_floors = {}  # per task set and controller, once for the job (same prior, same tasks at every snapshot)
    rows = []
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
            if store.has(key):  # another experiment of this job named the same evaluation
                store.link(key, name)
                continue
            task_set = tasks[series.multi_task]
            family = family_of(settings.maze)
            ex = series.execution.resolved(family, settings.maze)
            floors_key = (series.multi_task, ex.controller, ex.lookahead)
            if floors_key not in job_floors:
                job_floors[floors_key] = floors(planner, family, task_set, ex)
            sampled = planner if series.sampler is None else planner.with_sampler(series.sampler)
            sampled = sampled.with_correction(series.correction)
            row = row_from_eval_json(evaluate_planner(sampled, task_set, series.nfe, run=info, execution=ex,
                                                      precomputed_floors=job_floors[floors_key]).to_dict(), split)
            if store.add(row, [name]):  # a concurrent sweep may have added it meanwhile
                rows.append(row)
    return rows


def ensure_dataset(settings: SweepSettings) -> SweepSettings:
    """Generate the sweep's dataset once if none was given."""
    import dataclasses

    if settings.dataset:
        return settings
    from bridgeplan.envs import family_of

    path = (paths.data_dir(settings.results_dir) / f"{settings.maze}-{settings.dataset_steps}").resolve()
    if not path.exists():
        family_of(settings.maze).generate_dataset(settings.maze, path, seed=123, steps=settings.dataset_steps)
    return dataclasses.replace(settings, dataset=str(path))


def run_sweep(experiments: list[Experiment], settings: SweepSettings, executor: Executor = Executor(),
              progress: bool = True) -> int:
    """Run every job the experiments need, each job a unit of ``executor``; returns the number of new result rows."""
    for exp in experiments:
        exp.validate()
    ResultsStore(paths.store_path(settings.results_dir))  # refuse a newer schema before any work
    settings = ensure_dataset(settings)
    specs = list(dict.fromkeys(r for e in experiments for r in e.runs()))
    planner = cfg.preset_config(settings.maze, settings.preset, **settings.overrides)
    prior_runs = {}
    for seed in settings.seeds:
        if any(r.prior == "learned" and (settings.only_runs is None or _train_config(
                settings, r, seed, "").run_name() in settings.only_runs) for r in specs):
            prior_runs[seed] = _ensure_prior(settings, seed, planner, progress)
    jobs = [(spec, seed) for seed in settings.seeds for spec in specs]
    rows = executor.map(run_job, [(settings, experiments, spec, seed, prior_runs.get(seed, "")) for spec, seed in jobs],
                        [f"the worker of run {spec.label()} seed {seed}" for spec, seed in jobs], "the rows stored",
                        progress)
    return sum(len(r) for r in rows)


def _ensure_prior(settings: SweepSettings, seed: int, planner: cfg.TrainConfig, progress: bool) -> str:
    from bridgeplan.train import train_prior

    config = _prior_config(settings, seed, planner)
    run_dir = paths.runs_dir(settings.results_dir) / config.run_name()
    train_to(train_prior, config, run_dir, progress)
    return str(run_dir)
