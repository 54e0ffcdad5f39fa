"""OGBench pointmaze navigate: bridgeplan's planners by OGBench's protocol, beside the straight line alone, the
oracle and the published methods.

Rows: ``bridgeplan ogbench eval --json`` outputs in docs/results/ogbench-<maze>-navigate/<run>/ (one per run,
controller and evaluation seed). The test episodes are evaluation seed :data:`TEST_SEED` (the protocol's 5 tasks x
50 episodes); the controller (Diffuser-style tracking in time, or pursuit of the plan's path) is chosen per method
on the validation episodes, seed :data:`VALIDATION_SEED`, and reported on the test ones. Success is OGBench's
``overall_success`` (the mean of the 5 task rates), in %, mean ± standard error over training seeds; the line
alone is the same episodes planned by the straight line, no network, executed by the same controller.

Made by `bridgeplan study report ogbench-planners` (studies/ogbench-planners.toml) into
docs/results/ogbench-planners.md.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bridgeplan.analysis.stats import mean_se
from bridgeplan.analysis.tables import bold, fmt_mean_se, table

READS = ()
"""Its rows are the protocol's JSONs, not a Maze2D store."""
MAZES = ("medium", "large", "giant")
"""The mazes whose folders the report reads (a maze without rows is left out)."""
TEST_SEED, VALIDATION_SEED = 0, 1000
ORACLE = "ogbench-oracle"
PUBLISHED = {"medium": {"GCBC": 9, "QRL": 82, "SAW": 97}, "large": {"GCBC": 29, "QRL": 86, "SAW": 85},
             "giant": {"GCBC": 1, "QRL": 68, "SAW": 68}}
"""Published navigate success (%): GCBC and QRL from OGBench (Park et al., ICLR 2025), SAW from its paper, as
reprinted in later papers; 8 seeds at 1 M steps."""


def folder(maze: str) -> str:
    return f"ogbench-{maze}-navigate"


def read_rows(root: Path, maze: str) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((root / folder(maze)).glob("*/*.json"))]


def method_of(row: dict) -> str:
    return f"{row['method']}, NFE {row['nfe']}"


def controller_of(row: dict) -> str:
    ex = row["execution"]
    name = ex["controller"] + (f" {ex['lookahead']:g}" if ex.get("lookahead") else "")
    name += f", replan {ex['replan_every']}" if ex.get("replan_every") else ""
    return name + (f", high level every {row['replan_high_every']}" if row.get("replan_high_every") else "")


def by_seed(rows: list[dict], method: str, controller: str, seed: int, value) -> dict[int, float]:
    return {r["config"]["seed"]: value(r) for r in rows
            if method_of(r) == method and controller_of(r) == controller and r["seed"] == seed}


def success(r: dict) -> float:
    return 100 * r["success_rate"]


def floor(r: dict) -> float:
    return 100 * r["floor_line"]["success_rate"]


def cell(values: dict[int, float]) -> str:
    return fmt_mean_se(values, one_seed="mean") if values else "-"


def choose(rows: list[dict], methods: list[str], controllers: list[str]) -> dict[str, str | None]:
    """Per method, the controller with the best mean success over training seeds on the validation episodes."""
    out = {}
    for m in methods:
        validation = {c: by_seed(rows, m, c, VALIDATION_SEED, success) for c in controllers}
        measured = [c for c in controllers if validation[c]]
        out[m] = max(measured, key=lambda c: np.mean(list(validation[c].values()))) if measured else None
    return out


def goal_lines(rows: list[dict], maze: str, methods: list[str], chosen: dict[str, str | None]) -> list[str]:
    """Per method, its chosen setting's test success against each published method (above at two standard errors)."""
    lines = []
    for m in methods:
        c = chosen[m]
        test = by_seed(rows, m, c, TEST_SEED, success) if c else {}
        if len(test) < 2:
            continue
        s = mean_se(test)
        above = ", ".join(f"{name} {value}: {'yes' if s.mean - 2 * s.se > value else 'no'}"
                          for name, value in PUBLISHED.get(maze, {}).items())
        lines.append(f"- pointmaze-{maze}-navigate-v0, {m}, {c} (chosen on validation): {fmt_mean_se(test)}% "
                     f"over {len(test)} training seeds; above at two standard errors: {above}")
    return lines


