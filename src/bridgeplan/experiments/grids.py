"""The thesis's experiments as declared grids (REFERENCE §4).

An experiment is a set of series, each one line in its figure: a trained run (process, prior,
diffusion steps) sampled at one NFE, scored at every training-step snapshot. Two experiments
that name the same run share its training.
"""

from __future__ import annotations

from dataclasses import dataclass

from bridgeplan.errors import BridgeplanError


@dataclass(frozen=True)
class RunSpec:
    """What distinguishes one trained run inside a sweep."""

    process: str
    prior: str = "gaussian"
    diffusion_steps: int = 16

    @property
    def max_nfe(self) -> int:
        # the bridge walks N-1 jumps from the prior to step 0; DDPM has one call per step
        return self.diffusion_steps - 1 if self.process == "bridge" else self.diffusion_steps

    def label(self) -> str:
        return "DDPM" if self.process == "ddpm" else f"bridge ({self.prior})"


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
            if not 1 <= s.nfe <= s.run.max_nfe:
                raise BridgeplanError(f"experiment {self.name}: series {s.label!r} asks NFE {s.nfe}, but "
                                      f"{s.run.label()} with {s.run.diffusion_steps} steps allows 1..{s.run.max_nfe}")


def build_experiments(steps: int = 16, fixed_nfe: int = 4) -> dict[str, Experiment]:
    ddpm = RunSpec("ddpm", "gaussian", steps)
    bridges = {p: RunSpec("bridge", p, steps) for p in ("gaussian", "line", "learned")}
    same_nfe = steps - 1
    return {e.name: e for e in [
        Experiment("bridge-vs-ddpm", f"Bridge vs DDPM from Gaussian noise, N={steps}, NFE={same_nfe}",
                   (Series("DDPM", ddpm, same_nfe), Series("bridge (gaussian)", bridges["gaussian"], same_nfe))),
        Experiment("ddpm-steps", "DDPM trained with 1, 4, 7, 10 diffusion steps (NFE = steps)",
                   tuple(Series(f"DDPM N={n}", RunSpec("ddpm", "gaussian", n), n) for n in (1, 4, 7, 10))),
        Experiment("bridge-nfe", f"Bridge (gaussian prior), N={steps}, across NFE",
                   tuple(Series(f"NFE {k}", bridges["gaussian"], k) for k in (1, 4, 7, 10, same_nfe))),
        Experiment("priors", f"Bridge from each prior, N={steps}, NFE={fixed_nfe}",
                   tuple(Series(f"bridge ({p})", r, fixed_nfe) for p, r in bridges.items())),
        Experiment("nfe1", f"Bridge from each prior vs DDPM at NFE=1, N={steps}",
                   (Series("DDPM", ddpm, 1), *(Series(f"bridge ({p})", r, 1) for p, r in bridges.items()))),
    ]}


EXPERIMENTS = build_experiments()


def get_experiment(name: str, steps: int = 16, fixed_nfe: int = 4) -> Experiment:
    """The experiment ``name`` for runs trained with ``steps`` diffusion steps."""
    if name not in EXPERIMENTS:
        raise BridgeplanError(f"unknown experiment {name!r}: choose from {', '.join(EXPERIMENTS)}")
    experiment = build_experiments(steps, fixed_nfe)[name]
    experiment.validate()
    return experiment
