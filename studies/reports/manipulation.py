"""OGBench manipulation: GCBC, GCIQL, planners and the dataset graph by OGBench's protocol on each play dataset
generated here, beside the published numbers with their budget.

Rows: the evaluation JSONs in docs/results/manip-SCENE/ (one folder per dataset, ``manip-cube-single``; ``eval``
(earlier ``gcbc eval``) for GCBC and GCIQL, one per training seed and snapshot; ``eval`` for a planner and ``graph``
for the graph (no training: one row; with a policy low level, one per training seed of the policy), each its test
split and its validation split on tasks 6-10). Success is OGBench's
``overall_success``: the mean over the tasks of each task's rate; mean ± standard error over training seeds. The main
table is at each method's last snapshot (the largest step its rows have); GCBC and GCIQL also as OGBench averages
them (per training seed, the mean of its last :data:`LAST` evaluations) and against training steps.

Made by `bridgeplan study report manipulation` (the studies studies/manip-*.toml) into docs/results/manipulation.md.
"""

from __future__ import annotations

import re
from pathlib import Path

from bridgeplan.analysis.load import read_evaluation
from bridgeplan.analysis.stats import compare, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, table
from bridgeplan.envs.ogbench_manipulation.names import SCENES

READS = ()
"""Its planners are named runs of the studies, not a grid's methods."""
PUBLISHED = {"cube-single": (6, 68), "cube-double": (1, 40), "scene": (5, 51), "puzzle-3x3": (2, 95),
             "puzzle-4x4": (0, 26)}
"""OGBench's published success (%) of GCBC and GCIQL per play dataset (Park et al., ICLR 2025, Table 2), at
:data:`BUDGET`."""
BEST_REPORTED = {"cube-single": 89, "cube-double": 60, "scene": 90, "puzzle-3x3": 95, "puzzle-4x4": 84}
"""The best success (%) reported by any method after OGBench's paper, about (secondary sources, as the issue quotes
them): the moonshot."""
BUDGET = "(8 seeds, 1 M steps)"
PEERS = ("gcbc", "gciql")
LABELS = {"gcbc": "GCBC (20 k steps)", "gciql": "GCIQL (20 k steps)",
          "ddpm": "DDPM planner (cpu-small, 20 k steps, NFE 16, replanned every 8 steps)"}
"""The README's names of the studies' methods (the files' names are the report's); the graph's from its folder."""
GRAPH_FOLDER = re.compile(r"(?:regenerated-data/)?graph-keep(\d+)-r([\d.]+)(-objects(?:-hand)?)?"
                          r"(?:-(gcbc|gciql)-ahead(\d+)|-(ddpm|bridge|flow|meanflow)(?:-(line|learned|gaussian))?"
                          r"-k\d+-nfe\d+)?(?:-afterstep(\d+))?(?:-objtol([\d.]+))?")
"""A graph row's folder (under ``regenerated-data/`` where made on the recipe's data generated again elsewhere: its
arrays differ, see :data:`REGENERATED`): its graph (every Nth state, radius, one graph per cube or scene's part, or a
puzzle's presses solved; ``-hand``: scene's window and its button measuring the hand's opening too), then its low
level: a policy and its lookahead, or a planner's process, its prior where not the coarse path (the first low levels'
folders name none), its stride and NFE; then the paths' replanning where each first step ends
(``--replan-after-step``) and where an object left its plan (``--replan-object-tolerance``)."""
REGENERATED = "regenerated-data/"
"""The folder of rows made on a dataset generated again by the same recipe on another machine, whose arrays are not
the other rows' (the rows' ``dataset_identity``: the arrays' sha256; docs/usage.md says why): compared with each
other, not with the rows beside them."""
LAST = 3
"""Evaluations OGBench averages per training seed (its last three, at 800 k, 900 k and 1 M steps; here 10 k, 15 k and
20 k)."""


def folder(scene: str) -> str:
    """The folder under docs/results of dataset ``scene``'s rows (``manip-cube-single``)."""
    return f"manip-{scene}"


def published(scene: str, method: str) -> str | None:
    if method not in PEERS:
        return None
    return f"{PUBLISHED[scene][PEERS.index(method)]} {BUDGET}"


