"""Hierarchical planning on Maze2D (bridgeplan.hierarchy): a coarse plan refined by a low level, beside the same
coarse plans executed alone, the best flat planner, the line alone and the expert.

Rows: ``bridgeplan hierarchy eval`` (and ``graph --low``) JSONs in docs/results/<section>-hierarchy/<setting>/ (a
section: :data:`SECTIONS`; one per training seed,
task set and split; the test episodes are evaluation seed = training seed, the validation ones 1000 + it, as the
study runner's). A setting is the two levels' methods and NFEs and the execution; per family (the levels' methods
and shapes) the setting with the best mean validation score is chosen and reported on the test episodes. "Coarse
alone" is the same coarse plans, densified and pursued open loop: the paired difference says what the low level
adds. The flat planner is the best pursued one of the maze's batch-32 stores, the levels' batch
(docs/results/<maze>-v2-{curves,hold,consistent-priors}/results.csv, chosen on validation, its final snapshot), or
in the stitching section the best of its own flat planners (trained on the same pieces), paired by training seed on
the same test episodes. Issue 26's goal on large: success >= 0.98 and a Minari score >= 104.

Made by `bridgeplan study report hierarchy` (studies/large-hierarchy.toml) into docs/results/hierarchy.md and
the README's block.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bridgeplan.analysis.load import load_csvs
from bridgeplan.analysis.selection import best
from bridgeplan.analysis.stats import compare, mean_se, paired
from bridgeplan.analysis.tables import bold, fmt_diff, fmt_mean_se, table

from .headline import STORES, candidates, describe, expert_scores

READS = ()
"""Its rows are `bridgeplan hierarchy eval` JSONs (and the maze's batch-32 flat stores)."""
SECTIONS = {"large": ("large", "large"),
            "large-stitch": ("large", "large from 200-step pieces (stitching)")}
"""Each section's folder prefix (docs/results/<prefix>-hierarchy, <prefix>-hierarchy-flat) -> (maze, heading). The
stitching section's flat planners were trained on its own pieces (its -flat folder), not on the full stream."""
VALIDATION_OFFSET = 1000
GOAL = {"large": (0.98, 104.0)}
"""Issue 26's goal per maze: (success rate, Minari score)."""


def read_rows(root: Path, section: str) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((root / f"{section}-hierarchy").glob("*/*.json"))]


def read_high_alone(root: Path, section: str) -> list[dict]:
    """``bridgeplan eval`` JSONs of single planners, replanned (docs/results/<section>-hierarchy-flat): high levels
    executed alone, or the stitching section's flat planners."""
    return [json.loads(p.read_text()) for p in sorted((root / f"{section}-hierarchy-flat").glob("*/*.json"))]


def high_alone_setting(r: dict) -> str:
    ex = r["execution"]
    return (f"{r['method']} NFE {r['nfe']} (H{r['horizon']}k{r['stride']}) alone; replan {ex['replan_every']}, "
            f"{ex['controller']} {ex['lookahead']:g}")


def high_alone_values(rows: list[dict], setting: str, split: str, multi_task: bool, value) -> dict[int, float]:
    return {r["config"]["seed"]: value(r) for r in rows
            if high_alone_setting(r) == setting and split_of(r) == split and bool(r["multi_task"]) == multi_task}


def matching_high_alone(r: dict, alone_rows: list[dict]) -> str | None:
    """The high-level-alone setting that replans the same high level as often as hierarchy row ``r`` does."""
    every = r["execution"].get("replan_high_every")
    high = r["high"]
    if is_graph(high):
        return None
    for a in alone_rows:
        if (every and a["execution"]["replan_every"] == every and a["nfe"] == high["nfe"]
                and (a["horizon"], a["stride"]) == (high["horizon"], high["stride"])
                and a["config"]["seed"] == high["config"]["seed"] and a["process"] == high["process"]):
            return high_alone_setting(a)
    return None


def is_graph(high: dict) -> bool:
    """Whether a row's high level is the dataset graph (``bridgeplan graph --low``), not a trained planner."""
    return high.get("process") == "graph"


