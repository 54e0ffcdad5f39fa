"""The controllers experiment's table (issue 13): each run executed by Diffuser's tracking controller and by pursuit
at each lookahead, open loop and replanned, per maze and task set, from the `controllers` rows (test episodes) of
docs/results/<maze>-v2-curves/results.csv (studies/<maze>-v2-curves.toml). Each cell: Minari score, mean ±
standard error over training seeds, and the success rate; in bold the lookahead the validation episodes
(`controllers-validation`) pick for that method and NFE, the one findings.md reports.

Made by `bridgeplan study report controllers` (studies/controllers.toml) into docs/results/controllers.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridgeplan.analysis.keys import OPEN_LOOP, label
from bridgeplan.analysis.keys import method as method_key
from bridgeplan.analysis.load import Point, Results, Row, load_csvs
from bridgeplan.analysis.selection import Choice, resolve
from bridgeplan.analysis.tables import bold, fmt_mean_se
from bridgeplan.replan import Execution

MAZES = ("umaze", "medium", "large")
STORES = ("curves", "hold", "consistent-priors")
"""The maze's stores (docs/results/<maze>-v2-<store>), in order of precedence (as the findings report's)."""
PURSUIT = tuple(Execution(controller="pursuit", lookahead=r) for r in (0.5, 1, 1.5))
"""The open-loop pursuit executions of the controllers experiment; the validation episodes pick one."""
COLUMNS = (OPEN_LOOP, *PURSUIT)
READS = (method_key("ddpm", steps=16), method_key("bridge", "line", steps=16))
"""The trained methods every maze's rows have (flow matching's are shown where a store has them)."""
REPLAN = 32


def cell(rows: dict[int, Row], chosen: bool) -> str:
    text = fmt_mean_se([e.score for e in rows.values()])
    return (bold(text) if chosen else text) + f" ({np.mean([e.success for e in rows.values()]):.2f})"


def replanned(execution: Execution) -> bool:
    """Replanned every 32 steps and pursued at lookahead 1 (from the warm prior or not)."""
    return execution.replan_every == REPLAN and execution.controller == "pursuit" and execution.lookahead == 1


def maze_rows(results: Results, maze: str, multi: int) -> list[str]:
    pursued = [key for key in results.keys() if key.multi_task == bool(multi) and key.execution in PURSUIT
               and not key.hold_share]
    methods = sorted({key.replace(execution=OPEN_LOOP) for key in pursued}, key=label)
    lines = []
    for method in methods:
        pursuit1 = method.replace(execution=PURSUIT[1])
        step = results.steps(pursuit1)[-1]
        for nfe in sorted(results.nfes(pursuit1, step)):
            picked = resolve(results, Choice(method, nfe, among=PURSUIT), step)
            cells = []
            for ex in COLUMNS:
                point = Point(method.replace(execution=ex), step, nfe)
                rows = results.rows(point)
                cells.append(cell(rows, picked == point) if rows else "-")
            replan = [key for key in results.keys() if key.replace(execution=OPEN_LOOP) == method
                      and replanned(key.execution)]
            rows = results.rows(Point(replan[0], step, nfe)) if replan else {}
            cells.append(cell(rows, False) if rows else "-")
            lines.append(f"| {maze} | {label(method)} | {nfe} | " + " | ".join(cells) + " |")
    return lines


def render(root: Path) -> str:
    """controllers.md's text, from the committed results under ``root`` (docs/results)."""
    lines = ["# Executing plans: tracking against pursuit (issue 13)", "",
             "Made by `bridgeplan study report controllers` from the `controllers` rows of "
             "docs/results/<maze>-v2-curves/results.csv (studies/<maze>-v2-curves.toml): each run's final snapshot, "
             "3 training seeds x 200 test episodes, Minari score mean ± standard error over seeds (success rate). "
             "`track`: "
             "Diffuser's controller; `pursuit R`: the plan's path at the expert's pace, toward the first planned "
             "position R away; bold: the lookahead the validation episodes pick; `replan32 pursuit 1`: a new plan "
             "every 32 steps (bridge and flow from the warm prior).", ""]
    results = {maze: load_csvs((root / f"{maze}-v2-{store}" / "results.csv" for store in STORES),
                               experiments={"controllers", "controllers-validation"}) for maze in MAZES}
    for multi in (0, 1):
        lines += [f"## {'Multi2D' if multi else 'single-task'}", "",
                  "| maze | method | NFE | track | pursuit 0.5 | pursuit 1 | pursuit 1.5 | replan32 pursuit 1 |",
                  "|---|---|---|---|---|---|---|---|"]
        for maze in MAZES:
            lines += maze_rows(results[maze], maze, multi)
        lines.append("")
    return "\n".join(lines)

