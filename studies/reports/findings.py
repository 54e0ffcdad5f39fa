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

Made by `bridgeplan study report findings` (studies/findings.toml) into docs/results/findings.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridgeplan.analysis.keys import OPEN_LOOP, label, method
from bridgeplan.analysis.load import Results, load_csvs
from bridgeplan.analysis.selection import BEST, FULL, Choice, best, resolve
from bridgeplan.analysis.selection import steps as choice_steps
from bridgeplan.analysis.stats import finding_verdict, mean_se, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, table
from bridgeplan.replan import Execution

from .headline import expert_rows

MAZES = ("umaze", "medium", "large")
FLOOR = "floor"
"""The second series of a finding that compares with the straight line, tracked alone, on the same episodes."""
N = 16
"""Diffusion steps of every run in these stores."""

DDPM = method("ddpm", steps=N)
FLOW_LINE = method("flow", "line", steps=N)


def bridge(prior: str, **params):
    return method("bridge", prior, steps=N, **params)


def at(key, nfe, among=None, **execution) -> Choice:
    """``key`` at ``nfe``, executed by ``Execution(**execution)`` (open loop, tracked, by default) or chosen
    ``among`` executions on the validation episodes."""
    return Choice(key.replace(execution=Execution(**execution)), nfe, among)


PURSUIT = tuple(Execution(controller="pursuit", lookahead=r) for r in (0.5, 1, 1.5))
"""The open-loop pursuit executions of the controllers experiment: findings choose one on validation episodes."""
REPLAN = 32

