"""Issue 15's table: flow matching, the I2SB bridge and the consistent bridge from each prior across training,
against DDPM, and the issue's goal checked at every snapshot (umaze and medium; the rows of `prior-curves` and
`nfe-curves` in docs/results/<maze>-v2-curves/results.csv, made by studies/<maze>-v2-curves.toml, and in
docs/results/<maze>-v2-consistent-priors/results.csv, made by studies/<maze>-v2-consistent-priors.toml in a store
of its own). The line prior's consistent runs are in both: the table takes the first, and says how closely the
retrained runs reproduce it. On medium, a table checks the goal for the consistent bridge from the line sampled by
its posterior means (the consistent-means rows of docs/results/medium-v2-consistent-priors), and a
last one checks it with 5 seeds and the bridge's setting declared in advance (:func:`declared_table`).

Goal, per maze, prior and training step: flow at NFE 2 (fixed in advance, no selection) reaches the best score
DDPM reaches at any NFE and the best the bridge reaches from the same prior (I2SB or the consistent bridge,
whichever is higher), and clears the prior it starts from, tracked alone. "Best" is the NFE with the best mean
over seeds on these same (test) episodes, which favours DDPM and the bridges: the bar flow has to reach is
raised, not lowered. Per-seed differences (flow minus the other, Minari convention), mean ± standard error over
seeds; "reaches": yes when the mean is not below, "within noise" when below by less than two standard errors;
"clears": more than two above. The prior alone: the straight line's floor of each evaluation row, the learned
prior's from docs/results/<maze>-v2-curves/learned-floor (NFE-1 evaluation JSONs of the learned-prior runs).

Made by `bridgeplan study report prior-curves` (studies/prior-curves.toml) into docs/results/prior-curves.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bridgeplan.analysis.keys import MethodKey, label, method
from bridgeplan.analysis.load import Point, Results, load_csvs, read_csv, read_eval_json
from bridgeplan.analysis.selection import best, split_mean
from bridgeplan.analysis.stats import Paired, goal_verdict, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, rule

STORES = ("curves", "hold", "consistent-priors")
"""The maze's stores (docs/results/<maze>-v2-<store>), in order of precedence (as the findings report's)."""
MAZES = ("umaze", "medium")
PRIORS = ("gaussian", "line", "learned")
FLOW_NFE = 2
N = 16
"""Diffusion steps of every run in these stores."""
DDPM = method("ddpm", steps=N)
CONSISTENT = method("bridge", "line", steps=N, consistent=True)
READS = (DDPM, *(method(process, prior, steps=N, **params) for process, params in
                (("flow", {}), ("bridge", {}), ("bridge", {"consistent": True})) for prior in PRIORS))
"""The trained methods the tables read (studies that make this report must train them)."""
SWEEP = "sampler-sweep"
"""The store of studies/medium-v2-sampler-sweep.toml (docs/results/<maze>-v2-sampler-sweep): the samplers
experiment, 5 seeds."""


def load(root: Path, maze: str, stores=STORES) -> Results:
    return load_csvs(root / f"{maze}-v2-{store}" / "results.csv" for store in stores)


def scores(results: Results, point: Point | None) -> dict[int, float]:
    return results.values(point) if point else {}


def best_nfe(results: Results, key: MethodKey, step: int) -> Point | None:
    """The NFE of ``key`` with the best mean over seeds on the test episodes at ``step``."""
    return best(results, results.points(key, step), split="test")


def prior_alone(root: Path, results: Results, maze: str, prior: str, key: MethodKey,
                step: int) -> dict[int, float] | None:
    """Per-seed score of the prior alone, tracked, on the same episodes (None for Gaussian noise)."""
    if prior == "line":
        return results.values(Point(key, step, FLOW_NFE), field="floor") or None
    if prior == "learned":
        rows = [read_eval_json(p) for p in sorted((root / f"{maze}-v2-curves" / "learned-floor").glob("s*.json"))]
        return {r.seed: r.floor_learned for r in rows} or None
    return None


def diff(a: dict[int, float], b: dict[int, float]) -> Paired | None:
    """Per-seed differences over the seeds both have; None under two."""
    return paired(a, b, seeds="common") if len(set(a) & set(b)) >= 2 else None


def mean_se(by_seed: dict[int, float]) -> str:
    return fmt_mean_se(by_seed, one_seed="mean")


def verdict(d: Paired | None, rule: str) -> str:
    """reaches: yes (mean >= 0), "within noise" (below, by less than two standard errors) or no;
    clears: yes (more than two standard errors above) or no."""
    return "not measured" if d is None else f"{goal_verdict(d, rule)} ({fmt_diff(d)})"


def best_cell(results: Results, point: Point | None, name=lambda p: str(p.nfe)) -> str:
    return f"{mean_se(scores(results, point))} ({name(point)})" if point else "-"


def reproduction(root: Path, maze: str) -> str:
    """How closely the consistent-priors store's retrained runs reproduce the rows the other stores hold."""
    def evaluations(stores):  # the last row of each evaluation
        return {(r.key, r.split, r.step, r.nfe, r.seed): r for store in stores
                for path in [root / f"{maze}-v2-{store}" / "results.csv"] if path.exists() for r in read_csv(path)}

    retrained, held = evaluations(STORES[-1:]), evaluations(STORES[:-1])
    both = sorted(set(retrained) & set(held), key=lambda k: (label(k[0]), k[0].multi_task, k[0].tag, *k[1:]))
    if not both:
        return ""
    gaps = np.array([retrained[k].score - held[k].score for k in both])
    episode_se = np.mean([held[k].score_se for k in both])
    floors_equal = all(retrained[k].floor == held[k].floor for k in both)
    versions = sorted({r.code_version for k in both for r in (retrained[k], held[k])})
    return (f"**Reproduction.** {', '.join(sorted({label(k[0]) for k in both}))}: the {len(both)} rows the other "
            f"store holds were retrained and re-evaluated here (codes {', '.join(versions)}, another machine): "
            f"difference {gaps.mean():+.2f} on average, {np.abs(gaps).mean():.2f} in absolute value, at most "
            f"{np.abs(gaps).max():.2f}, against a standard error of {episode_se:.2f} over each row's 200 "
            f"episodes; {int((gaps == 0).sum())} identical. The straight-line floors on the same episodes are "
            f"{'bit-identical' if floors_equal else 'not identical'}, so the tasks, simulator and controller "
            f"reproduce exactly{'' if floors_equal else ' (they do not)'}; the trained networks do not (the "
            f"training code draws the same random stream; the likely cause is float rounding in another CPU's "
            f"kernels, not checked). "
            f"The table takes the first store's rows.")