def published_line(scene: str) -> str:
    """Dataset ``scene``'s published GCBC and GCIQL, with their budget."""
    return f"GCBC {PUBLISHED[scene][0]}, GCIQL {PUBLISHED[scene][1]} {BUDGET}"


def label(method: str, found: list[dict]) -> str:
    """A method's name in the README: its label, or for the graph its settings (its folder's) and replanning."""
    m = GRAPH_FOLDER.fullmatch(method)
    if m is None:
        return LABELS.get(method, method)
    every = {r["execution"].get("replan_every") for r in found if r["method"] == method}
    replan = f", replanned every {every.pop()} steps" if len(every) == 1 and None not in every else ""
    if m[8]:
        replan += f" and {m[8]} steps after a path's first step ends"
    if m[9]:  # the cubes' columns: 10 per metre
        replan += f" and where a cube is more than {10 * float(m[9]):g} cm from its plan"
    first = next(r for r in found if r["method"] == method)
    graph = first.get("graph", {})
    hand = ", the window's and its button's graphs measuring the hand's opening too" if m[3] == "-objects-hand" else ""
    apart = ("" if not m[3] else ", the buttons' presses solved (Lights Out), the arm's way to each searched"
             if "buttons" in graph else ", one graph per part (cube, buttons, drawer, window), their steps in order"
             if "paths_per_part" in graph else ", one graph per cube")
    if m[6]:  # a planner low level: its settings are its rows'
        row = next(r for r in found if r["method"] == method)
        low, ex = row["low"], row["execution"]
        return (f"the dataset graph (every {m[1]}th state, radius {m[2]}, searched again every "
                f"{ex['replan_high_every']} steps), its path's states every {low['subgoal_every'] * low['stride']} "
                f"steps the subgoals of a {low['method']} low level ({low['config']['preset']}, "
                f"{low['step'] // 1000} k steps, {low['horizon']} states {low['stride']} steps apart, NFE "
                f"{low['nfe']}) replanned every {ex['replan_every']} steps")
    if m[4]:  # a policy low level
        return (f"the dataset graph (every {m[1]}th state, radius {m[2]}{apart}{replan}), its paths executed by "
                f"the policy of {LABELS[m[4]]} toward the path's state {m[5]} steps on")
    data = ("; on the recipe's data generated again here" + (f", sha256 {first['data']}" if first["data"] else "")
            if method.startswith(REGENERATED) else "")
    return f"the dataset graph (no network: every {m[1]}th state, radius {m[2]}{apart}{hand}{replan}{data})"


def rows(root: Path, scene: str) -> list[dict]:
    """Every evaluation JSON under dataset ``scene``'s folder, with the method it is of (the file's or its folder's
    stem before ``-s<seed>``, below the dataset's folder: ``regenerated-data/graph-...``), that training seed (None: no
    training), whether it is on the validation tasks and the first 16 hex digits of its data's sha256 (None: not
    recorded)."""
    out = []
    home = Path(root) / folder(scene)
    for path in sorted(home.rglob("*.json")):
        d = read_evaluation(path)
        name = path.parent.relative_to(home).as_posix() if path.parent != home else path.stem
        validation = any(int(t) > 5 for t in d["tasks"])
        seed = re.search(r"-s(\d+)", name)
        data = re.search(r"sha256 ([0-9a-f]+)", d.get("config", {}).get("dataset_identity", ""))
        out.append({**d, "method": name.split("-s")[0], "validation": validation,
                    "training_seed": int(seed[1]) if seed else None, "data": data[1] if data else None})
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
    """Each method's success (%) on the test tasks at its last snapshot, one per training seed (the graph: one per
    evaluation seed)."""
    out: dict[str, list[float]] = {}
    for r in final(found):
        if not r["validation"]:
            out.setdefault(r["method"], []).append(100 * r["success_rate"])
    return dict(sorted(out.items()))


def curves(found: list[dict]) -> dict[str, dict[int, dict[int, float]]]:
    """The test success (%) of GCBC, GCIQL and each other trained method evaluated at more than one snapshot (a
    planner low level), by training seed and snapshot step: ``{method: {seed: {step: rate}}}``."""
    out: dict[str, dict[int, dict[int, float]]] = {}
    for r in found:
        seed = r["train_seed"] if r["method"] in PEERS else r["training_seed"]
        if seed is not None and not r["validation"]:
            out.setdefault(r["method"], {}).setdefault(seed, {})[r["step"]] = 100 * r["success_rate"]
    return {m: per_seed for m, per_seed in out.items()
            if m in PEERS or len({k for by_step in per_seed.values() for k in by_step}) > 1}