# (finding, first series, second series or FLOOR, rule, step)
FINDINGS = [
    ("Thesis: the bridge holds its score down to NFE 1 (Gaussian prior, NFE 1 vs full)",
     at(bridge("gaussian"), 1), at(bridge("gaussian"), FULL), "not below", "last"),
    ("Thesis: at NFE 1 the bridge beats DDPM (line prior)",
     at(bridge("line"), 1), at(DDPM, 1), "above", "last"),
    ("Thesis: at NFE 1 the bridge beats DDPM (learned prior)",
     at(bridge("learned"), 1), at(DDPM, 1), "above", "last"),
    ("Thesis: at full NFE, from Gaussian noise, DDPM beats the bridge",
     at(DDPM, FULL), at(bridge("gaussian"), FULL), "above", "last"),
    ("Thesis: early in training an informative prior helps (line vs Gaussian, NFE 4, first snapshot)",
     at(bridge("line"), 4), at(bridge("gaussian"), 4), "above", "first"),
    ("Thesis: early in training an informative prior helps (learned vs Gaussian, NFE 4, first snapshot)",
     at(bridge("learned"), 4), at(bridge("gaussian"), 4), "above", "first"),
    ("Thesis: the learned prior beats the straight line (NFE 4)",
     at(bridge("learned"), 4), at(bridge("line"), 4), "above", "last"),
    ("Thesis schedule: beta_max 0.3 beats the default 1.0 (line prior, NFE 1)",
     at(bridge("line", beta_max=0.3), 1), at(bridge("line"), 1), "above", "last"),
    ("Ours: the bridge (line) at NFE 1 clears the straight-line floor",
     at(bridge("line"), 1), FLOOR, "above", "last"),
    ("Ours: DDPM at its best NFE clears the straight-line floor",
     at(DDPM, BEST), FLOOR, "above", "last"),
    ("Ours: flow matching (line) at NFE 2 reaches DDPM's best NFE",
     at(FLOW_LINE, 2), at(DDPM, BEST), "not below", "last"),
    ("Ours: flow matching (line) at NFE 2 beats the I2SB bridge's best NFE (line)",
     at(FLOW_LINE, 2), at(bridge("line"), BEST), "above", "last"),
    ("Ours: the consistent bridge beats I2SB (line prior, NFE 2)",
     at(bridge("line", consistent=True), 2), at(bridge("line"), 2), "above", "last"),
    ("Ours: the consistent bridge beats I2SB (Gaussian prior, NFE 2)",
     at(bridge("gaussian", consistent=True), 2), at(bridge("gaussian"), 2), "above", "last"),
    ("Ours: the consistent bridge beats I2SB (learned prior, NFE 2)",
     at(bridge("learned", consistent=True), 2), at(bridge("learned"), 2), "above", "last"),
    ("Ours: pursuit (lookahead chosen on validation) beats Diffuser's tracking (bridge, line, NFE 1, open loop)",
     at(bridge("line"), 1, PURSUIT), at(bridge("line"), 1), "above", "last"),
    ("Ours: pursuit (lookahead chosen on validation) beats Diffuser's tracking (DDPM, full NFE, open loop)",
     at(DDPM, FULL, PURSUIT), at(DDPM, FULL), "above", "last"),
    ("Ours: pursued, the bridge at NFE 1 reaches DDPM at full NFE (line prior, open loop)",
     at(bridge("line"), 1, PURSUIT), at(DDPM, FULL, PURSUIT), "not below", "last"),
    ("Ours: pursued, replanning every 32 steps beats open loop (bridge, line, NFE 1, warm, lookahead 1)",
     at(bridge("line"), 1, replan_every=REPLAN, warm=True, controller="pursuit", lookahead=1),
     at(bridge("line"), 1, controller="pursuit", lookahead=1), "above", "last"),
    ("Ours: replanning every 32 steps beats open loop (bridge, line, NFE 1, warm, arrival kept)",
     at(bridge("line"), 1, replan_every=REPLAN, warm=True, arrival="keep"), at(bridge("line"), 1), "above", "last"),
    ("Loss ablation: an x0 output beats I2SB's scaled difference, same loss (line, NFE 1, first snapshot)",
     at(bridge("line", predict="x0"), 1), at(bridge("line"), 1), "above", "first"),
    ("Loss ablation: an x0 output beats I2SB's scaled difference, same loss (line, NFE 1)",
     at(bridge("line", predict="x0"), 1), at(bridge("line"), 1), "above", "last"),
    ("Loss ablation: Diffuser's equal weight per step beats I2SB's (line, NFE 1, first snapshot)",
     at(bridge("line", weighting="uniform"), 1), at(bridge("line"), 1), "above", "first"),
    ("Loss ablation: Diffuser's equal weight per step beats I2SB's (line, NFE 1)",
     at(bridge("line", weighting="uniform"), 1), at(bridge("line"), 1), "above", "last"),
    ("Ours: training windows that wait (hold 0.5) raise DDPM's open-loop score (NFE 1)",
     at(DDPM.replace(hold_share=0.5), 1), at(DDPM, 1), "above", "last"),
    ("Ours: training windows that wait (hold 0.5) raise the bridge's open-loop score (line, NFE 1)",
     at(bridge("line", hold_share=0.5), 1), at(bridge("line"), 1), "above", "last"),
    ("Ours: holds make replanning pay: DDPM replanned every 32 steps, with vs without holds (NFE 1)",
     at(DDPM.replace(hold_share=0.5), 1, replan_every=REPLAN), at(DDPM, 1, replan_every=REPLAN), "above", "last"),
    ("Ours: DDPM with holds replanned every 32 steps beats DDPM without holds open loop (NFE 1)",
     at(DDPM.replace(hold_share=0.5), 1, replan_every=REPLAN), at(DDPM, 1), "above", "last"),
    ("Ours: with holds, replanning every 32 steps beats open loop (DDPM, NFE 1, arrival kept)",
     at(DDPM.replace(hold_share=0.5), 1, replan_every=REPLAN, arrival="keep"), at(DDPM.replace(hold_share=0.5), 1),
     "above", "last"),
    ("Ours: with holds, replanning every 32 steps beats open loop (bridge, line, NFE 1, warm, as sampled)",
     at(bridge("line", hold_share=0.5), 1, replan_every=REPLAN, warm=True), at(bridge("line", hold_share=0.5), 1),
     "above", "last"),
]


READS = tuple(dict.fromkeys(choice.method.replace(sampler="", execution=OPEN_LOOP, multi_task=False)
                            for finding in FINDINGS for choice in finding[1:3] if choice != FLOOR))
"""The trained methods the findings compare (studies that make this report must train them)."""

STORES = ("curves", "hold", "consistent-priors")
"""The maze's stores (docs/results/<maze>-v2-<store>), in order of precedence: a row another store holds too
(a run retrained in a store of its own) is taken from the first."""


def load(root: Path, maze: str, stores=STORES) -> Results:
    """The maze's rows, store by store (test and validation episodes)."""
    return load_csvs(root / f"{maze}-v2-{store}" / "results.csv" for store in stores)


def on(choice: Choice, multi: int) -> Choice:
    """``choice`` on the single-task (0) or Multi2D (1) tasks."""
    return Choice(choice.method.replace(multi_task=bool(multi)), choice.nfe, choice.among)


def floor(results: Results, multi: int, step: int) -> dict[int, float] | None:
    """Per-seed score of the straight line alone on the episodes of the task set at ``step``: any open-loop
    tracked series carries it."""
    for key in results.keys():
        if key.multi_task == bool(multi) and key.execution == OPEN_LOOP and step in results.steps(key):
            return results.values(results.points(key, step)[0], field="floor")
    return None


