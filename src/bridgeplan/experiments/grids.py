"""The thesis's experiments as declared grids (thesis, chapter "Experiments"; its five figures).

An experiment is a set of series, each one line in its figure: a trained run (a process with its
parameters, and a prior) sampled at one NFE, scored at every training-step snapshot. Two
experiments that name the same run share its training.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from bridgeplan.config import check_prior
from bridgeplan.errors import BridgeplanError
from bridgeplan.processes import DDPM, Bridge, Process


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


@dataclass(frozen=True)
class Experiment:
    name: str
    title: str
    series: tuple[Series, ...]

    def runs(self) -> list[RunSpec]:
        return list(dict.fromkeys(s.run for s in self.series))

    def validate(self) -> None:
        for s in self.series:
            if not 1 <= s.nfe <= s.run.process.max_nfe:
                raise BridgeplanError(f"experiment {self.name}: series {s.label!r} asks NFE {s.nfe}, but "
                                      f"{s.run.label()} with {s.run.process.steps} steps allows "
                                      f"1..{s.run.process.max_nfe}")


def build_experiments(steps: int = 16, fixed_nfe: int = 4, bridge: Bridge | None = None) -> dict[str, Experiment]:
    """The five experiments for runs of ``steps`` diffusion steps; ``bridge`` gives the bridge's other
    parameters (beta_max, ot_ode, ...; default: the ``Bridge`` defaults)."""
    ddpm = RunSpec(DDPM(steps))
    bridge = dataclasses.replace(bridge or Bridge(), steps=steps)
    bridges = {p: RunSpec(bridge, p) for p in ("gaussian", "line", "learned")}
    noise, same_nfe = bridges["gaussian"], bridge.max_nfe
    return {e.name: e for e in [
        Experiment("bridge-vs-ddpm", f"Bridge vs DDPM from Gaussian noise, N={steps}, NFE={same_nfe}",
                   (Series("DDPM", ddpm, same_nfe), Series(noise.label(), noise, same_nfe))),
        Experiment("ddpm-steps", "DDPM trained with 1, 4, 7, 10 diffusion steps (NFE = steps)",
                   tuple(Series(f"DDPM N={n}", RunSpec(DDPM(n)), n) for n in (1, 4, 7, 10))),
        Experiment("bridge-nfe", f"Bridge (gaussian prior), N={steps}, across NFE",
                   tuple(Series(f"NFE {k}", noise, k) for k in (1, 4, 7, 10, same_nfe))),
        Experiment("priors", f"Bridge from each prior, N={steps}, NFE={fixed_nfe}",
                   tuple(Series(r.label(), r, fixed_nfe) for r in bridges.values())),
        Experiment("nfe1", f"Bridge from each prior vs DDPM at NFE=1, N={steps}",
                   (Series("DDPM", ddpm, 1), *(Series(r.label(), r, 1) for r in bridges.values()))),
    ]}


EXPERIMENTS = build_experiments()


def get_experiment(name: str, steps: int = 16, fixed_nfe: int = 4, bridge: Bridge | None = None) -> Experiment:
    """The experiment ``name`` for runs trained with ``steps`` diffusion steps."""
    if name not in EXPERIMENTS:
        raise BridgeplanError(f"unknown experiment {name!r}: choose from {', '.join(EXPERIMENTS)}")
    experiment = build_experiments(steps, fixed_nfe, bridge)[name]
    experiment.validate()
    return experiment
