"""The README's headline table: per maze and task set, the best planner executed by Diffuser's tracking controller
and the best pursued one, each chosen on the validation episodes and reported on the test episodes, beside the
straight line alone executed the same ways, the expert on the same episodes and Diffuser's published score.

Rows: per maze, the stores of :data:`HEADLINE_STORES` (umaze and medium: docs/results/<maze>-v2-{curves,hold,
consistent-priors}, batch 32; large: docs/results/large-v2-batch256-controllers, cpu-small's batch 256 that beat batch
32 there at equal wall-clock), each run's final snapshot; candidates are every method (holds included), NFE and
open-loop or replanned execution evaluated there on both splits. The
expert: docs/results/expert-on-eval-tasks.json (`bridgeplan reference expert-on-tasks`, the same test episodes).
Diffuser's published scores (Janner et al. 2022, Table 1) use D4RL's normalization constants in the old
environment (goal threshold 0.5): they are shown beside this project's scores converted to that convention
(``score_d4rl``), not compared with them.

Made by `bridgeplan study report headline` (studies/headline.toml) into docs/results/headline.md and the README's
generated block.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bridgeplan.analysis.keys import MethodKey, label, method
from bridgeplan.analysis.load import Point, Results, load_csvs
from bridgeplan.analysis.selection import best
from bridgeplan.analysis.tables import fmt_mean_se, table

MAZES = ("umaze", "medium", "large")
STORES = ("curves", "hold", "consistent-priors")
"""A maze's batch-32 stores (docs/results/<maze>-v2-<store>), in order of precedence (as the findings report's)."""
HEADLINE_STORES = {"umaze": STORES, "medium": STORES, "large": ("batch256-controllers",)}
"""The stores each maze's rows come from. Large's are at cpu-small's batch 256 / lr 3e-3, which beat batch 32 at
equal wall-clock there (docs/results/throughput-wallclock.md); at medium the two tied, and medium's batch-32 stores
hold more methods (holds, consistent priors)."""
EXPERT = "expert-on-eval-tasks.json"
READS = (method("ddpm", steps=16), method("bridge", "line", steps=16))
"""The trained methods every maze's rows have."""
DIFFUSER_PUBLISHED = {("umaze", False): 113.9, ("medium", False): 121.5, ("large", False): 123.0,
                      ("umaze", True): 128.9, ("medium", True): 127.2, ("large", True): 132.1}
"""Diffuser's Maze2D scores (Janner et al. 2022, Table 1; D4RL convention, old environment)."""


def paths(root: Path, maze: str) -> list[Path]:
    """The results.csv files of ``maze``'s headline stores."""
    return [root / f"{maze}-v2-{store}" / "results.csv" for store in HEADLINE_STORES[maze]]


def load(root: Path, maze: str) -> Results:
    """``maze``'s headline rows."""
    return load_csvs(paths(root, maze))


def candidates(results: Results, multi_task: bool, pursued: bool) -> list[Point]:
    """Every (method, execution, NFE) at its final snapshot with rows on both splits, tracked or pursued."""
    points = []
    for key in results.keys("validation"):
        if key.multi_task != multi_task or (key.execution.controller == "pursuit") != pursued:
            continue
        steps = results.steps(key)
        if steps:
            points += [p for p in results.points(key, steps[-1]) if results.rows(p)]
    return points


def describe(key: MethodKey, nfe: int) -> str:
    """``DDPM, NFE 16, pursuit 1.5`` (with the hold share and replanning where they apply)."""
    ex = key.execution
    parts = [label(key), f"NFE {nfe}"]
    if ex.controller == "pursuit":
        parts.append(f"pursuit {ex.lookahead:g}")
    if ex.replan_every:
        parts.append(ex.tag().split("-pursuit")[0])
    return ", ".join(parts)


def mean(results: Results, point: Point, field: str) -> float:
    return float(np.mean(list(results.values(point, field=field).values())))


def ms_per_decision(results: Results, point: Point) -> str:
    """Open loop: ms per plan planned with the other episodes in one batch; replanned: a decision's p50 at batch 1."""
    if point.key.execution.replan_every:
        p50 = [r.decision_ms[0] for r in results.rows(point).values() if r.decision_ms]
        return f"{np.mean(p50):.1f} ms at batch 1" if p50 else "-"
    return f"{mean(results, point, 'plan_ms'):.2f} ms batched"


