"""The findings table (issue 12): each thesis finding, and ours, per maze and task set, from the committed
results CSVs (docs/results/<maze>-v2-curves/results.csv and, for runs trained on windows that wait,
docs/results/<maze>-v2-hold/results.csv; written by `bridgeplan report --csv`).

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
import sys
from pathlib import Path

import numpy as np

from bridgeplan.experiments.runner import VALIDATION_SUFFIX
from bridgeplan.report import method_label

HERE = Path(__file__).resolve().parent
MAZES = ("umaze", "medium", "large")
FLOOR = "floor"
VALIDATION = "validation"

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


def load(maze: str) -> dict:
    """``{(method, multi, execution): {step: {nfe: {seed: (score, floor)}}}}`` from the maze's CSVs, test
    episodes; the validation episodes' rows under the key ``VALIDATION``, in the same shape."""
    table: dict = {VALIDATION: {}}
    paths = [HERE / f"{maze}-v2-{store}" / "results.csv" for store in ("curves", "hold")]
    for r in (r for path in paths if path.exists() for r in csv.DictReader(path.open())):
        into = table[VALIDATION] if r["experiment"].endswith(VALIDATION_SUFFIX) else table
        key = (method_label(r), int(r.get("multi_task") or 0), r.get("execution") or "")
        cell = into.setdefault(key, {}).setdefault(int(r["step"]), {}).setdefault(int(r["nfe"]), {})
        cell.setdefault(int(r["seed"]), (float(r["score_minari"]), float(r["floor_minari"])))
    return table


def best_nfe(table: dict, key, step: int) -> int | None:
    """The NFE with the best mean score over seeds on the validation episodes (None: not evaluated there)."""
    by_nfe = table[VALIDATION].get(key, {}).get(step)
    return max(by_nfe, key=lambda k: np.mean([s for s, _ in by_nfe[k].values()])) if by_nfe else None


def series(table: dict, spec, multi: int, step: int) -> dict[int, float] | None:
    """Per-seed scores of ``spec`` = (method or FLOOR, nfe, execution) at ``step``, test episodes."""
    method, nfe, execution = spec
    if method == FLOOR:  # the floor of the other series' episodes: any open-loop series carries it
        for (m, mt, ex), steps in ((k, v) for k, v in table.items() if k != VALIDATION):
            if mt == multi and ex == "" and step in steps:
                at = next(iter(steps[step].values()))
                return {seed: floor for seed, (_, floor) in at.items()}
        return None
    by_nfe = table.get((method, multi, execution), {}).get(step)
    if not by_nfe:
        return None
    if nfe == "full":
        nfe = max(by_nfe)
    elif nfe == "best":
        nfe = best_nfe(table, (method, multi, execution), step)
    if nfe not in by_nfe:
        return None
    return {seed: score for seed, (score, _) in by_nfe[nfe].items()}


def cell(table: dict, finding, multi: int) -> str:
    _, a, b, rule, which = finding
    steps_a = set(table.get((a[0], multi, a[2]), {}))
    steps_b = set(table.get((b[0], multi, b[2]), {})) if b[0] != FLOOR else steps_a
    common = sorted(steps_a & steps_b)
    if not common:
        return "not measured"
    step = common[0] if which == "first" else common[-1]
    chosen = {spec[0]: best_nfe(table, (spec[0], multi, spec[2]), step) for spec in (a, b) if spec[1] == "best"}
    if None in chosen.values():
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
    picked = "".join(f", {m} NFE {k}" for m, k in chosen.items())
    return f"{verdict}: {mean:+.1f} ± {se:.1f} (step {step}, {len(seeds)} seeds{picked})"


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
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
