"""The findings table (issue 12): each thesis finding, and ours, per maze and task set, from the committed
results CSVs (docs/results/<maze>-v2-curves/results.csv; for runs trained on windows that wait,
docs/results/<maze>-v2-hold/results.csv; for the consistent bridge from each prior,
docs/results/<maze>-v2-consistent-priors/results.csv; written by `bridgeplan report --csv`).

A finding compares two series on the same evaluation episodes, training seed by training seed: the cell is
the mean ± standard error over seeds of the per-seed difference (first minus second, Minari convention) and
a verdict: "holds" when the difference is more than two standard errors on the finding's side, "does not"
when it is more than two on the other side, "not decidable" in between. For "not below" findings (a score
kept), "holds" means not more than two standard errors below. Series are taken at the last training step
both have (or the first, where the finding says so); "full" is each method's most NFE, "best" the NFE with
the best mean over seeds on the validation episodes (rows of `<experiment>-validation`, made by `experiment
--validation`: other tasks than the reported ones), whose score on the reported (test) episodes the cell uses.

Usage: python docs/results/findings.py > docs/results/findings.md
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from bridgeplan.experiments.runner import VALIDATION_SUFFIX
from bridgeplan.report import method_label

HERE = Path(__file__).resolve().parent
MAZES = ("umaze", "medium", "large")
FLOOR = "floor"


class Eval(NamedTuple):
    """One evaluation row (one training seed): Minari score, the line floor, success rate, network calls per
    episode and timings."""

    score: float
    floor: float
    success: float
    calls: float
    plan_ms: float
    """Milliseconds per plan, planned in one batch with the other episodes."""
    decision_ms: tuple[float, float] | None
    """Closed loop: a decision's p50 and p95 milliseconds at batch 1 (None open loop)."""

VALIDATION = "validation"
PURSUIT = ("pursuit0.5", "pursuit1", "pursuit1.5")
"""The open-loop pursuit executions of the controllers experiment: findings choose one on validation episodes."""

