"""The controllers experiment's table (issue 13): each run executed by Diffuser's tracking controller and by pursuit
at each lookahead, open loop and replanned, per maze and task set, from the `controllers` rows (test episodes) of
docs/results/<maze>-v2-curves/results.csv (run_controllers.sh). Each cell: Minari score, mean ± standard error over
training seeds, and the success rate; in bold the lookahead the validation episodes (`controllers-validation`)
pick for that method and NFE, the one findings.md reports.

Usage: python docs/results/controllers_table.py > docs/results/controllers.md
"""

from __future__ import annotations

import sys

import numpy as np
from findings import MAZES, PURSUIT, choose, load

COLUMNS = ("", *PURSUIT)


def cell(by_seed: dict, bold: bool) -> str:
    scores = np.array([e.score for e in by_seed.values()])
    se = scores.std(ddof=1) / np.sqrt(len(scores)) if len(scores) > 1 else float("nan")
    text = f"{scores.mean():.1f} ± {se:.1f}"
    return (f"**{text}**" if bold else text) + f" ({np.mean([e.success for e in by_seed.values()]):.2f})"


def main() -> int:
    lines = ["# Executing plans: tracking against pursuit (issue 13)", "",
             "Made by `python docs/results/controllers_table.py` from the `controllers` rows of "
             "docs/results/<maze>-v2-curves/results.csv (run_controllers.sh): each run's final snapshot, 3 training "
             "seeds x 200 test episodes, Minari score mean ± standard error over seeds (success rate). `track`: "
             "Diffuser's controller; `pursuit R`: the plan's path at the expert's pace, toward the first planned "
             "position R away; bold: the lookahead the validation episodes pick; `replan32 pursuit 1`: a new plan "
             "every 32 steps (bridge and flow from the warm prior).", ""]
    for multi in (0, 1):
        lines += [f"## {'Multi2D' if multi else 'single-task'}", "",
                  "| maze | method | NFE | track | pursuit 0.5 | pursuit 1 | pursuit 1.5 | replan32 pursuit 1 |",
                  "|---|---|---|---|---|---|---|---|"]
        for maze in MAZES:
            table = load(maze)
            methods = sorted({key[0] for key in table if key != "validation" and key[1] == multi
                              and key[2] in PURSUIT and "hold" not in key[0]})
            for method in methods:
                by_step = table[(method, multi, "pursuit1")]
                step = max(by_step)
                for nfe in sorted(by_step[step]):
                    picked = choose(table, (method, nfe, PURSUIT), multi, step)
                    cells = []
                    for ex in COLUMNS:
                        by_seed = table.get((method, multi, ex), {}).get(step, {}).get(nfe)
                        cells.append(cell(by_seed, picked == (nfe, ex)) if by_seed else "-")
                    replan = [k for k in table if k[0] == method and k[1] == multi and k[2].startswith("replan32")
                              and k[2].endswith("pursuit1")]
                    by_seed = table[replan[0]].get(step, {}).get(nfe) if replan else None
                    cells.append(cell(by_seed, False) if by_seed else "-")
                    lines.append(f"| {maze} | {method} | {nfe} | " + " | ".join(cells) + " |")
        lines.append("")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