def high_label(high: dict) -> str:
    if is_graph(high):
        g = high["graph"]
        return f"dataset graph (keep {g['keep']}, radius {g['radius']:g}; every {high['stride']})"
    return f"{high['method']} NFE {high['nfe']} (H{high['horizon']}k{high['stride']})"


def setting_of(r: dict) -> str:
    high, low, ex = r["high"], r["low"], r["execution"]
    control = ex["controller"] + (f" {ex['lookahead']:g}" if ex.get("lookahead") else "")
    if ex.get("replan_high_every"):
        control += f", high level replanned every {ex['replan_high_every']}"
    return (f"{high_label(high)} -> {low['method']} NFE {low['nfe']} (H{low['horizon']}k{low['stride']}, subgoal "
            f"every {low['subgoal_every']}); replan {ex['replan_every']}, {control}")


def family_of(r: dict) -> str:
    """The two levels' methods and shapes: a setting is chosen on validation within each family."""
    high, low = r["high"], r["low"]
    first = "dataset graph" if is_graph(high) else f"{high['method']} H{high['horizon']}k{high['stride']}"
    return f"{first} -> {low['method']} H{low['horizon']}k{low['stride']}"


def training_seed(r: dict) -> int:
    """The row's training seed: its low level's (a planner high level shares it; the graph has none)."""
    return r["low"]["config"]["seed"]


def split_of(r: dict) -> str:
    return "validation" if r["seed"] >= VALIDATION_OFFSET else "test"


def by_seed(rows: list[dict], setting: str, split: str, multi_task: bool, value) -> dict[int, float]:
    return {training_seed(r): value(r) for r in rows
            if setting_of(r) == setting and split_of(r) == split and bool(r["multi_task"]) == multi_task}


def minari(r: dict) -> float:
    return r["score"]["minari"]["mean"]


def alone(r: dict) -> float:
    return r["high_alone"]["score"]["minari"]["mean"]


def line_alone(r: dict) -> float | None:
    """The straight line over the high level's span, pursued (None for the graph, which has no span)."""
    return r["floor_line"]["score"]["minari"]["mean"] if "floor_line" in r else None


def average(values: dict[int, float]) -> float:
    return float(np.mean(list(values.values())))


def latency(values) -> str:
    """``p50 / p95`` ms of a decision at batch 1, averaged over seeds (a hierarchy's p95 is its coarse plans')."""
    p50, p95 = values(lambda r: r["decision_ms_batch1"]["p50"]), values(lambda r: r["decision_ms_batch1"]["p95"])
    return f"{average(p50):.1f} / {average(p95):.1f}" if p50 else "-"


def diagnostic(test, field: str, form: str) -> str:
    """The coarse plans' diagnostic ``field`` averaged over seeds ('-' in rows made before it was recorded)."""
    values = test(lambda r: r.get("coarse_plans", {}).get(field, np.nan))
    value = average(values) if values else np.nan
    return "-" if np.isnan(value) else form.format(value)


def cell(values: dict[int, float]) -> str:
    return fmt_mean_se(values, one_seed="mean") if values else "-"


def chosen_settings(rows: list[dict], multi_task: bool) -> dict[str, str]:
    """Per family (the levels' methods and shapes), the setting with the best mean validation score."""
    out: dict[str, tuple[float, str]] = {}
    for setting in sorted({setting_of(r) for r in rows}):
        family = next(family_of(r) for r in rows if setting_of(r) == setting)
        validation = by_seed(rows, setting, "validation", multi_task, minari)
        if validation and (family not in out or average(validation) > out[family][0]):
            out[family] = (average(validation), setting)
    return {family: setting for family, (_, setting) in out.items()}


