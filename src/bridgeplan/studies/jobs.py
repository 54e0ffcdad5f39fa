"""Studies whose rows are evaluation JSONs, one command each: named runs trained per training seed as the study
says, then ``bridgeplan eval`` (a planner's or a GCBC/GCIQL policy's), ``hierarchy eval``, ``graph`` or ``oracle`` per
training seed, split and task set, each writing one JSON (the form of OGBench's ``hyperparameters.sh``: every table
cell one declared line, run by ``study run``)::

    [runs.high-ddpm-k12]                 # a named run: TrainConfig fields over [training]'s, one per training seed
    process = "ddpm"
    horizon = 32
    stride = 12

    [[evaluations]]
    command = "hierarchy eval"           # eval | hierarchy eval | graph | oracle
    runs = ["high-ddpm-k12", "low-flow-k4"]
    args = { nfe_high = 16, nfe_low = 1, replan_every = 12, lookahead = 1.5 }   # the command's options
    out = "large-hierarchy/high-ddpm-k12-nfe16-low-flow-k4-nfe1/{tasks}-seed{eval_seed}.json"   # under docs/results
    splits = ["test", "validation"]      # the evaluation seed: the training seed, or 1000 + it
    task_sets = ["single", "multi"]      # multi: Multi2D (--multi-task; where the family has it)
    # task_seed = 0                      # the same test episodes for every training seed (validation: 1000)

A named run from the learned prior (``prior = "learned"``) samples it from the thesis's MLP trained first on the
same windows, per training seed, for [training]'s ``prior_steps`` (runs/<maze>-prior-learned-<shape>-s<seed>, shared
by the runs of one plan shape). ``out`` may name ``{seed}`` (training), ``{eval_seed}`` and ``{tasks}`` (``single``
or ``multi``). ``study run`` writes each under the study's results directory (results/NAME/OUT): a JSON there is
done; it trains what the missing ones need and calls their commands' functions on the options ``args`` fills (the
options dataclass the command's flags fill: :data:`bridgeplan.eval_commands.STUDY_COMMANDS`; ``--workers`` training
seeds side by side, one torch thread each). ``study export`` copies them to docs/results/OUT, where the study's
report reads them; ``study import`` copies the committed ones back. ``graph`` takes no run (``runs = []``), or its
low level (``runs = ["low"]``, its ``low`` option); the runner gives it the study's dataset. A validation split of a
family with validation tasks of its own (OGBench's) evaluates them (``--tasks``), unless the study pins the earlier
draw.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridgeplan.errors import one_line_warnings
from bridgeplan.eval_commands import STUDY_COMMANDS
from bridgeplan.studies.spec import NamedRun, command_options
from bridgeplan.workers import Unit, doing

# --- planning and running (the file format: bridgeplan.studies.spec) ---------------------------------------------

@dataclass(frozen=True)
class Job:
    """One JSON: the command that writes it, its runs' directories and its options (:data:`STUDY_COMMANDS`)."""

    path: Path
    run_dirs: tuple[str, ...]
    args: tuple[tuple[str, Any], ...]
    """Without the study's dataset file, which :func:`run_seed` adds for a command that reads it."""
    seed: int
    runs: tuple[str, ...]
    command: str

    def options(self, dataset: Path | None = None, progress: bool = False):
        """The command's options (``dataset``: the study's file, for a command that reads it)."""
        given = dict(self.args) | ({} if progress else {"no_progress": True})
        if STUDY_COMMANDS[self.command].reads_dataset and dataset is not None:
            given["dataset"] = str(dataset)
        return command_options(self.command, list(self.run_dirs), given)


def run_dir(results: Path, run: str, seed: int) -> Path:
    return Path(results) / "runs" / f"{run}-s{seed}"


def train_config(study, run: NamedRun, seed: int, dataset: Path, results: Path | None = None):
    """The config that trains ``run`` for training seed ``seed`` (a ``TrainConfig``, or a GCBC run's
    ``GCBCConfig``); a run from the learned prior samples it from :func:`prior_dir` under ``results``."""
    from bridgeplan import config as cfg
    from bridgeplan.processes import make_process

    t = study.training
    if run.trainer == "gcbc":
        from bridgeplan.gcbc import GCBCConfig

        return GCBCConfig(dataset=str(dataset), steps=t.steps, checkpoint_every=t.checkpoint_every, seed=seed,
                          **dict(run.fields))
    fields = dict(run.fields)
    process = make_process(fields.pop("process"), steps=t.diffusion_steps, **dict(fields.pop("params")))
    config = cfg.preset_config(study.dataset.maze, t.preset, **{**dict(t.overrides), **fields}, process=process,
                               dataset=str(dataset), steps=t.steps, checkpoint_every=t.checkpoint_every, seed=seed)
    if config.prior == "learned" and results is not None:
        config = cfg.replace(config, prior_run=str(prior_dir(results, prior_config(study, config))))
    return config


def prior_config(study, planner):
    """The learned prior of ``planner`` (a named run's ``TrainConfig``): the thesis's MLP trained on the same
    windows (maze, dataset, horizon, stride) for [training]'s ``prior_steps``, with the planner's seed; the runs of
    one plan shape and seed share it."""
    from bridgeplan import config as cfg

    return cfg.learned_prior_config(planner, study.training.prior_steps)


def prior_dir(results: Path, prior) -> Path:
    """Where the learned prior ``prior`` (a ``PriorTrainConfig``) is trained: beside the named runs, under its own
    name (a grid's priors are named the same way)."""
    return Path(results) / "runs" / prior.run_name()


