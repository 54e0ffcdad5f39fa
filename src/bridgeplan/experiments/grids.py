"""The thesis's experiments as declared grids (thesis, chapter "Experiments"; its five figures), and ours.

An experiment is a set of series, each one line in its figure: a trained run (a process with its
parameters, and a prior) sampled at one NFE by one of its samplers and executed one way (open loop, or
replanned) on single- or multi-task episodes, scored at every training-step snapshot (or the last one). Two
experiments that name the same run share its training.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from bridgeplan.config import check_prior
from bridgeplan.consistency import Correction, sampling_tag
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.processes import DDPM, Bridge, Process
from bridgeplan.replan import Execution


@dataclass(frozen=True)
class RunSpec:
    """What distinguishes one trained run inside a sweep: the process (with its parameters) and the prior."""

    process: Process
    prior: str = "gaussian"

    def __post_init__(self):
        check_prior(self.process, self.prior)

    def label(self) -> str:
        return self.process.label(self.prior)


@dataclass(frozen=True)
class Series:
    label: str
    run: RunSpec
    nfe: int
    execution: Execution = Execution()
    """How its plans are executed (default: open loop, one plan per episode)."""
    multi_task: bool = False
    """Multi2D tasks (random goals) instead of the maze's single evaluation goal."""
    sampler: str | None = None
    """One of the run's process's samplers (``Process.with_sampler``); None: the one it was trained with."""
    correction: Correction | None = None
    """A consistency correction of every x0 prediction (CDDB, ``Planner.with_correction``); None: uncorrected."""

    @property
    def process(self) -> Process:
        """The run's process as this series samples it."""
        return self.run.process if self.sampler is None else self.run.process.with_sampler(self.sampler)

    def sampling_tag(self) -> str:
        """The store's ``sampler`` of this series' rows (``consistency.sampling_tag``: the sampler and the
        correction), as ``EvalResult.sampling_tag`` writes it: the runner's and the study plan's "missing" key."""
        return sampling_tag(self.process.sampling_tag(), self.correction)


@dataclass(frozen=True)
class Experiment:
    name: str
    title: str
    series: tuple[Series, ...]
    last_snapshot_only: bool = False
    """Evaluate only each run's final snapshot (a comparison at one budget, not a curve over training)."""

    def runs(self) -> list[RunSpec]:
        return list(dict.fromkeys(s.run for s in self.series))

    def validate(self) -> None:
        for s in self.series:
            if s.sampler is not None and s.sampler not in s.run.process.usable_samplers():
                raise BridgeplanError(f"experiment {self.name}: series {s.label!r} asks sampler {s.sampler!r}, but "
                                      f"{s.run.label()} has {', '.join(s.run.process.usable_samplers()) or 'one'}")
            if s.correction is not None and not s.run.process.predicts_x0:
                raise BridgeplanError(f"experiment {self.name}: series {s.label!r} asks a correction of x0 "
                                      f"predictions, but {s.run.label()} does not sample through them")
            if not 1 <= s.nfe <= s.run.process.max_nfe:
                raise BridgeplanError(f"experiment {self.name}: series {s.label!r} asks NFE {s.nfe}, but "
                                      f"{s.run.label()} with {s.run.process.steps} steps allows "
                                      f"1..{s.run.process.max_nfe}")


def build_experiments(steps: int = 16, fixed_nfe: int = 4, informed: Process | None = None) -> dict[str, Experiment]:
    """The five experiments for runs of ``steps`` diffusion steps. ``informed`` is the process run from
    each prior against DDPM, with its parameters (default: the thesis's bridge, ``Bridge()``); the
    experiments keep the thesis's names."""
    informed = dataclasses.replace(informed or Bridge(), steps=steps)
    if not informed.uses_prior:
        raise BridgeplanError(f"the experiments compare DDPM with a process that starts from a prior; "
                              f"{informed.name} does not")
    name = informed.display_name
    ddpm = RunSpec(DDPM(steps))
    runs = {p: RunSpec(informed, p) for p in ("gaussian", "line", "learned")}
    noise, same_nfe = runs["gaussian"], informed.max_nfe
    return {e.name: e for e in [
        Experiment("demo", f"DDPM vs {name} from the straight-line prior at the full NFE and at NFE 1, N={steps} "
                   "(`bridgeplan demo`)",
                   tuple(Series(r.label(), r, k) for r in (ddpm, runs["line"]) for k in (r.process.max_nfe, 1))),
        Experiment("bridge-vs-ddpm", f"{name} vs DDPM from Gaussian noise, N={steps}, NFE={same_nfe}",
                   (Series("DDPM", ddpm, same_nfe), Series(noise.label(), noise, same_nfe))),
        Experiment("ddpm-steps", "DDPM trained with 1, 4, 7, 10 diffusion steps (NFE = steps)",
                   tuple(Series(f"DDPM N={n}", RunSpec(DDPM(n)), n) for n in (1, 4, 7, 10))),
        Experiment("bridge-nfe", f"{name} (gaussian prior), N={steps}, across NFE",
                   tuple(Series(f"NFE {k}", noise, k) for k in sorted({1, 4, 7, 10, same_nfe}) if k <= same_nfe)),
        Experiment("priors", f"{name} from each prior, N={steps}, NFE={fixed_nfe}",
                   tuple(Series(r.label(), r, fixed_nfe) for r in runs.values())),
        Experiment("nfe1", f"{name} from each prior vs DDPM at NFE=1, N={steps}",
                   (Series("DDPM", ddpm, 1), *(Series(r.label(), r, 1) for r in runs.values()))),
        Experiment("nfe-curves", f"DDPM and {name} from the line prior at NFE 1, 2, 4 and full, N={steps}",
                   tuple(Series(f"{r.label()} NFE {k}", r, k) for r in (ddpm, runs["line"])
                         for k in sorted({1, 2, 4, r.process.max_nfe}) if k <= r.process.max_nfe)),
        Experiment("prior-curves", f"{name} from each prior at NFE 1, 2, 4 and full, N={steps}",
                   tuple(Series(f"{r.label()} NFE {k}", r, k) for r in runs.values()
                         for k in sorted({1, 2, 4, r.process.max_nfe}) if k <= r.process.max_nfe)),
        Experiment("samplers", f"DDPM and {name} from the line prior at NFE 1, and at 2, 4 and full by each "
                   f"of their samplers, N={steps}",
                   tuple(s for r in (ddpm, runs["line"]) for s in sampler_series(r))),
        Experiment("closed-loop", f"DDPM and {name} from the line prior, open loop and replanned every "
                   f"{REPLAN_EVERY} steps, single-task and Multi2D, at the final snapshot, N={steps}",
                   tuple(s for r in (ddpm, runs["line"]) for multi in (False, True)
                         for s in closed_loop_series(r, multi)), last_snapshot_only=True),
        Experiment("controllers", f"DDPM and {name} from the line prior, open loop at NFE 1 and full, tracked "
                   f"(Diffuser's controller) and pursued (lookahead {', '.join(f'{r:g}' for r in LOOKAHEADS)}), and "
                   f"replanned every {REPLAN_EVERY} steps pursued, single-task and Multi2D, at the final snapshot, "
                   f"N={steps}",
                   tuple(s for r in (ddpm, runs["line"]) for multi in (False, True)
                         for s in controller_series(r, multi)), last_snapshot_only=True),
    ]}