# (finding, (method, nfe, execution), (method or FLOOR, nfe, execution), rule, step)
FINDINGS = [
    ("Thesis: the bridge holds its score down to NFE 1 (Gaussian prior, NFE 1 vs full)",
     ("bridge (gaussian)", 1, ""), ("bridge (gaussian)", "full", ""), "not below", "last"),
    ("Thesis: at NFE 1 the bridge beats DDPM (line prior)",
     ("bridge (line)", 1, ""), ("DDPM", 1, ""), "above", "last"),
    ("Thesis: at NFE 1 the bridge beats DDPM (learned prior)",
     ("bridge (learned)", 1, ""), ("DDPM", 1, ""), "above", "last"),
    ("Thesis: at full NFE, from Gaussian noise, DDPM beats the bridge",
     ("DDPM", "full", ""), ("bridge (gaussian)", "full", ""), "above", "last"),
    ("Thesis: early in training an informative prior helps (line vs Gaussian, NFE 4, first snapshot)",
     ("bridge (line)", 4, ""), ("bridge (gaussian)", 4, ""), "above", "first"),
    ("Thesis: early in training an informative prior helps (learned vs Gaussian, NFE 4, first snapshot)",
     ("bridge (learned)", 4, ""), ("bridge (gaussian)", 4, ""), "above", "first"),
    ("Thesis: the learned prior beats the straight line (NFE 4)",
     ("bridge (learned)", 4, ""), ("bridge (line)", 4, ""), "above", "last"),
    ("Thesis schedule: beta_max 0.3 beats the default 1.0 (line prior, NFE 1)",
     ("bridge (line; beta_max=0.3)", 1, ""), ("bridge (line)", 1, ""), "above", "last"),
    ("Ours: the bridge (line) at NFE 1 clears the straight-line floor",
     ("bridge (line)", 1, ""), (FLOOR, 1, ""), "above", "last"),
    ("Ours: DDPM at its best NFE clears the straight-line floor",
     ("DDPM", "best", ""), (FLOOR, 1, ""), "above", "last"),
    ("Ours: flow matching (line) at NFE 2 reaches DDPM's best NFE",
     ("flow (line)", 2, ""), ("DDPM", "best", ""), "not below", "last"),
    ("Ours: flow matching (line) at NFE 2 beats the I2SB bridge's best NFE (line)",
     ("flow (line)", 2, ""), ("bridge (line)", "best", ""), "above", "last"),
    ("Ours: the consistent bridge beats I2SB (line prior, NFE 2)",
     ("bridge (line; consistent=True)", 2, ""), ("bridge (line)", 2, ""), "above", "last"),
    ("Ours: the consistent bridge beats I2SB (Gaussian prior, NFE 2)",
     ("bridge (gaussian; consistent=True)", 2, ""), ("bridge (gaussian)", 2, ""), "above", "last"),
    ("Ours: the consistent bridge beats I2SB (learned prior, NFE 2)",
     ("bridge (learned; consistent=True)", 2, ""), ("bridge (learned)", 2, ""), "above", "last"),
    ("Ours: pursuit (lookahead chosen on validation) beats Diffuser's tracking (bridge, line, NFE 1, open loop)",
     ("bridge (line)", 1, PURSUIT), ("bridge (line)", 1, ""), "above", "last"),
    ("Ours: pursuit (lookahead chosen on validation) beats Diffuser's tracking (DDPM, full NFE, open loop)",
     ("DDPM", "full", PURSUIT), ("DDPM", "full", ""), "above", "last"),
    ("Ours: pursued, the bridge at NFE 1 reaches DDPM at full NFE (line prior, open loop)",
     ("bridge (line)", 1, PURSUIT), ("DDPM", "full", PURSUIT), "not below", "last"),
    ("Ours: pursued, replanning every 32 steps beats open loop (bridge, line, NFE 1, warm, lookahead 1)",
     ("bridge (line)", 1, "replan32-warm-pursuit1"), ("bridge (line)", 1, "pursuit1"), "above", "last"),
    ("Ours: replanning every 32 steps beats open loop (bridge, line, NFE 1, warm, arrival kept)",
     ("bridge (line)", 1, "replan32-warm-arrival-keep"), ("bridge (line)", 1, ""), "above", "last"),
    ("Loss ablation: an x0 output beats I2SB's scaled difference, same loss (line, NFE 1, first snapshot)",
     ("bridge (line; predict=x0)", 1, ""), ("bridge (line)", 1, ""), "above", "first"),
    ("Loss ablation: an x0 output beats I2SB's scaled difference, same loss (line, NFE 1)",
     ("bridge (line; predict=x0)", 1, ""), ("bridge (line)", 1, ""), "above", "last"),
    ("Loss ablation: Diffuser's equal weight per step beats I2SB's (line, NFE 1, first snapshot)",
     ("bridge (line; weighting=uniform)", 1, ""), ("bridge (line)", 1, ""), "above", "first"),
    ("Loss ablation: Diffuser's equal weight per step beats I2SB's (line, NFE 1)",
     ("bridge (line; weighting=uniform)", 1, ""), ("bridge (line)", 1, ""), "above", "last"),
    ("Ours: training windows that wait (hold 0.5) raise DDPM's open-loop score (NFE 1)",
     ("DDPM, hold 0.5", 1, ""), ("DDPM", 1, ""), "above", "last"),
    ("Ours: training windows that wait (hold 0.5) raise the bridge's open-loop score (line, NFE 1)",
     ("bridge (line), hold 0.5", 1, ""), ("bridge (line)", 1, ""), "above", "last"),
    ("Ours: holds make replanning pay: DDPM replanned every 32 steps, with vs without holds (NFE 1)",
     ("DDPM, hold 0.5", 1, "replan32"), ("DDPM", 1, "replan32"), "above", "last"),
    ("Ours: DDPM with holds replanned every 32 steps beats DDPM without holds open loop (NFE 1)",
     ("DDPM, hold 0.5", 1, "replan32"), ("DDPM", 1, ""), "above", "last"),
    ("Ours: with holds, replanning every 32 steps beats open loop (DDPM, NFE 1, arrival kept)",
     ("DDPM, hold 0.5", 1, "replan32-arrival-keep"), ("DDPM, hold 0.5", 1, ""), "above", "last"),
    ("Ours: with holds, replanning every 32 steps beats open loop (bridge, line, NFE 1, warm, as sampled)",
     ("bridge (line), hold 0.5", 1, "replan32-warm"), ("bridge (line), hold 0.5", 1, ""), "above", "last"),
]


STORES = ("curves", "hold", "consistent-priors")
"""The maze's stores (docs/results/<maze>-v2-<store>), in order of precedence: a row another store holds too
(a run retrained in a store of its own) is taken from the first."""