def mean_sampler_table(root: Path, results: Results, maze: str) -> list[str]:
    """The consistent bridge from the line sampled by its posterior means at NFE 2 (the consistent-means experiment
    of docs/results/<maze>-v2-consistent-priors) against DDPM's best NFE at each step, per seed, and against the
    line alone."""
    means = CONSISTENT.replace(sampler="mean")
    lines = []
    for step in results.steps(means):
        point = Point(means, step, 2)
        ours, alone = results.values(point), results.values(point, field="floor")
        if not ours:
            continue
        ddpm = best_nfe(results, DDPM, step)
        reaches, clears = verdict(diff(ours, scores(results, ddpm)), "reaches"), verdict(diff(ours, alone), "clears")
        lines.append(f"| {step} | {mean_se(ours)} | {best_cell(results, ddpm)} | {reaches} | {clears} |")
    if not lines:
        return []
    return [f"### {maze}: the consistent bridge (line) by its posterior means at NFE 2", "",
            "| step | consistent bridge, `--sampler mean`, NFE 2 | DDPM best (NFE) | reaches DDPM's best | clears the "
            "line alone |", "|---|---|---|---|---|", *lines, ""]


def declared_table(root: Path, maze: str) -> list[str]:
    """The goal with the candidate's setting declared before the test episodes are read: the consistent bridge
    from the line at NFE 1 or 2, by posterior draws or by posterior means, whichever has the best mean over seeds
    on the validation episodes (final snapshot; studies/medium-v2-sampler-sweep.toml), scored on the test episodes
    at every snapshot against DDPM's best sampler and NFE at that snapshot (picked on the test episodes: favours DDPM),
    the I2SB bridge's best NFE from the line (docs/results/<maze>-v2-curves, seeds 0-2, paired by seed) and
    the line alone; per-seed differences over the sweep's 5 seeds. A second table gives every candidate on the
    test episodes against DDPM's best, for reference."""
    results = load(root, maze, (SWEEP,))

    def final(key: MethodKey) -> list[Point]:  # the validation episodes' points at the final snapshot
        steps = results.steps(key, "validation")
        return results.points(key, steps[-1], "validation") if steps else []

    def named(point: Point) -> str:  # at NFE 1 both samplers make the one call to x0 the same way
        sampler = "posterior means" if point.key.sampler == "mean" else "posterior draws"
        return "NFE 1, one call" if point.nfe == 1 else f"{sampler}, NFE {point.nfe}"

    candidates = [p for key in (CONSISTENT, CONSISTENT.replace(sampler="mean")) for k in (1, 2)
                  for p in final(key) if p.nfe == k]
    chosen = best(results, candidates, "validation")
    if chosen is None:
        return []
    steps = results.steps(chosen.key)
    ddpm_best = {}  # step -> the best point over DDPM's samplers and NFE on the test episodes
    for step in steps:
        ddpm_best[step] = best(results, [p for key in (DDPM, DDPM.replace(sampler="ddim"))
                                         for p in results.points(key, step)], "test")
    i2sb = load(root, maze, ("curves",))
    i2sb_line = method("bridge", "line", steps=N)
    lines = []
    for step in steps:
        test = Point(chosen.key, step, chosen.nfe)
        ours, alone = results.values(test), results.values(test, field="floor")
        ddpm = ddpm_best[step]
        i2sb_best = best_nfe(i2sb, i2sb_line, step)
        i2sb_scores = scores(i2sb, i2sb_best)
        lines.append(" | ".join([
            f"| {step}", mean_se(ours),
            best_cell(results, ddpm, lambda p: f"{'DDIM' if p.key.sampler == 'ddim' else 'ancestral'}, NFE {p.nfe}"),
            best_cell(i2sb, i2sb_best, lambda p: f"NFE {p.nfe}"), mean_se(alone),
            verdict(diff(ours, scores(results, ddpm)), "reaches"),
            verdict(diff(ours, i2sb_scores) if i2sb_best else None, "reaches"),
            verdict(diff(ours, alone), "clears")]) + " |")
    on_test = []
    for option in candidates:
        cells = []
        for step in steps:
            by_seed = results.values(Point(option.key, step, option.nfe))
            reaches = verdict(diff(by_seed, scores(results, ddpm_best[step])), "reaches")
            cells.append(f"{mean_se(by_seed)}; {reaches}" if by_seed else "-")
        on_test.append(f"| {named(option)} | " + " | ".join(cells) + " |")
    validation = "; ".join(f"{named(o)}: {split_mean(results, o, 'validation'):.1f}" for o in candidates)
    return [f"### {maze}: the goal with the bridge's setting declared on validation episodes (5 seeds)", "",
            f"The consistent bridge from the line at NFE <= 2, its sampler and NFE chosen on the validation "
            f"episodes at the final snapshot ({validation}): **{named(chosen)}**, then scored on the test episodes "
            f"at every snapshot. DDPM's best over its samplers (ancestral, DDIM) and NFE (1, 2, 4, 16) is picked on "
            f"the test episodes at each snapshot, which favours DDPM. I2SB's best from the line: seeds 0-2 of "
            f"{maze}-v2-curves, paired by seed. (docs/results/{maze}-v2-{SWEEP}, studies/{maze}-v2-{SWEEP}.toml.)", "",
            f"| step | consistent bridge ({named(chosen)}) | DDPM best (sampler, NFE) | I2SB best (line) | line alone "
            "| reaches DDPM's best | reaches I2SB's best | clears the line alone |", rule(8), *lines, "",
            "Every candidate on the test episodes and whether it reaches DDPM's best there, for reference (not a "
            "choice: picking here would favour the bridge):", "",
            "| consistent bridge (line) | " + " | ".join(f"step {step}" for step in steps) + " |",
            rule(len(steps) + 1), *on_test, ""]