def ogbench_average(per_seed: dict[int, dict[int, float]], final_step: int) -> list[float]:
    """Per training seed whose last :data:`LAST` evaluations run up to ``final_step``, their mean (OGBench's
    averaging)."""
    out = []
    for by_step in per_seed.values():
        last = sorted(by_step)[-LAST:]
        if len(last) == LAST and last[-1] == final_step:
            out.append(sum(by_step[k] for k in last) / LAST)
    return out


def best_planner(found: list[dict]) -> tuple[str, list[float]] | None:
    """The best of bridgeplan's planners (every method but the peers) on the test tasks, by mean success, of equal
    means the one on more seeds: its method and its rates (one per training seed)."""
    mine = {m: r for m, r in test_rates(found).items() if m not in PEERS}
    if not mine:
        return None
    return max(mine.items(), key=lambda item: (sum(item[1]) / len(item[1]), len(item[1])))


def _margin(mine: float, theirs: float) -> str:
    return f"{mine - theirs:+.1f}"


def bests(root: Path) -> list[tuple[str, list[dict], str, list[float], list[float] | None]]:
    """Per dataset with a planner's rows: the dataset, its rows, its best planner (:func:`best_planner`) with its test
    rates, and GCIQL's test rates here (None: not trained here)."""
    out = []
    for scene in SCENES:
        found = rows(root, scene)
        best = best_planner(found)
        if best is not None:
            out.append((scene, found, *best, test_rates(found).get("gciql")))
    return out


def _rates(rates: list[float]) -> str:
    return fmt_mean_se(rates, one_seed="mean") + (f" ({len(rates)} seeds)" if len(rates) > 1 else " (one run)")


def goal_table(root: Path) -> list[str]:
    """Per dataset with rows, the best planner against GCIQL measured here, GCIQL's published number and the best
    reported: by how much it is above or below each (points of success); what limits it: its study file."""
    body = []
    for scene, _, method, rates, gciql in bests(root):
        mean = sum(rates) / len(rates)
        here = (f"{fmt_mean_se(gciql, one_seed='mean')} ({_margin(mean, sum(gciql) / len(gciql))})" if gciql
                else "not trained here")
        body.append([scene, f"{method}: {_rates(rates)}", here,
                     f"{PUBLISHED[scene][1]} ({_margin(mean, PUBLISHED[scene][1])})",
                     f"{BEST_REPORTED[scene]} ({_margin(mean, BEST_REPORTED[scene])})",
                     f"`studies/{folder(scene)}.toml`"])
    if not body:
        return []
    return ["## Against the goal", "",
            "The best bridgeplan planner per dataset (every method but GCBC and GCIQL, by its mean test success) "
            "against GCIQL measured here (20 k steps), GCIQL's published number (8 seeds, 1 M steps) and the best "
            "any method has reported (about: later papers, secondary sources); in brackets the best planner's "
            "margin in points of success. Its study file says what limits it.", "",
            *table(["dataset", "best planner: success (%)", "GCIQL here (margin)", "GCIQL published (margin)",
                    "best reported (margin)", "what limits it"], body)]


def block(root: Path) -> str:
    """The README's table: per dataset, its best planner (named in words) and its success on the 5 test tasks beside
    GCIQL's here and published; every method's rows are the page's."""
    body = [[f"{scene}-play-v0", label(method, found), _rates(rates),
             _rates(gciql) if gciql else "not trained here", f"{PUBLISHED[scene][1]} {BUDGET}"]
            for scene, found, method, rates, gciql in bests(root)]
    if not body:
        return "No rows yet (`bridgeplan study run manip-cube-single`)."
    return "\n".join(table(["dataset", "best planner", "success (%)", "GCIQL here (20 k steps)", "GCIQL published"],
                           body))