def block(root: Path) -> str:
    """The README's lines: each method's chosen setting against the published methods."""
    lines = []
    for maze in MAZES:
        rows = read_rows(Path(root), maze)
        methods = sorted({method_of(r) for r in rows})
        lines += goal_lines(rows, maze, methods, choose(rows, methods, sorted({controller_of(r) for r in rows})))
    return "\n".join(lines)


def maze_lines(root: Path, maze: str) -> list[str]:
    rows = read_rows(root, maze)
    if not rows:
        return []
    methods = sorted({method_of(r) for r in rows})
    controllers = sorted({controller_of(r) for r in rows})
    body, chosen = [], choose(rows, methods, controllers)
    for m in methods:
        validation = {c: by_seed(rows, m, c, VALIDATION_SEED, success) for c in controllers}
        for c in controllers:
            test = by_seed(rows, m, c, TEST_SEED, success)
            if not test:
                continue
            tasks = [cell(by_seed(rows, m, c, TEST_SEED, lambda r, i=i: 100 * r["tasks"][str(i)]["success_rate"]))
                     for i in range(1, 6)]
            ms = by_seed(rows, m, c, TEST_SEED, lambda r: r["decision_ms_batch1"]["p50"])
            body.append([m, bold(c) if c == chosen[m] else c,
                         cell(validation[c]), bold(cell(test)) if c == chosen[m] else cell(test), *tasks,
                         cell(by_seed(rows, m, c, TEST_SEED, floor)),
                         f"{np.mean(list(ms.values())):.0f}" if ms else "-"])
    oracle_path = root / ORACLE / f"{maze}.json"
    oracle = f"{100 * json.loads(oracle_path.read_text())['success_rate']:.1f}" if oracle_path.exists() else "-"
    published = PUBLISHED.get(maze, {})
    seeds = sorted({r["config"]["seed"] for r in rows})
    steps = sorted({r["step"] for r in rows})
    versions = sorted({r["environment"]["code_version"] for r in rows})
    goal = goal_lines(rows, maze, methods, chosen)
    return [f"## pointmaze-{maze}-navigate-v0", "",
            f"Training seeds {', '.join(map(str, seeds))}; step {', '.join(map(str, steps))}; code "
            f"{', '.join(versions)}. Bold: the controller the validation episodes choose per method. ms / decision: "
            "one plan at batch 1 (p50). The noise-free oracle on the same protocol: " + oracle + "%; OGBench's "
            "published navigate success: " + ", ".join(f"{k} {v}" for k, v in published.items()) + ".", "",
            *table(["method", "controller", "validation", "test", "task 1", "task 2", "task 3", "task 4", "task 5",
                    "line alone", "ms / decision"], body), "", *goal, ""]


def render(root: Path) -> str:
    root = Path(root)
    lines = ["# OGBench pointmaze navigate: the planners by OGBench's protocol", "",
             "Generated by `bridgeplan study report ogbench-planners` from the `bridgeplan ogbench eval` JSONs in "
             "docs/results/ogbench-<maze>-navigate/ (and `ogbench hierarchy-eval`'s, the methods named "
             "`hierarchy HIGH -> LOW`, NFE the low level's). Datasets generated locally in OGBench's recipe; success "
             "(%) over the 5 tasks x 50 episodes, open loop unless the controller says `replan K` (a hierarchy: its "
             "low level every K steps, its high level once or as said); test episodes: evaluation seed "
             f"{TEST_SEED}, validation: "
             f"seed {VALIDATION_SEED}; mean ± standard error over training seeds (OGBench reports 8 seeds at 1 M "
             "steps: these runs train minutes on a CPU).", ""]
    for maze in MAZES:
        lines += maze_lines(root, maze)
    return "\n".join(lines).rstrip("\n")
