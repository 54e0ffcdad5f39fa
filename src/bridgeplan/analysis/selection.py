"""Choosing a setting on one set of episodes and reporting it on another.

A setting is a :class:`~bridgeplan.analysis.load.Point` (method key with its execution, snapshot step, NFE).
:func:`best` picks, among candidate points, the one with the best mean over seeds on a split: on the
``validation`` split it is a choice declared before the test episodes are read; on ``test`` it is the best on
the reported episodes themselves (a bar raised for the method compared with it). Ties go to the first
candidate given.

:class:`Choice` is a series a comparison names: a fixed NFE, or ``full`` (the most NFE evaluated), or
``best`` (chosen on validation), and optionally executions to choose among on validation (the lookahead of
pursuit, say); :func:`resolve` turns it into the point whose test rows a table reports.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from bridgeplan.analysis.keys import MethodKey
from bridgeplan.analysis.load import Point, Results
from bridgeplan.errors import BridgeplanError
from bridgeplan.replan import Execution

FULL, BEST = "full", "best"


def split_mean(results: Results, point: Point, split: str) -> float:
    """Mean score over seeds at ``point`` on ``split`` (NaN when nothing was evaluated there)."""
    scores = results.values(point, split)
    return float(np.mean(list(scores.values()))) if scores else float("nan")


def best(results: Results, candidates: Iterable[Point], split: str = "validation") -> Point | None:
    """The candidate with the best mean score over seeds on ``split``, among those evaluated there (the first of
    equal ones); None when none was."""
    measured = [p for p in candidates if results.rows(p, split)]
    return max(measured, key=lambda p: split_mean(results, p, split)) if measured else None


@dataclass(frozen=True)
class Choice:
    """A series named by a comparison: ``method`` (its execution and task set included) at ``nfe``: a number,
    :data:`FULL` (the most NFE evaluated at the step) or :data:`BEST` (chosen on the validation episodes);
    ``among``: executions to choose among on the validation episodes (``method``'s execution is then ignored),
    None for ``method``'s own."""

    method: MethodKey
    nfe: int | str
    among: tuple[Execution, ...] | None = None

    def __post_init__(self):
        if not isinstance(self.nfe, int) and self.nfe not in (FULL, BEST):
            raise BridgeplanError(f"nfe must be a number, {FULL!r} or {BEST!r}, got {self.nfe!r}")

    @property
    def chooses(self) -> bool:
        """True when the series is chosen on validation episodes (its NFE or its execution)."""
        return self.nfe == BEST or self.among is not None

    def keys(self) -> list[MethodKey]:
        """The method keys the series may take its rows from."""
        if self.among is None:
            return [self.method]
        return [self.method.replace(execution=ex) for ex in self.among]


def candidates(results: Results, choice: Choice, step: int) -> list[Point]:
    """The points ``choice`` may stand for at ``step``, among those evaluated on the test episodes."""
    out = []
    for key in choice.keys():
        nfes = results.nfes(key, step)
        if choice.nfe == BEST:
            picks = nfes
        elif choice.nfe == FULL:
            picks = [max(nfes)] if nfes else []
        else:
            picks = [choice.nfe] if choice.nfe in nfes else []
        out += [Point(key, step, nfe) for nfe in picks]
    return out


def resolve(results: Results, choice: Choice, step: int) -> Point | None:
    """The point ``choice`` stands for at ``step``: the one candidate when nothing is chosen, else the candidate
    with the best mean on the validation episodes; None when there is none (or none was validated)."""
    options = candidates(results, choice, step)
    if not choice.chooses and len(options) <= 1:
        return options[0] if options else None
    return best(results, options, "validation")


def steps(results: Results, choice: Choice) -> set[int]:
    """The steps at which any of ``choice``'s keys was evaluated on the test episodes."""
    return {step for key in choice.keys() for step in results.steps(key)}
