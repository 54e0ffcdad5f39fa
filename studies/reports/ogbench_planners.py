"""OGBench pointmaze, navigate and stitch: bridgeplan's planners by OGBench's protocol, beside the dataset graph,
the straight line alone, the oracle and the published methods.

Rows: ``bridgeplan eval --json`` outputs (and ``hierarchy eval``'s, ``graph``'s; made as ``ogbench eval``, ...) in
docs/results/ogbench-<maze>-<kind>/<run>/ (one per run, controller and evaluation seed). The dataset graph
(``bridgeplan.graph``) trains nothing: its rows are one deterministic graph per setting, so their "mean over
training seeds" is that one value. The test episodes are evaluation seed :data:`TEST_SEED` (the protocol's 5 tasks x
50 episodes); the controller (Diffuser-style tracking in time, or pursuit of the plan's path) is chosen per method
on the validation episodes, seed :data:`VALIDATION_SEED`, and reported on the test ones. Success is OGBench's
``overall_success`` (the mean of the 5 task rates), in %, mean ± standard error over training seeds; the line
alone is the same episodes planned by the straight line, no network, executed by the same controller.

Made by `bridgeplan study report ogbench-planners` (studies/ogbench-planners.toml) into
docs/results/ogbench-planners.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridgeplan.analysis.load import read_evaluation
from bridgeplan.analysis.stats import mean_se
from bridgeplan.analysis.tables import bold, fmt_mean_se, table

READS = ()
"""Its rows are the protocol's JSONs, not a Maze2D store."""
DATASETS = tuple((maze, kind) for kind in ("navigate", "stitch") for maze in ("medium", "large", "giant"))
"""The datasets whose folders the report reads (one without rows is left out)."""
TEST_SEED, VALIDATION_SEED = 0, 1000
ORACLE = "ogbench-oracle"
PUBLISHED = {"navigate": {"medium": {"GCBC": 9, "QRL": 82, "SAW": 97}, "large": {"GCBC": 29, "QRL": 86, "SAW": 85},
                          "giant": {"GCBC": 1, "QRL": 68, "SAW": 68}},
             "stitch": {"medium": {"GCBC": 23, "QRL": 80, "CompDiffuser": 100},
                        "large": {"GCBC": 7, "QRL": 84, "CompDiffuser": 100},
                        "giant": {"GCBC": 0, "QRL": 50, "CompDiffuser": 68}}}
"""Published success (%): GCBC and QRL from OGBench (Park et al., ICLR 2025; 8 seeds at 1 M steps), SAW and
CompDiffuser from their papers, as reprinted in later papers."""


def folder(maze: str, kind: str = "navigate") -> str:
    return f"ogbench-{maze}-{kind}"


def dataset_name(maze: str, kind: str) -> str:
    return f"pointmaze-{maze}-{kind}-v0"


def read_rows(root: Path, maze: str, kind: str = "navigate") -> list[dict]:
    return [read_evaluation(p) for p in sorted((root / folder(maze, kind)).glob("*/*.json"))]


def graph_alone(row: dict) -> bool:
    """A row of the dataset graph's paths alone (no trained level)."""
    return row.get("kind") == "graph" and "low" not in row


def method_of(row: dict) -> str:
    if row.get("kind") == "graph":
        g = row["graph"]
        graph = f"keep {g['keep']}, radius {g['radius']:g}"
        if graph_alone(row):
            return f"dataset graph ({graph}), no network"
        return f"{row['method']} (graph {graph}), NFE {row['nfe']}"
    return f"{row['method']}, NFE {row['nfe']}"


def training_seed(row: dict) -> int:
    """The row's training seed (its low level's under the dataset graph; the graph alone trains nothing: 0)."""
    if row.get("kind") == "graph":
        return row["config"]["low"]["seed"] if "low" in row["config"] else 0
    return row["config"]["seed"]


def controller_of(row: dict) -> str:
    ex = row["execution"]
    name = ex["controller"] + (f" {ex['lookahead']:g}" if ex.get("lookahead") else "")
    name += f", replan {ex['replan_every']}" if ex.get("replan_every") else ""
    return name + (f", high level every {row['replan_high_every']}" if row.get("replan_high_every") else "")


def by_seed(rows: list[dict], method: str, controller: str, seed: int, value) -> dict[int, float]:
    return {training_seed(r): value(r) for r in rows
            if method_of(r) == method and controller_of(r) == controller and r["seed"] == seed and value(r) is not None}