def cell(results: Results, finding, multi: int) -> str:
    _, a, b, rule, which = finding
    a = on(a, multi)
    b = on(b, multi) if b != FLOOR else b
    steps_a = choice_steps(results, a)
    steps_b = choice_steps(results, b) if b != FLOOR else steps_a
    common = sorted(steps_a & steps_b)
    if not common:
        return "not measured"
    step = common[0] if which == "first" else common[-1]
    picks = {choice: resolve(results, choice, step) for choice in (a, b) if choice != FLOOR and choice.chooses}
    if None in picks.values():
        return "no validation episodes"

    def series(choice):
        if choice == FLOOR:
            return floor(results, multi, step)
        point = resolve(results, choice, step)
        return results.values(point) if point else None

    sa, sb = series(a) or {}, series(b) or {}
    seeds = sorted(set(sa) & set(sb))
    if len(seeds) < 2:
        return "not measured" if not seeds else f"1 seed only ({sa[seeds[0]] - sb[seeds[0]]:+.1f})"
    d = paired(sa, sb, seeds="common")
    picked = "".join(f", {label(choice.method)}: NFE {point.nfe}{' ' + point.key.tag if point.key.tag else ''}"
                     for choice, point in picks.items())
    return f"{finding_verdict(d, rule)}: {fmt_diff(d)} (step {step}, {d.n} seeds{picked})"


def goal_cell(results: Results, multi: int, expert: list[float]) -> str:
    """Issue 13's goal: the best setting on the validation episodes (any method, NFE and execution evaluated
    there, each at its final snapshot), its score on the test episodes (mean ± standard error over seeds),
    success rate, network calls per episode and timing (medians over seeds), against 95 and the expert on the
    same test episodes."""
    options = [point for key in results.keys("validation") if key.multi_task == bool(multi)
               for step in results.steps(key, "validation") for point in results.points(key, step, "validation")]
    chosen = best(results, options, "validation")
    if chosen is None:
        return "no validation episodes"
    test = list(results.rows(chosen).values())
    if not test:
        return "not measured on the test episodes"
    scores = mean_se([e.score for e in test])
    met = "met" if scores.mean >= 95 else "not met"
    decisions = [e.decision_ms for e in test if e.decision_ms]
    timing = (f"decision p50/p95 {np.median([d[0] for d in decisions]):.1f}/{np.median([d[1] for d in decisions]):.1f}"
              f" ms at batch 1" if decisions else
              f"{np.median([e.plan_ms for e in test]):.2f} ms per plan in a batch of the episodes")
    return (f"{met}: {fmt_mean_se(scores)} ({label(chosen.key)}, NFE {chosen.nfe}, "
            f"{chosen.key.tag or 'open loop, track'}; success {np.mean([e.success for e in test]):.2f}, "
            f"{np.mean([e.calls for e in test]):.0f} calls/episode, {timing}; expert {np.mean(expert):.1f})")


def render(root: Path) -> str:
    """findings.md's text, from the committed results under ``root`` (docs/results)."""
    results = {maze: load(root, maze) for maze in MAZES}
    header = ["finding", *MAZES, *(f"{m} Multi2D" for m in MAZES)]
    lines = ["# Findings per maze", "",
             "Made by `bridgeplan study report findings` from docs/results/<maze>-v2-curves/results.csv "
             "(data version 2, `cpu-small`; umaze 128 states x 1, medium 32 x 8, large 48 x 8). Each cell: the "
             "per-seed difference, first series minus second, mean ± standard error over training seeds "
             "(Minari convention), and the verdict at two standard errors (see "
             "bridgeplan/studies/reports/findings.py).", "",
             *table(header, [[finding[0], *(cell(results[m], finding, multi) for multi in (0, 1) for m in MAZES)]
                             for finding in FINDINGS])]
    expert = expert_rows(root)
    lines += ["", "## Issue 13's goal: a Minari score of 95 or more", "",
              "The setting (method, NFE, execution) with the best mean on the validation episodes "
              "(`experiment --validation`: nfe-curves and controllers), scored on the test episodes; the expert "
              "on the same test episodes from expert-on-eval-tasks.json.", "",
              *table(["maze", "single-task", "Multi2D"],
                     [[m, *(goal_cell(results[m], multi, [r["score_minari"] for r in expert
                                                          if r["maze"] == m and r["multi_task"] == bool(multi)])
                            for multi in (0, 1))] for m in MAZES])]
    return "\n".join(lines)