def low_levels(found: list[dict]) -> list[str]:
    """The dataset graph over each planner low level side by side (the thesis's comparison where the graph is the high
    level): each process at each NFE on the test tasks, mean ± SE over training seeds, and its difference with DDPM's
    at its largest NFE paired by training seed, with the verdict at 2 standard errors (:func:`compare`)."""
    by: dict[tuple[str, str, int], dict[int, float]] = {}  # (process, prior, NFE) -> training seed -> success
    ms: dict[tuple[str, str, int], list[float]] = {}
    names: dict[tuple[str, str], str] = {}
    alone = set()  # the graph's first paths through the subgoals executed without a network (one per evaluation)
    for r in final(found):
        m = GRAPH_FOLDER.fullmatch(r["method"])
        if m is None or not m[6] or r["validation"]:
            continue
        key = (m[6], m[7] or "", r["low"]["nfe"])
        names[key[:2]] = r["low"]["method"]
        if "high_alone" in r:
            alone.add(round(100 * r["high_alone"]["success_rate"], 6))
        by.setdefault(key, {})[r["training_seed"]] = 100 * r["success_rate"]
        if "decision_ms_batch1" in r:
            ms.setdefault(key, []).append(r["decision_ms_batch1"]["p50"])
    if not by:
        return []
    ddpm = max((k for k in by if k[0] == "ddpm"), key=lambda k: k[2], default=None)
    body = []
    for key, rates in sorted(by.items()):
        vs, verdict = "-", "-"
        if ddpm is not None and key != ddpm:
            d = paired(rates, by[ddpm], seeds="common")
            vs = f"{fmt_diff(d)} ({d.n})" if d.n > 1 else f"{d.mean:+.1f} (1)"
            verdict = compare(d) if d.n > 1 else "-"
        body.append([names[key[:2]], key[2], len(rates), fmt_mean_se(rates, one_seed="mean"), vs, verdict,
                     f"{sum(ms[key]) / len(ms[key]):.1f}" if key in ms else "-"])
    reference = f"DDPM at NFE {ddpm[2]}" if ddpm else "DDPM"
    line = ("bridge", "line", 1)
    priors = []  # the thesis's comparison of priors: each bridge at one network call against the plain line's
    if line in by:
        for key in sorted(k for k in by if k[0] == "bridge" and k[2] == 1 and k != line):
            d = paired(by[key], by[line], seeds="common")
            if d.n > 1:
                priors.append(f"{names[key[:2]]} {fmt_diff(d)} ({d.n} seeds, {compare(d)})")
    if priors:
        priors = ["", f"The bridge's priors at NFE 1, each paired by training seed with {names[line[:2]]}'s (the "
                      f"thesis's comparison of priors; verdict at 2 standard errors): {'; '.join(priors)}."]
    floor = []
    if alone:
        floor = ["", "Without a network: the graph's first path through the same subgoals, a straight line between "
                     "them, executed open loop by the same controller (each row's `high_alone`, what the low level "
                     f"must add to): {' / '.join(f'{a:.1f}' for a in sorted(alone))} % of the test episodes."]
    return ["", "The dataset graph over a diffusion planner low level (the graph's path the subgoals; the rows above "
                "named graph-...-k4-nfeN), by the low level's process and NFE: test tasks, mean ± standard error over "
                f"training seeds, the difference with {reference} paired by training seed (its verdict: better or "
                "worse beyond 2 standard errors, else tie), and the median decision's milliseconds at batch 1 (high "
                "and low level together, one CPU thread; mean over seeds):", "",
            *table(["low level", "NFE", "seeds", "success (%)", f"minus {reference} (paired)", "verdict",
                    "decision ms at batch 1"], body), *priors, *floor]


SETTINGS = ((r"-objects-hand", "-objects"), (r"-objtol[\d.]+", ""))
"""A graph's settings that a folder names (the hand measured; searched again where an object left its plan), each
with what its folder is without it: :func:`setting_pairs` pairs the two."""