def success(r: dict) -> float:
    return 100 * r["success_rate"]


def floor(r: dict) -> float | None:
    return 100 * r["floor_line"]["success_rate"] if "floor_line" in r else None


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


def goal_lines(rows: list[dict], maze: str, kind: str, methods: list[str],
               chosen: dict[str, str | None]) -> list[str]:
    """Per method, its chosen setting's test success against each published method (above at two standard errors;
    the dataset graph, one deterministic graph: above when its success is); where not above, by how much the mean
    differs (points, mean minus published)."""
    lines = []
    for m in methods:
        c = chosen[m]
        test = by_seed(rows, m, c, TEST_SEED, success) if c else {}
        graph = any(graph_alone(r) for r in rows if method_of(r) == m)
        if len(test) < (1 if graph else 2):
            continue
        s = mean_se(test)
        lower = s.mean if graph else s.mean - 2 * s.se  # one deterministic graph: its value
        above = ", ".join(f"{name} {value}: " + ("yes" if lower > value else f"no ({s.mean - value:+.1f})")
                          for name, value in PUBLISHED[kind].get(maze, {}).items())
        how = "one graph, no training" if graph else f"over {len(test)} training seeds"
        lines.append(f"- {dataset_name(maze, kind)}, {m}, {c} (chosen on validation): "
                     f"{fmt_mean_se(test, one_seed='mean')}% {how}; above"
                     f"{'' if graph else ' at two standard errors'}: {above}")
    return lines


def block(root: Path) -> str:
    """The README's lines: each method's chosen setting against the published methods."""
    lines = []
    for maze, kind in DATASETS:
        rows = read_rows(Path(root), maze, kind)
        methods = sorted({method_of(r) for r in rows})
        lines += goal_lines(rows, maze, kind, methods,
                            choose(rows, methods, sorted({controller_of(r) for r in rows})))
    return "\n".join(lines)


def dataset_lines(root: Path, maze: str, kind: str) -> list[str]:
    rows = read_rows(root, maze, kind)
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
    oracle = (f"{100 * read_evaluation(oracle_path)['success_rate']:.1f}" if oracle_path.exists()
              else "-")
    published = PUBLISHED[kind].get(maze, {})
    trained = [r for r in rows if not graph_alone(r)]
    seeds = sorted({training_seed(r) for r in trained})
    steps = sorted({r["step"] for r in trained})
    versions = sorted({r["code_version"] for r in rows})
    training = (f"Training seeds {', '.join(map(str, seeds))}; step {', '.join(map(str, steps))}; " if trained
                else "No trained planner yet; ")
    goal = goal_lines(rows, maze, kind, methods, chosen)
    return [f"## {dataset_name(maze, kind)}", "",
            f"{training}code {', '.join(versions)}. Bold: the controller the validation episodes choose per method. "
            "ms / decision: one plan at batch 1 (p50). The noise-free oracle on the same protocol: " + oracle + "%; "
            f"published {kind} success: " + ", ".join(f"{k} {v}" for k, v in published.items()) + ".", "",
            *table(["method", "controller", "validation", "test", "task 1", "task 2", "task 3", "task 4", "task 5",
                    "line alone", "ms / decision"], body), "", *goal, ""]


def render(root: Path) -> str:
    root = Path(root)
    lines = ["# OGBench pointmaze: the planners by OGBench's protocol", "",
             "Generated by `bridgeplan study report ogbench-planners` from the `bridgeplan eval` JSONs in "
             "docs/results/ogbench-<maze>-<kind>/ (and `bridgeplan hierarchy eval`'s, the methods named "
             "`hierarchy HIGH -> LOW`, NFE the low level's; and `bridgeplan graph`'s, the dataset graph: the data's "
             "own states, their shortest paths executed, no network and no map, one deterministic graph per "
             "setting). Datasets generated locally in OGBench's recipe; success "
             "(%) over the 5 tasks x 50 episodes, open loop unless the controller says `replan K` (a hierarchy: its "
             "low level every K steps, its high level once or as said); test episodes: evaluation seed "
             f"{TEST_SEED}, validation: "
             f"seed {VALIDATION_SEED}; mean ± standard error over training seeds (OGBench reports 8 seeds at 1 M "
             "steps: these runs train minutes on a CPU).", ""]
    for maze, kind in DATASETS:
        lines += dataset_lines(root, maze, kind)
    return "\n".join(lines).rstrip("\n")