def jobs(study, results: Path, out_root: Path, quick: bool) -> list[Job]:
    """Every JSON the study's evaluations write (under ``out_root``), with its command line; ``study`` at its scale
    (``plan.Scale.apply``), ``quick`` lowering the episodes."""
    from bridgeplan.evaluate import VALIDATION_SEED_OFFSET

    out = []
    for e in study.evaluations:
        for seed in e.seeds or study.training.seeds:
            for split in e.splits:
                base = seed if e.task_seed is None else e.task_seed
                eval_seed = base + (VALIDATION_SEED_OFFSET if split == "validation" else 0)
                for tasks in e.task_sets:
                    path = out_root / e.out.format(seed=seed, eval_seed=eval_seed, tasks=tasks)
                    args = dict(e.args)
                    episodes = args.pop("episodes", None) or study.evaluation.episodes
                    if quick:
                        cap = study.dataset.family.quick_episodes
                        episodes = cap if episodes is None else min(episodes, cap)
                    command = STUDY_COMMANDS[e.command]
                    if command.reads_dataset:
                        args.setdefault("maze", study.dataset.maze)
                    validation_tasks = study.dataset.family.validation_tasks
                    if (split == "validation" and validation_tasks and "tasks" not in args
                            and study.evaluation.validation == "other-tasks"):
                        args["tasks"] = ",".join(map(str, validation_tasks))  # not the test tasks, reseeded
                    args |= {**({"episodes": episodes} if episodes is not None else {}), command.seed: eval_seed,
                             **({"multi_task": True} if tasks == "multi" else {}), "threads": 1, "out": str(path)}
                    out.append(Job(path, tuple(str(run_dir(results, r, seed)) for r in e.runs),
                                   tuple(sorted(args.items())), seed, e.runs, e.command))
    return out


def needed_runs(study, results: Path, needed: set[tuple[str, int]] | None = None) -> list[tuple[str, int, int]]:
    """(run directory name, steps to train, steps done so far) of the named runs ``needed`` ((name, training seed)
    pairs; default: every one an evaluation needs) and of the learned priors they sample from."""
    from bridgeplan.experiments.runner import _trained_step

    if needed is None:
        needed = {(r, seed) for e in study.evaluations for seed in (e.seeds or study.training.seeds) for r in e.runs}
    runs = {r.name: r for r in study.runs}
    out = {}
    for name, seed in sorted(needed):
        directory = run_dir(results, name, seed)
        out[directory.name] = (study.training.steps, _trained_step(directory))
        config = train_config(study, runs[name], seed, Path("dataset"))
        if runs[name].trainer == "planner" and config.prior == "learned":
            prior = prior_dir(results, prior_config(study, config))
            out[prior.name] = (study.training.prior_steps, _trained_step(prior))
    return [(name, steps, done) for name, (steps, done) in out.items()]


def run_seed(study, results: Path, dataset: Path, todo: list[Job], seed: int, threads: int = 0,
             progress: bool = True) -> int:
    """Train (or finish) the runs ``todo`` needs for ``seed``, then run its commands (each at one torch thread, as
    its options say); the JSONs written."""
    from bridgeplan.device import configure_threads
    from bridgeplan.experiments.runner import train_to
    from bridgeplan.gcbc import train_gcbc
    from bridgeplan.train import train, train_prior

    configure_threads(threads or 1)
    one_line_warnings()  # as the CLI's, in a worker process too
    runs = {r.name: r for r in study.runs}
    for name in dict.fromkeys(r for job in todo for r in job.runs):
        config = train_config(study, runs[name], seed, dataset, results)
        if runs[name].trainer == "gcbc":
            train_to(train_gcbc, config, run_dir(results, name, seed), progress)
            continue
        if config.prior == "learned":
            train_to(train_prior, prior_config(study, config), Path(config.prior_run), progress)
        train_to(train, config, run_dir(results, name, seed), progress)
    written = 0
    for job in todo:
        if job.path.exists():  # another worker or sweep wrote it meanwhile
            continue
        doing(f"running `{job.command}` for {job.path}")
        run_job(job, dataset, progress)
        written += 1
    return written


def run_job(job: Job, dataset: Path, progress: bool) -> None:
    """Write ``job``'s JSON: its command's function on its options."""
    STUDY_COMMANDS[job.command].run(job.options(dataset, progress))


def work_units(todo: list[Job]) -> list[tuple[int, list[Job]]]:
    """The jobs grouped by training seed and the runs they read, in order: what one worker trains and evaluates. A
    run that two units read is trained once, under its lock (``train_to``), the other unit waiting for it."""
    units: dict[tuple[int, tuple[str, ...]], list[Job]] = {}
    for job in todo:
        units.setdefault((job.seed, job.runs), []).append(job)
    return [(seed, unit) for (seed, _), unit in units.items()]


def evaluation_units(study, results: Path, dataset: Path, quick: bool) -> list[Unit]:
    """Every missing JSON's work (after training what it needs), one unit per work unit (:func:`work_units`), for an
    :class:`Executor`."""
    units = work_units([job for job in jobs(study, results, results, quick) if not job.path.exists()])
    return [Unit(run_seed, (study, results, dataset, unit, seed),
                 f"the worker of training seed {seed} (runs: {', '.join(unit[0].runs) or 'none'})")
            for seed, unit in units]