def flat_best(root: Path, section: str, multi_task: bool):
    """The best pursued flat planner: (description, {seed: test score}, {seed: success}). The stitching section's:
    of its own (-flat folder), chosen on validation; the others': the batch-32 stores', trained on the full stream."""
    maze = SECTIONS[section][0]
    if section != maze:
        rows = [r for r in read_high_alone(root, section) if bool(r["multi_task"]) == multi_task]
        settings = sorted({high_alone_setting(r) for r in rows})
        if not settings:
            return None
        chosen = max(settings, key=lambda s: average(high_alone_values(rows, s, "validation", multi_task, minari)))
        return (chosen, high_alone_values(rows, chosen, "test", multi_task, minari),
                high_alone_values(rows, chosen, "test", multi_task, lambda r: r["success_rate"]["mean"]))
    results = load_csvs(p for store in STORES for p in [root / f"{maze}-v2-{store}" / "results.csv"] if p.exists())
    point = best(results, candidates(results, multi_task, True))
    if point is None:
        return None
    return (f"{describe(point.key, point.nfe)}, step {point.step}", results.values(point),
            results.values(point, field="success"))


def verdict(d) -> str:
    return f"{fmt_diff(d)} ({compare(d)})" if d.n >= 2 else fmt_diff(d)


def summary_lines(root: Path, section: str, rows: list[dict], multi_task: bool) -> list[str]:
    """Per family, its chosen setting against the coarse plans alone, the flat planner and the goal."""
    lines = []
    maze, heading = SECTIONS[section]
    flat = flat_best(root, section, multi_task)
    alone_rows = read_high_alone(root, section)
    goal_success, goal_score = GOAL.get(maze, (None, None))
    for family, setting in sorted(chosen_settings(rows, multi_task).items()):
        test = by_seed(rows, setting, "test", multi_task, minari)
        if not test:
            continue
        success = mean_se(by_seed(rows, setting, "test", multi_task, lambda r: r["success_rate"]["mean"]))
        coarse = by_seed(rows, setting, "test", multi_task, alone)
        parts = [f"{fmt_mean_se(test)} (success {success.mean:.2f})",
                 f"minus the coarse plans alone {verdict(paired(test, coarse))}"]
        first = next(r for r in rows if setting_of(r) == setting)
        replanned = matching_high_alone(first, alone_rows)
        if replanned is not None:
            same = high_alone_values(alone_rows, replanned, "test", multi_task, minari)
            if same:
                parts.append(f"minus its high level alone, replanned as often, "
                             f"{verdict(paired(test, same, seeds='common'))}")
        if flat is not None:
            parts.append(f"minus the best flat planner ({flat[0]}) {verdict(paired(test, flat[1], seeds='common'))}")
        if goal_score is not None:
            s = mean_se(test)
            met = success.mean >= goal_success and s.mean >= goal_score
            parts.append("goal (success >= " f"{goal_success}, Minari >= {goal_score:g}): " + (
                "met" if met else f"missed by {max(goal_success - success.mean, 0):.2f} success and "
                                  f"{max(goal_score - s.mean, 0):.1f} points"))
        lines.append(f"- {heading} {'Multi2D' if multi_task else 'single-task'}, {family}: " + "; ".join(parts))
    return lines


def block(root: Path) -> str:
    root = Path(root)
    return "\n".join(line for section in SECTIONS for multi in (False, True)
                     for line in summary_lines(root, section, read_rows(root, section), multi))


