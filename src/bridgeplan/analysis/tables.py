"""Markdown tables and their cells: ``mean ± SE`` (one decimal), paired differences with a sign, verdicts.

The formats are those of the committed reports (findings.md, prior-curves.md, controllers.md): a table is a
header row, a ``|---|`` rule and rows ``| a | b |``; a mean over one seed prints its SE as ``nan``
(``one_seed="nan"``) or prints the mean alone (``one_seed="mean"``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from bridgeplan.analysis.stats import MeanSE, mean_se
from bridgeplan.errors import BridgeplanError

ONE_SEED = ("nan", "mean")


def fmt_mean_se(values: MeanSE | Iterable[float] | Mapping[int, float], one_seed: str = "nan",
                digits: int = 1) -> str:
    """``81.0 ± 1.9``; over one seed ``81.0 ± nan`` (``one_seed="nan"``) or ``81.0`` (``"mean"``)."""
    if one_seed not in ONE_SEED:
        raise BridgeplanError(f"one_seed must be one of {', '.join(ONE_SEED)}, got {one_seed!r}")
    m = values if isinstance(values, MeanSE) else mean_se(values)
    if m.n == 1 and one_seed == "mean":
        return f"{m.mean:.{digits}f}"
    return f"{m.mean:.{digits}f} ± {m.se:.{digits}f}"


def fmt_diff(d: MeanSE, digits: int = 1) -> str:
    """A paired difference, signed: ``+5.4 ± 1.0``, ``-9.4 ± 2.5``."""
    return f"{d.mean:+.{digits}f} ± {d.se:.{digits}f}"


def bold(text: str) -> str:
    return f"**{text}**"


def row(cells: Sequence[object]) -> str:
    """``| a | b | c |``."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


def rule(columns: int) -> str:
    """``|---|---|`` for ``columns`` columns."""
    return "|" + "---|" * columns


def table(header: Sequence[object], rows: Iterable[Sequence[object]]) -> list[str]:
    """A Markdown table's lines: the header, the rule, one line per row (each as long as the header)."""
    lines = [row(header), rule(len(header))]
    for cells in rows:
        if len(cells) != len(header):
            raise BridgeplanError(f"a table row has {len(cells)} cells for {len(header)} columns: {list(cells)}")
        lines.append(row(cells))
    return lines