def rows(maze: str, stores=STORES):
    """The maze's CSV rows, store by store."""
    paths = [HERE / f"{maze}-v2-{store}" / "results.csv" for store in stores]
    return (r for path in paths if path.exists() for r in csv.DictReader(path.open()))


def method(row: dict) -> str:
    """A row's method, with the sampler where it is not the process's default: ``bridge (line) by mean``."""
    return method_label(row) + (f" by {row['sampler']}" if row.get("sampler") else "")


def load(maze: str, stores=STORES) -> dict:
    """``{(method, multi, execution): {step: {nfe: {seed: Eval}}}}`` from the maze's CSVs, test
    episodes; the validation episodes' rows under the key ``VALIDATION``, in the same shape."""
    table: dict = {VALIDATION: {}}
    for r in rows(maze, stores):
        into = table[VALIDATION] if r["experiment"].endswith(VALIDATION_SUFFIX) else table
        key = (method(r), int(r.get("multi_task") or 0), r.get("execution") or "")
        cell = into.setdefault(key, {}).setdefault(int(r["step"]), {}).setdefault(int(r["nfe"]), {})
        decision = (float(r["decision_ms_p50"]), float(r["decision_ms_p95"])) if r.get("decision_ms_p50") else None
        cell.setdefault(int(r["seed"]), Eval(float(r["score_minari"]), float(r["floor_minari"]),
                                             float(r["success_rate"]), float(r["calls_per_episode"] or r["nfe"]),
                                             float(r["plan_ms"]), decision))
    return table


def _mean(by_seed: dict) -> float:
    return float(np.mean([e.score for e in by_seed.values()]))


def choose(table: dict, spec, multi: int, step: int) -> tuple[int, str] | None:
    """The (NFE, execution) ``spec`` = (method, nfe, execution) stands for at ``step``: ``nfe`` a number,
    "full" (the most NFE evaluated) or "best"; ``execution`` a tag or a tuple of tags to choose among. A choice
    ("best", a tuple) is, among the options evaluated on the validation episodes too, the one with the best
    mean over seeds there; None when there is none."""
    method, nfe, execution = spec
    options = []
    for ex in execution if isinstance(execution, tuple) else (execution,):
        by_nfe = table.get((method, multi, ex), {}).get(step, {})
        nfes = list(by_nfe) if nfe == "best" else [max(by_nfe)] if nfe == "full" and by_nfe else [nfe]
        options += [(k, ex) for k in nfes if k in by_nfe]
    if len(options) <= 1 and nfe != "best" and not isinstance(execution, tuple):
        return options[0] if options else None
    validated = [(o, table[VALIDATION].get((method, multi, o[1]), {}).get(step, {}).get(o[0])) for o in options]
    validated = [(o, by_seed) for o, by_seed in validated if by_seed]
    return max(validated, key=lambda o: _mean(o[1]))[0] if validated else None


def series(table: dict, spec, multi: int, step: int) -> dict[int, float] | None:
    """Per-seed scores of ``spec`` = (method or FLOOR, nfe, execution) at ``step``, test episodes."""
    method = spec[0]
    if method == FLOOR:  # the floor of the other series' episodes: any open-loop tracked series carries it
        for (m, mt, ex), steps in ((k, v) for k, v in table.items() if k != VALIDATION):
            if mt == multi and ex == "" and step in steps:
                at = next(iter(steps[step].values()))
                return {seed: e.floor for seed, e in at.items()}
        return None
    chosen = choose(table, spec, multi, step)
    if chosen is None:
        return None
    nfe, execution = chosen
    return {seed: e.score for seed, e in table[(method, multi, execution)][step][nfe].items()}


def _steps(table: dict, spec, multi: int) -> set[int]:
    executions = spec[2] if isinstance(spec[2], tuple) else (spec[2],)
    return {step for ex in executions for step in table.get((spec[0], multi, ex), {})}