def sampler_series(run: RunSpec) -> list[Series]:
    """One run's series in the samplers experiment: NFE 1 as trained (one call: every sampler lands on the
    network's x0 prediction), and NFE 2, 4 and full by each sampler the process has."""
    process = run.process
    return ([Series(f"{run.label()} NFE 1", run, 1)]
            + [Series(f"{run.label()} NFE {k} {sampler}", run, k, sampler=sampler)
               for k in sorted({2, 4, process.max_nfe}) if k <= process.max_nfe
               for sampler in process.usable_samplers() or (None,)])


REPLAN_EVERY = 32
"""Steps between replans in the closed-loop experiment (10 / 19 / 25 plans per umaze / medium / large episode)."""


def closed_loop_series(run: RunSpec, multi_task: bool) -> list[Series]:
    """One run's series in the closed-loop experiment: open loop at NFE 1 and at the most NFE (Diffuser's
    protocol: the matched-calls baseline of a replanner), and replanned at NFE 1 with the arrival as sampled
    (truncated) and kept to the first plan's (``keep``); processes with a prior replan from the warm prior."""
    warm = run.process.uses_prior
    task = " Multi2D" if multi_task else ""
    replans = [Execution(replan_every=REPLAN_EVERY, warm=warm),
               Execution(replan_every=REPLAN_EVERY, warm=warm, arrival="keep")]
    return ([Series(f"{run.label()} NFE {k} open loop{task}", run, k, multi_task=multi_task)
             for k in sorted({1, run.process.max_nfe})]
            + [Series(f"{run.label()} NFE 1 {ex.tag()}{task}", run, 1, ex, multi_task) for ex in replans])


LOOKAHEADS = (0.5, 1.0, 1.5)
"""Pursuit lookaheads of the controllers experiment (maze units): one is chosen on validation episodes."""


def controller_series(run: RunSpec, multi_task: bool) -> list[Series]:
    """One run's series in the controllers experiment: open loop at NFE 1 and the most NFE with Diffuser's
    tracking controller and with pursuit at each of :data:`LOOKAHEADS`; replanned every ``REPLAN_EVERY`` steps
    at NFE 1 with pursuit (lookahead 1; processes with a prior from the warm prior)."""
    task = " Multi2D" if multi_task else ""
    open_loop = [Execution()] + [Execution(controller="pursuit", lookahead=r) for r in LOOKAHEADS]
    replanned = Execution(replan_every=REPLAN_EVERY, warm=run.process.uses_prior, controller="pursuit",
                          lookahead=1.0)
    return ([Series(f"{run.label()} NFE {k} {ex.tag() or 'track'}{task}", run, k, ex, multi_task)
             for k in sorted({1, run.process.max_nfe}) for ex in open_loop]
            + [Series(f"{run.label()} NFE 1 {replanned.tag()}{task}", run, 1, replanned, multi_task)])


EXPERIMENTS = build_experiments()


def get_experiment(name: str, steps: int = 16, fixed_nfe: int = 4, informed: Process | None = None) -> Experiment:
    """The experiment ``name`` for runs trained with ``steps`` diffusion steps (see :func:`build_experiments`)."""
    check_choice("experiment", name, EXPERIMENTS)
    experiment = build_experiments(steps, fixed_nfe, informed)[name]
    experiment.validate()
    return experiment
