"""Statistics over training seeds: mean ± standard error, paired per-seed differences, and verdicts.

The standard error is the sample standard deviation (``ddof=1``) over seeds divided by sqrt(n): the spread
of the per-seed means, which already contains the episode noise. With one seed it is undefined: NaN (tables
print ``nan`` or the mean alone, :mod:`bridgeplan.analysis.tables`), and no verdict is given on it.

A verdict compares a paired difference (first minus second) with ``k`` standard errors (2 by default):
:func:`compare` says ``better`` when the mean is more than k SE above zero, ``worse`` when more than k SE
below, ``tie`` in between. The findings' and the goal's words are that rule read for a claim
(:func:`finding_verdict`, :func:`goal_verdict`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from bridgeplan.errors import BridgeplanError, check_choice

K_SE = 2.0
"""Standard errors a difference has to clear for a verdict other than ``tie``."""


@dataclass(frozen=True)
class MeanSE:
    """Mean and standard error over ``n`` seeds (``se`` NaN when ``n`` is 1)."""

    mean: float
    se: float
    n: int


@dataclass(frozen=True)
class Paired(MeanSE):
    """Mean ± standard error of per-seed differences, first minus second, over the ``seeds`` both have."""

    seeds: tuple[int, ...] = ()


def mean_se(values: Iterable[float] | Mapping[int, float]) -> MeanSE:
    """Mean and standard error of ``values`` (a mapping: its values, e.g. ``{seed: score}``)."""
    v = np.array(list(values.values() if isinstance(values, Mapping) else values), dtype=float)
    if len(v) == 0:
        raise BridgeplanError("mean ± standard error of no values")
    se = float(v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else float("nan")
    return MeanSE(float(v.mean()), se, len(v))


def paired(a: Mapping[int, float], b: Mapping[int, float], seeds: str = "same") -> Paired:
    """Per-seed differences ``a[s] - b[s]`` matched by seed, their mean ± standard error.

    ``seeds="same"``: ``a`` and ``b`` must have the same seeds (else :class:`BridgeplanError` naming the seeds
    one side lacks); ``"common"``: the seeds both have (at least one), the rest left out, as when a series of
    5 seeds is compared with one of 3.
    """
    if seeds not in ("same", "common"):
        raise BridgeplanError(f"seeds must be 'same' or 'common', got {seeds!r}")
    if seeds == "same" and set(a) != set(b):
        raise BridgeplanError(f"paired difference over mismatched seeds: only the first has {sorted(set(a) - set(b))}, "
                              f"only the second {sorted(set(b) - set(a))} (seeds='common' pairs the shared ones)")
    both = sorted(set(a) & set(b))
    if not both:
        raise BridgeplanError("paired difference: the two series share no seed")
    d = mean_se([a[s] - b[s] for s in both])
    return Paired(d.mean, d.se, d.n, tuple(both))


def compare(d: MeanSE, k: float = K_SE) -> str:
    """``better`` (mean - k SE > 0), ``worse`` (mean + k SE < 0) or ``tie``; a verdict needs 2 seeds or more."""
    if d.n < 2:
        raise BridgeplanError(f"a verdict needs at least 2 seeds, got {d.n}")
    return "better" if d.mean - k * d.se > 0 else "worse" if d.mean + k * d.se < 0 else "tie"


FINDING_RULES = ("above", "not below")


def finding_verdict(d: MeanSE, rule: str, k: float = K_SE) -> str:
    """A finding's verdict (findings.md). ``above`` (the first beats the second): ``holds`` when better,
    ``does not`` when worse, ``not decidable`` when a tie; ``not below`` (the first keeps the second's score):
    ``holds`` unless worse (not more than k SE below), else ``does not``."""
    check_choice("finding rule", rule, FINDING_RULES)
    verdict = compare(d, k)
    if rule == "above":
        return {"better": "holds", "worse": "does not", "tie": "not decidable"}[verdict]
    return "does not" if verdict == "worse" else "holds"


GOAL_RULES = ("reaches", "clears")


def goal_verdict(d: MeanSE, rule: str, k: float = K_SE) -> str:
    """The goal's words (prior-curves.md). ``reaches``: ``yes`` when the mean is not below zero, ``within noise``
    when below by no more than k SE, ``no`` when worse; ``clears``: ``yes`` when better, else ``no``."""
    check_choice("goal rule", rule, GOAL_RULES)
    verdict = compare(d, k)
    if rule == "reaches":
        return "yes" if d.mean >= 0 else "within noise" if verdict != "worse" else "no"
    return "yes" if verdict == "better" else "no"
