"""Analysis of committed results: rows with structured method keys, statistics over seeds, choices on
validation episodes, Markdown tables.

- :mod:`~bridgeplan.analysis.keys`: :class:`MethodKey` (what was trained, how it was sampled and executed, on
  which task set), :func:`method` to name one, :func:`label` / :func:`describe` to render one,
  :func:`parse_execution` (the one place an execution tag is read back);
- :mod:`~bridgeplan.analysis.load`: :class:`Row`, :func:`read_csv` (every committed CSV schema),
  :func:`read_eval_json`, :class:`Results` (rows by key, split, step, NFE, seed), :class:`Point`;
- :mod:`~bridgeplan.analysis.stats`: :func:`mean_se`, :func:`paired`, :func:`compare` and the verdict words;
- :mod:`~bridgeplan.analysis.selection`: :func:`best` (a choice on a split), :class:`Choice`, :func:`resolve`;
- :mod:`~bridgeplan.analysis.tables`: ``mean ± SE`` cells and Markdown tables.
"""

from bridgeplan.analysis.keys import OPEN_LOOP, MethodKey, describe, label, method, parse_execution, tasks_label
from bridgeplan.analysis.load import Point, Results, Row, load_csvs, read_csv, read_eval_json
from bridgeplan.analysis.selection import BEST, FULL, Choice, best, resolve
from bridgeplan.analysis.stats import MeanSE, Paired, compare, finding_verdict, goal_verdict, mean_se, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, table

__all__ = ["BEST", "FULL", "OPEN_LOOP", "Choice", "MeanSE", "MethodKey", "Paired", "Point", "Results", "Row", "best",
           "compare", "describe", "finding_verdict", "fmt_diff", "fmt_mean_se", "goal_verdict", "label", "load_csvs",
           "mean_se", "method", "paired", "parse_execution", "read_csv", "read_eval_json", "resolve", "table",
           "tasks_label"]