def cell(table: dict, finding, multi: int) -> str:
    _, a, b, rule, which = finding
    steps_a = _steps(table, a, multi)
    steps_b = _steps(table, b, multi) if b[0] != FLOOR else steps_a
    common = sorted(steps_a & steps_b)
    if not common:
        return "not measured"
    step = common[0] if which == "first" else common[-1]
    picks = {spec: choose(table, spec, multi, step) for spec in (a, b)
             if spec[0] != FLOOR and (spec[1] == "best" or isinstance(spec[2], tuple))}
    if None in picks.values():
        return "no validation episodes"
    sa, sb = series(table, a, multi, step), series(table, b, multi, step)
    seeds = sorted(set(sa or {}) & set(sb or {}))
    if len(seeds) < 2:
        return "not measured" if not seeds else f"1 seed only ({sa[seeds[0]] - sb[seeds[0]]:+.1f})"
    d = np.array([sa[s] - sb[s] for s in seeds])
    mean, se = float(d.mean()), float(d.std(ddof=1) / np.sqrt(len(d)))
    if rule == "above":
        verdict = "holds" if mean - 2 * se > 0 else "does not" if mean + 2 * se < 0 else "not decidable"
    else:  # not below
        verdict = "holds" if mean + 2 * se >= 0 else "does not"
    picked = "".join(f", {spec[0]}: NFE {k}{' ' + ex if ex else ''}" for spec, (k, ex) in picks.items())
    return f"{verdict}: {mean:+.1f} ± {se:.1f} (step {step}, {len(seeds)} seeds{picked})"


def goal_cell(table: dict, multi: int, expert: list[float]) -> str:
    """Issue 13's goal: the best setting on the validation episodes (any method, NFE and execution evaluated
    there, each at its final snapshot), its score on the test episodes (mean ± standard error over seeds),
    success rate, network calls per episode and timing (medians over seeds), against 95 and the expert on the
    same test episodes."""
    options = [(key, step, nfe, _mean(by_seed)) for key, steps in table[VALIDATION].items() if key[1] == multi
               for step, by_nfe in steps.items() for nfe, by_seed in by_nfe.items()]
    if not options:
        return "no validation episodes"
    (method, _, execution), step, nfe, _ = max(options, key=lambda o: o[3])
    test = table.get((method, multi, execution), {}).get(step, {}).get(nfe)
    if not test:
        return "not measured on the test episodes"
    scores = np.array([e.score for e in test.values()])
    se = scores.std(ddof=1) / np.sqrt(len(scores)) if len(scores) > 1 else float("nan")
    met = "met" if scores.mean() >= 95 else "not met"
    decisions = [e.decision_ms for e in test.values() if e.decision_ms]
    timing = (f"decision p50/p95 {np.median([d[0] for d in decisions]):.1f}/{np.median([d[1] for d in decisions]):.1f}"
              f" ms at batch 1" if decisions else
              f"{np.median([e.plan_ms for e in test.values()]):.2f} ms per plan in a batch of the episodes")
    return (f"{met}: {scores.mean():.1f} ± {se:.1f} ({method}, NFE {nfe}, {execution or 'open loop, track'}; "
            f"success {np.mean([e.success for e in test.values()]):.2f}, "
            f"{np.mean([e.calls for e in test.values()]):.0f} calls/episode, {timing}; "
            f"expert {np.mean(expert):.1f})")


def main() -> int:
    tables = {maze: load(maze) for maze in MAZES}
    header = ["finding", *MAZES, *(f"{m} Multi2D" for m in MAZES)]
    lines = ["# Findings per maze", "",
             "Made by `python docs/results/findings.py` from docs/results/<maze>-v2-curves/results.csv "
             "(data version 2, `cpu-small`; umaze 128 states x 1, medium 32 x 8, large 48 x 8). Each cell: the "
             "per-seed difference, first series minus second, mean ± standard error over training seeds "
             "(Minari convention), and the verdict at two standard errors (see the script's docstring).", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for finding in FINDINGS:
        cells = [cell(tables[m], finding, 0) for m in MAZES] + [cell(tables[m], finding, 1) for m in MAZES]
        lines.append(f"| {finding[0]} | " + " | ".join(cells) + " |")
    expert = json.loads((HERE / "expert-on-eval-tasks.json").read_text())["rows"]
    lines += ["", "## Issue 13's goal: a Minari score of 95 or more", "",
              "The setting (method, NFE, execution) with the best mean on the validation episodes "
              "(`experiment --validation`: nfe-curves and controllers), scored on the test episodes; the expert "
              "on the same test episodes from expert-on-eval-tasks.json.", "",
              "| maze | single-task | Multi2D |", "|---|---|---|"]
    for m in MAZES:
        cells = [goal_cell(tables[m], multi, [r["score_minari"] for r in expert
                                              if r["maze"] == m and r["multi_task"] == bool(multi)])
                 for multi in (0, 1)]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