def expert_rows(root: Path) -> list[dict]:
    """The expert's rows on the evaluation tasks, each with its ``score_minari``: the committed file's (made by
    ``reference expert-on-tasks``) or rows of ``bridgeplan oracle`` (its score under ``score``)."""
    return [{**r, "score_minari": r["score"]["minari"]["mean"]} if "score_minari" not in r else r
            for r in json.loads((root / EXPERT).read_text())["rows"]]


def expert_scores(root: Path) -> dict[tuple[str, bool], list[float]]:
    out: dict[tuple[str, bool], list[float]] = {}
    for r in expert_rows(root):
        out.setdefault((r["maze"], bool(r["multi_task"])), []).append(r["score_minari"])
    return out


def scored(results: Results, point: Point) -> str:
    """``84.0 ± 0.6 (0.95)``: the score over seeds and the mean success rate."""
    return f"{fmt_mean_se(results.values(point))} ({mean(results, point, 'success'):.2f})"


def headline_rows(root: Path) -> list[list[str]]:
    expert = expert_scores(root)
    rows = []
    for multi_task in (False, True):
        for maze in MAZES:
            results = load(root, maze)
            tracked, pursued = (best(results, candidates(results, multi_task, p)) for p in (False, True))
            if tracked is None or pursued is None:
                continue
            scores = expert.get((maze, multi_task))
            rows.append([
                maze, "Multi2D" if multi_task else "single-task",
                f"{describe(tracked.key, tracked.nfe)}; {ms_per_decision(results, tracked)}", scored(results, tracked),
                f"{describe(pursued.key, pursued.nfe)}; {ms_per_decision(results, pursued)}", scored(results, pursued),
                f"{fmt_mean_se(results.values(tracked, field='floor'))} / "
                f"{fmt_mean_se(results.values(pursued, field='floor'))}",
                fmt_mean_se(scores) if scores else "-",
                f"{fmt_mean_se(results.values(tracked, field='score_d4rl'))} / "
                f"{DIFFUSER_PUBLISHED[(maze, multi_task)]}"])
    return rows


HEADER = ["maze", "tasks", "best tracked planner; ms / decision", "score (success)",
          "best pursued planner; ms / decision", "score (success)", "line alone: tracked / pursued",
          "expert", "tracked, D4RL convention / Diffuser published"]


def block(root: Path) -> str:
    """The table the README shows (its generated block)."""
    return "\n".join(table(HEADER, headline_rows(Path(root))))


def sources() -> str:
    """Each maze's headline stores as the text names them: ``umaze-v2-{curves,hold}, large-v2-batch256-...``."""
    return ", ".join(f"{maze}-v2-{{{','.join(stores)}}}" if len(stores) > 1 else f"{maze}-v2-{stores[0]}"
                     for maze, stores in HEADLINE_STORES.items())


def render(root: Path) -> str:
    root = Path(root)
    versions = sorted({r.code_version for maze in MAZES for path in paths(root, maze) if path.exists()
                       for r in load_csvs([path])})
    return "\n".join([
        "# Headline: the best tracked and the best pursued planner per maze", "",
        "Generated by `bridgeplan study report headline` from docs/results/<store>/results.csv of the stores "
        + sources() + " (umaze's and medium's at batch 32, lr 1e-3; large's at batch 256, lr 3e-3: cpu-small's "
        "large setting since it beat batch 32 at equal wall-clock, docs/results/throughput-wallclock.md) and "
        "docs/results/expert-on-eval-tasks.json (codes "
        + ", ".join(versions) + "). Each run's final snapshot; 3 training seeds x 200 test episodes; Minari score, "
        "mean ± standard error over seeds. "
        "Each planner (method, NFE, execution) is chosen among all evaluated on 200 validation episodes per seed, "
        "then scored on the test episodes; the line alone is executed the same way on the same episodes. ms / "
        "decision: open loop, one plan per episode planned in a batch with the others; replanned, the p50 of one "
        "decision at batch 1. The last column puts this project's tracked score in D4RL's convention beside "
        "Diffuser's published one (Janner et al. 2022, Table 1: old environment, goal threshold 0.5), which is not "
        "a like-for-like comparison.", "",
        block(root)])