def section_lines(root: Path, section: str) -> list[str]:
    rows = read_rows(root, section)
    if not rows:
        return []
    maze, heading = SECTIONS[section]
    expert = expert_scores(root)
    seeds = sorted({training_seed(r) for r in rows})
    steps = sorted({(r["high"]["step"], r["low"]["step"]) for r in rows})
    versions = sorted({r["environment"]["code_version"] for r in rows})
    out = [f"## {heading}", "",
           f"Training seeds {', '.join(map(str, seeds))}; steps (high, low) {', '.join(map(str, steps))}; code "
           f"{', '.join(versions)}; {rows[0]['episodes']} episodes per split.", ""]
    for multi_task in (False, True):
        settings = sorted({setting_of(r) for r in rows if bool(r["multi_task"]) == multi_task})
        if not settings:
            continue
        chosen = set(chosen_settings(rows, multi_task).values())
        body = []
        for setting in settings:
            def test(value, s=setting):
                return by_seed(rows, s, "test", multi_task, value)
            sc, co = test(minari), test(alone)
            ms = latency(test)
            body.append([bold(setting) if setting in chosen else setting,
                         cell(by_seed(rows, setting, "validation", multi_task, minari)),
                         bold(cell(sc)) if setting in chosen else cell(sc),
                         f"{average(test(lambda r: r['success_rate']['mean'])):.2f}", cell(co),
                         f"{average(test(lambda r: r['high_alone']['success_rate']['mean'])):.2f}",
                         verdict(paired(sc, co)) if sc and co else "-",
                         cell({k: v for k, v in test(line_alone).items() if v is not None}),
                         diagnostic(test, "in_walls", "{:.2f}"), diagnostic(test, "arrival_step", "{:.0f}"),
                         f"{average(test(lambda r: r['calls_per_episode'])):.0f}",
                         ms])
        scores = expert.get((maze, multi_task))
        flat = flat_best(root, section, multi_task)
        alone_rows = [r for r in read_high_alone(root, section) if bool(r["multi_task"]) == multi_task]
        alone_body = []
        for setting in sorted({high_alone_setting(r) for r in alone_rows}):
            def values(value, s=setting):
                return high_alone_values(alone_rows, s, "test", multi_task, value)
            ms = latency(values)
            alone_body.append([setting, cell(high_alone_values(alone_rows, setting, "validation", multi_task, minari)),
                               cell(values(minari)), f"{average(values(lambda r: r['success_rate']['mean'])):.2f}",
                               f"{average(values(lambda r: r['calls_per_episode'])):.0f}",
                               ms])
        out += [f"### {'Multi2D' if multi_task else 'single-task'}", "",
                *table(["setting", "validation", "test", "success", "coarse alone", "success", "hierarchy - coarse",
                        "line alone", "coarse in walls", "coarse arrival (step)", "calls / episode",
                        "ms / decision p50 / p95"], body), "",
                *([("The high level alone" if section == maze else "Flat planners trained on the same pieces")
                   + ", replanned from the current state (`bridgeplan eval --replan-every K`, pursued; no low level):",
                   "",
                   *table(["setting", "validation", "test", "success", "calls / episode",
                           "ms / decision p50 / p95"],
                          alone_body), ""] if alone_body else []),
                f"The expert on the same test episodes: {fmt_mean_se(scores) if scores else '-'}; the best flat "
                f"pursued planner: " + (f"{flat[0]}, {fmt_mean_se(flat[1])} (success "
                                        f"{average(flat[2]):.2f})" if flat else "-") + ".", "",
                *summary_lines(root, section, rows, multi_task), ""]
    return out


def render(root: Path) -> str:
    root = Path(root)
    lines = ["# Hierarchical planning: a coarse plan over the episode, refined by a low level", "",
             "Generated by `bridgeplan study report hierarchy` from the `bridgeplan hierarchy eval` JSONs in "
             "docs/results/<section>-hierarchy/ (studies/large-hierarchy.toml and large-stitch-hierarchy.toml say how "
             "the runs were trained). The high "
             "level plans at a long stride once per episode (or again every K steps where the setting says so), or is "
             "the dataset graph's cheapest path through the data's own states (`bridgeplan graph --low RUN`); the "
             "low level plans from the current state through the next coarse states every `replan` steps and is "
             "pursued. "
             "Minari score, mean ± standard error over training seeds; bold: the setting the validation episodes "
             "choose per family (the levels' methods and shapes), reported on the test episodes. Coarse alone: the "
             "same coarse plans, "
             "densified, pursued open loop; hierarchy - coarse: the paired per-seed difference (better / worse / tie "
             "at two standard errors). Coarse in walls: the share of the densified coarse plans' positions inside "
             "walls; coarse arrival: the mean step at which they first come within 0.45 of the goal (both measured "
             "with the maze's map, which no planner reads: what limits the coarse plans). ms / decision: p50 and p95 "
             "of one decision at batch 1 (a hierarchy's decisions that make a coarse plan are its slow ones).", ""]
    for section in SECTIONS:
        lines += section_lines(root, section)
    return "\n".join(lines).rstrip("\n")