def maze_table(root: Path, results: Results, maze: str) -> list[str]:
    lines = [f"## {maze}", "",
             "| prior | step | flow NFE 1 | flow NFE 2 | flow full | bridge NFE 1 | bridge NFE 2 | bridge best "
             "(NFE) | consistent bridge best (NFE) | DDPM best (NFE) | prior alone | flow NFE 2 reaches DDPM's best "
             "| reaches the bridges' best | clears its prior |", rule(14)]
    for prior in PRIORS:
        flow, bridge = method("flow", prior, steps=N), method("bridge", prior, steps=N)
        consistent = method("bridge", prior, steps=N, consistent=True)
        for step in sorted(set(results.steps(flow)) & set(results.steps(DDPM))):
            flow_nfes = results.nfes(flow, step)
            if FLOW_NFE not in flow_nfes:
                continue
            ddpm_best, bridge_best = best_nfe(results, DDPM, step), best_nfe(results, bridge, step)
            consistent_best = best_nfe(results, consistent, step)
            either = [b for b in (bridge_best, consistent_best) if b]  # I2SB's best in either variant
            bridges_best = max(either, key=lambda p: split_mean(results, p, "test")) if either else None
            alone = prior_alone(root, results, maze, prior, flow, step)
            ours = results.values(Point(flow, step, FLOW_NFE))

            def cell(key, nfe):
                by_seed = results.values(Point(key, step, nfe))
                return mean_se(by_seed) if by_seed else "-"

            lines.append(" | ".join([
                f"| {prior}", str(step), cell(flow, 1), f"**{mean_se(ours)}**", cell(flow, max(flow_nfes)),
                cell(bridge, 1), cell(bridge, 2), best_cell(results, bridge_best), best_cell(results, consistent_best),
                best_cell(results, ddpm_best), mean_se(alone) if alone else "-",
                verdict(diff(ours, scores(results, ddpm_best)) if ddpm_best else None, "reaches"),
                verdict(diff(ours, scores(results, bridges_best)) if bridges_best else None, "reaches"),
                verdict(diff(ours, alone) if alone else None, "clears") if alone else "n/a (noise)",
            ]) + " |")
    return lines


def render(root: Path) -> str:
    """prior-curves.md's text, from the committed results under ``root`` (docs/results)."""
    lines = ["# Flow matching from each prior across training (issue 15)", "",
             "Made by `bridgeplan study report prior-curves` from docs/results/<maze>-v2-{curves,consistent-priors}/"
             "results.csv (data "
             "version 2, `cpu-small`, 200 episodes per evaluation, mean ± standard error over training seeds, "
             "Minari convention). The goal's columns compare flow at NFE 2 with the best NFE of DDPM and of the "
             "bridges (I2SB or consistent) from the same prior, picked on these episodes (which favours them), "
             "per seed; see bridgeplan/studies/reports/prior_curves.py.", ""]
    for maze in MAZES:
        results = load(root, maze)
        lines += [*maze_table(root, results, maze), "", reproduction(root, maze), "",
                  *mean_sampler_table(root, results, maze), *declared_table(root, maze)]
    return "\n".join(lines)