def setting_pairs(found: list[dict]) -> list[str]:
    """Each graph with a setting of :data:`SETTINGS` against the same graph without it on the same data, on the test
    tasks paired by evaluation seed (the same episodes), with the verdict at 2 standard errors."""
    by: dict[str, dict[int, float]] = {}
    for r in final(found):
        if not r["validation"] and GRAPH_FOLDER.fullmatch(r["method"]):
            by.setdefault(f"{r['method']} {r['data']}", {})[r["seed"]] = 100 * r["success_rate"]
    out = []
    for key, rates in sorted(by.items()):
        for setting, plain in SETTINGS:
            without = re.sub(setting, plain, key)
            if without != key and without in by:
                d = paired(rates, by[without], seeds="common")
                verdict = f" ({d.n} seeds, {compare(d)})" if d.n > 1 else " (1 seed)"
                out.append(f"{key.split()[0]} minus {without.split()[0]}: {fmt_diff(d)}{verdict}")
    return ["", "A graph's setting against the same graph without it (each row's replanning in its file's name), on "
                "the same data, paired by evaluation seed (test tasks; verdict: better or worse beyond 2 standard "
                "errors, else tie): " + "; ".join(out) + "."] if out else []


def section(scene: str, found: list[dict]) -> list[str]:
    """Dataset ``scene``'s tables: every method at its last snapshot, then GCBC and GCIQL against training steps."""
    lines = [f"## {scene}-play-v0", "", f"Rows in docs/results/{folder(scene)}/ ({SCENES[scene].eval_steps} steps per "
             f"episode). OGBench published: {published_line(scene)}. The data column: the first hex digits of the "
             f"dataset's arrays' sha256 where the rows record it (GCBC's and GCIQL's do not); rows under "
             f"{REGENERATED} were made on the recipe's data generated again on another machine, whose arrays differ.",
             ""]
    body = []
    for method in sorted({r["method"] for r in found}):
        for validation in (False, True):
            mine = [r for r in final(found) if r["method"] == method and r["validation"] == validation]
            if mine:
                rates = [100 * r["success_rate"] for r in mine]
                beside = "" if validation else published(scene, method) or "-"
                data = ", ".join(sorted({r["data"] for r in mine if r["data"]})) or "-"
                body.append([method, "validation (tasks 6-10)" if validation else "test", len(mine),
                             fmt_mean_se(rates, one_seed="mean"), beside, data])
    lines += table(["method", "tasks", "seeds", "success (%)", "published", "data (sha256)"], body)
    lines += setting_pairs(found)
    lines += low_levels(found)
    found_curves = curves(found)
    if found_curves:
        steps = sorted({k for per_seed in found_curves.values() for by_step in per_seed.values() for k in by_step})
        others = "" if set(found_curves) <= set(PEERS) else " and the planners evaluated at more than one snapshot"
        lines += ["", f"GCBC and GCIQL{others} against training steps (test tasks; mean ± standard error over the "
                      f"training seeds evaluated at that step), and as OGBench averages (per seed the mean of its last "
                      f"{LAST} evaluations, then over seeds):", ""]
        curve_rows = []
        for method, per_seed in sorted(found_curves.items()):
            at = [[by_step[k] for by_step in per_seed.values() if k in by_step] for k in steps]
            average = ogbench_average(per_seed, last_steps(found)[method])
            curve_rows.append([method, *(f"{fmt_mean_se(v, one_seed='mean')} ({len(v)})" if v else "-" for v in at),
                               f"{fmt_mean_se(average, one_seed='mean')} ({len(average)})" if average else "-"])
        lines += table(["method", *(f"{k // 1000} k steps" for k in steps), f"OGBench's average (last {LAST})"],
                       curve_rows)
    return lines


def render(root: Path) -> str:
    lines = ["# OGBench manipulation: GCBC, GCIQL, planners and the dataset graph by OGBench's protocol", "",
             "Generated by `bridgeplan study report manipulation` from the JSONs in docs/results/manip-*/ (one folder "
             "per dataset, each made by its study, studies/manip-*.toml). Datasets generated locally by OGBench's play "
             "recipe (`bridgeplan data generate --maze NAME`); success (%) over the 5 test tasks (50 episodes per "
             "task, evaluation seed 0), mean ± standard error over training seeds (a method without training: over "
             "the evaluation seeds its study lists); validation rows on tasks 6-10."]
    sections = [section(scene, found) for scene in SCENES if (found := rows(root, scene))]
    if not sections:
        return "\n".join([*lines, "", "No rows yet: `bridgeplan study run manipulation`, then `bridgeplan study "
                                      "export manipulation`."])
    return "\n".join(lines + ["", *goal_table(root)] + [line for s in sections for line in ["", *s]])
