"""OGBench manipulation, cube-single: GCBC, GCIQL, a DDPM planner and the dataset graph by OGBench's protocol, beside
the published numbers with their budget.

Rows: the evaluation JSONs in docs/results/manip-cube-single/ (``gcbc eval`` for GCBC and GCIQL, one per training
seed and snapshot; ``eval`` for the planner and ``graph`` for the graph (no training: one row), each its test split
and its validation split on tasks 6-10). Success is OGBench's
``overall_success``: the mean over the tasks of each task's rate; mean ± standard error over training seeds. The main
table is at each method's last snapshot (the largest step its rows have); GCBC and GCIQL also as OGBench averages
them (per training seed, the mean of its last :data:`LAST` evaluations) and against training steps.

Made by `bridgeplan study report manip-cube-single` (studies/manip-cube-single.toml) into
docs/results/manip-cube-single.md.
"""

from __future__ import annotations

import json
from pathlib import Path

from bridgeplan.analysis.tables import fmt_mean_se, table

READS = ()
"""Its planner is a named run of the study, not a grid's method."""
FOLDER = "manip-cube-single"
PUBLISHED = {"gcbc": "6 (8 seeds, 1 M steps)", "gciql": "68 (8 seeds, 1 M steps)"}
"""OGBench's published success (%) on cube-single-play-v0 (Park et al., ICLR 2025)."""
LABELS = {"gcbc": "GCBC (20 k steps)", "gciql": "GCIQL (20 k steps)",
          "ddpm": "DDPM planner (cpu-small, 20 k steps, NFE 16, replanned every 8 steps)",
          "graph-keep5-r1": "the dataset graph (no network: every 5th state, radius 1, replanned every 50 steps)"}
"""The README's names of the study's methods (the files' names are the report's)."""


LAST = 3
"""Evaluations OGBench averages per training seed (its last three, at 800 k, 900 k and 1 M steps; here 10 k, 15 k and
20 k)."""


def rows(root: Path) -> list[dict]:
    """Every evaluation JSON under the study's folder, with the method it is of (the file's or its folder's stem
    before ``-s<seed>``) and whether it is on the validation tasks."""
    out = []
    for path in sorted((Path(root) / FOLDER).rglob("*.json")):
        d = json.loads(path.read_text())
        name = path.parent.name if path.parent.name != FOLDER else path.stem
        validation = any(int(t) > 5 for t in d["tasks"])
        out.append({**d, "method": name.split("-s")[0], "validation": validation})
    return out


def last_steps(found: list[dict]) -> dict[str, int]:
    """Each method's last snapshot: the largest step its rows have (the graph's: 0, no training)."""
    out: dict[str, int] = {}
    for r in found:
        out[r["method"]] = max(out.get(r["method"], 0), r["step"])
    return out


def final(found: list[dict]) -> list[dict]:
    """The rows at their method's last snapshot."""
    last = last_steps(found)
    return [r for r in found if r["step"] == last[r["method"]]]


def test_rates(found: list[dict]) -> dict[str, list[float]]:
    """Each method's success (%) on the test tasks at its last snapshot, one per training seed (the graph: one)."""
    out: dict[str, list[float]] = {}
    for r in final(found):
        if not r["validation"]:
            out.setdefault(r["method"], []).append(100 * r["success_rate"])
    return dict(sorted(out.items()))


def curves(found: list[dict]) -> dict[str, dict[int, dict[int, float]]]:
    """GCBC's and GCIQL's test success (%) by training seed and snapshot step: ``{method: {seed: {step: rate}}}``."""
    out: dict[str, dict[int, dict[int, float]]] = {}
    for r in found:
        if r["method"] in PUBLISHED and not r["validation"]:
            out.setdefault(r["method"], {}).setdefault(r["train_seed"], {})[r["step"]] = 100 * r["success_rate"]
    return out


def ogbench_average(per_seed: dict[int, dict[int, float]], final_step: int) -> list[float]:
    """Per training seed whose last :data:`LAST` evaluations run up to ``final_step``, their mean (OGBench's
    averaging)."""
    out = []
    for by_step in per_seed.values():
        last = sorted(by_step)[-LAST:]
        if len(last) == LAST and last[-1] == final_step:
            out.append(sum(by_step[k] for k in last) / LAST)
    return out


def block(root: Path) -> str:
    """The README's lines: each method's success on the 5 test tasks, beside the published number."""
    found = rows(root)
    if not found:
        return "- cube-single-play-v0: no rows yet (`bridgeplan study run manip-cube-single`)."
    return "\n".join(f"- cube-single-play-v0, {LABELS.get(method, method)}: {fmt_mean_se(rates, one_seed='mean')}% "
                     + (f"over {len(rates)} training seeds" if len(rates) > 1 else "(one run)")
                     + (f"; OGBench published {PUBLISHED[method]}" if method in PUBLISHED else "")
                     for method, rates in test_rates(found).items())


def render(root: Path) -> str:
    found = rows(root)
    lines = ["# OGBench cube-single: GCBC, GCIQL, a DDPM planner and the dataset graph by OGBench's protocol", "",
             f"Generated by `bridgeplan study report manip-cube-single` from the JSONs in docs/results/{FOLDER}/. "
             "Dataset generated locally by OGBench's play recipe (`bridgeplan data generate --maze "
             "cube-single-play-v0`); success (%) over the 5 test tasks (200 steps per episode, 50 episodes per task, "
             "evaluation seed 0), mean ± standard error over training seeds.", ""]
    if not found:
        return "\n".join([*lines, "No rows yet: `bridgeplan study run manip-cube-single`, then `bridgeplan study "
                                  "export manip-cube-single`."])
    body = []
    for method in sorted({r["method"] for r in found}):
        for validation in (False, True):
            mine = [r for r in final(found) if r["method"] == method and r["validation"] == validation]
            if mine:
                rates = [100 * r["success_rate"] for r in mine]
                body.append([method, "validation (tasks 6-10)" if validation else "test", len(mine),
                             fmt_mean_se(rates, one_seed="mean"), "" if validation else PUBLISHED.get(method, "-")])
    lines += table(["method", "tasks", "seeds", "success (%)", "published"], body)
    found_curves = curves(found)
    if found_curves:
        steps = sorted({k for per_seed in found_curves.values() for by_step in per_seed.values() for k in by_step})
        lines += ["", f"GCBC and GCIQL against training steps (test tasks; mean ± standard error over the training "
                      f"seeds evaluated at that step), and as OGBench averages (per seed the mean of its last {LAST} "
                      "evaluations, then over seeds):", ""]
        curve_rows = []
        for method, per_seed in sorted(found_curves.items()):
            at = [[by_step[k] for by_step in per_seed.values() if k in by_step] for k in steps]
            average = ogbench_average(per_seed, last_steps(found)[method])
            curve_rows.append([method, *(f"{fmt_mean_se(v, one_seed='mean')} ({len(v)})" for v in at),
                               f"{fmt_mean_se(average, one_seed='mean')} ({len(average)})" if average else "-"])
        lines += table(["method", *(f"{k // 1000} k steps" for k in steps), f"OGBench's average (last {LAST})"],
                       curve_rows)
    return "\n".join(lines)
