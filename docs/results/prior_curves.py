"""Issue 15's table: flow matching, the I2SB bridge and the consistent bridge from each prior across training,
against DDPM, and the issue's goal checked at every snapshot (umaze and medium; the rows of `prior-curves` and
`nfe-curves` in docs/results/<maze>-v2-curves/results.csv, made by run_flow_priors.sh, run_maze_variants.sh
PARTS=consistent and run_maze_curves.sh, and in docs/results/<maze>-v2-consistent-priors/results.csv, made by
run_maze_variants.sh PARTS=consistent-priors in a store of its own). The line prior's consistent runs are in
both: the table takes the first, and says how closely the retrained runs reproduce it. On medium, a table checks
the goal for the consistent bridge from the line sampled by its posterior means (run_bridge_sampler.sh), and a
last one checks it with 5 seeds and the bridge's setting declared in advance (:func:`declared_table`).

Goal, per maze, prior and training step: flow at NFE 2 (fixed in advance, no selection) reaches the best score
DDPM reaches at any NFE and the best the bridge reaches from the same prior (I2SB or the consistent bridge,
whichever is higher), and clears the prior it starts from, tracked alone. "Best" is the NFE with the best mean
over seeds on these same (test) episodes, which favours DDPM and the bridges: the bar flow has to reach is
raised, not lowered. Per-seed differences (flow minus the other, Minari convention), mean ± standard error over
seeds; "reaches": yes when the mean is not below, "within noise" when below by less than two standard errors;
"clears": more than two above. The prior alone: the straight line's floor of each evaluation row, the learned
prior's from docs/results/<maze>-v2-curves/learned-floor (run_learned_floor.sh).

Usage: python docs/results/prior_curves.py > docs/results/prior-curves.md
"""

from __future__ import annotations

import json
import sys

import numpy as np
from findings import HERE, STORES, VALIDATION, Eval, load, rows

from bridgeplan.experiments.runner import VALIDATION_SUFFIX
from bridgeplan.report import method_label

MAZES = ("umaze", "medium")
PRIORS = ("gaussian", "line", "learned")
FLOW_NFE = 2
CONSISTENT = "bridge (line; consistent=True)"
SWEEP = "sampler-sweep"
"""The store of run_sampler_sweep.sh (docs/results/<maze>-v2-sampler-sweep): the samplers experiment, 5 seeds."""


def at_step(table: dict, method: str, step: int) -> dict[int, dict[int, float]]:
    """``{nfe: {seed: score}}`` of an open-loop single-task series at ``step``."""
    by_nfe = table.get((method, 0, ""), {}).get(step, {})
    return {nfe: {seed: e.score for seed, e in seeds.items()} for nfe, seeds in by_nfe.items()}


def best(by_nfe: dict[int, dict[int, float]]) -> tuple[int, dict[int, float]] | None:
    if not by_nfe:
        return None
    nfe = max(by_nfe, key=lambda k: np.mean(list(by_nfe[k].values())))
    return nfe, by_nfe[nfe]


def prior_alone(table: dict, maze: str, prior: str, method: str, step: int) -> dict[int, float] | None:
    """Per-seed score of the prior alone, tracked, on the same episodes (None for Gaussian noise)."""
    if prior == "line":
        seeds = table.get((method, 0, ""), {}).get(step, {}).get(FLOW_NFE, {})
        return {seed: e.floor for seed, e in seeds.items()} or None
    if prior == "learned":
        paths = sorted((HERE / f"{maze}-v2-curves" / "learned-floor").glob("s*.json"))
        rows = [json.loads(p.read_text()) for p in paths]
        return {r["seed"]: r["prior_only_learned"]["score"]["minari"]["mean"] for r in rows} or None
    return None


def diff(a: dict[int, float], b: dict[int, float]) -> tuple[float, float, int] | None:
    seeds = sorted(set(a) & set(b))
    if len(seeds) < 2:
        return None
    d = np.array([a[s] - b[s] for s in seeds])
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(len(d))), len(seeds)


def mean_se(by_seed: dict[int, float]) -> str:
    v = np.array(list(by_seed.values()))
    return f"{v.mean():.1f} ± {v.std(ddof=1) / np.sqrt(len(v)):.1f}" if len(v) > 1 else f"{v.mean():.1f}"


def verdict(d, rule: str) -> str:
    """reaches: yes (mean >= 0), "within noise" (below, by less than two standard errors) or no;
    clears: yes (more than two standard errors above) or no."""
    if d is None:
        return "not measured"
    mean, se, _ = d
    if rule == "reaches":
        word = "yes" if mean >= 0 else "within noise" if mean + 2 * se >= 0 else "no"
    else:
        word = "yes" if mean - 2 * se > 0 else "no"
    return f"{word} ({mean:+.1f} ± {se:.1f})"


def reproduction(maze: str) -> str:
    """How closely the consistent-priors store's retrained runs reproduce the rows the other stores hold."""
    def scores(stores):
        return {(method_label(r), r.get("multi_task"), r.get("execution"), r["experiment"].endswith(VALIDATION_SUFFIX),
                 r["step"], r["nfe"], r["seed"]): (float(r["score_minari"]), float(r["score_minari_se"]),
                                                  float(r["floor_minari"]), r["code_version"])
                for r in rows(maze, stores)}

    retrained, held = scores(STORES[-1:]), scores(STORES[:-1])
    both = sorted(set(retrained) & set(held))
    if not both:
        return ""
    gaps = np.array([retrained[k][0] - held[k][0] for k in both])
    episode_se = np.mean([held[k][1] for k in both])
    floors_equal = all(retrained[k][2] == held[k][2] for k in both)
    versions = sorted({v[3] for v in [*map(retrained.get, both), *map(held.get, both)]})
    return (f"**Reproduction.** {', '.join(sorted({k[0] for k in both}))}: the {len(both)} rows the other store "
            f"holds were retrained and re-evaluated here (codes {', '.join(versions)}, another machine): "
            f"difference {gaps.mean():+.2f} on average, {np.abs(gaps).mean():.2f} in absolute value, at most "
            f"{np.abs(gaps).max():.2f}, against a standard error of {episode_se:.2f} over each row's 200 "
            f"episodes; {int((gaps == 0).sum())} identical. The straight-line floors on the same episodes are "
            f"{'bit-identical' if floors_equal else 'not identical'}, so the tasks, simulator and controller "
            f"reproduce exactly{'' if floors_equal else ' (they do not)'}; the trained networks do not (the "
            f"training code draws the same random stream; the likely cause is float rounding in another CPU's "
            f"kernels, not checked). "
            f"The table takes the first store's rows.")


def mean_sampler_table(table: dict, maze: str) -> list[str]:
    """The consistent bridge from the line sampled by its posterior means at NFE 2 (run_bridge_sampler.sh's eval
    JSONs in docs/results/<maze>-v2-consistent-samplers: the final snapshot there, earlier ones in step*/) against
    DDPM's best NFE at each step, per seed, and against the line alone."""
    here = HERE / f"{maze}-v2-consistent-samplers"
    lines = []
    by_step: dict[int, list[dict]] = {}
    for path in [*here.glob("step*/s[0-9]-mean-nfe2-track.json"), *here.glob("s[0-9]-mean-nfe2-track.json")]:
        row = json.loads(path.read_text())
        by_step.setdefault(row["step"], []).append(row)
    for step, evals in sorted(by_step.items()):
        ours = {r["seed"]: r["score"]["minari"]["mean"] for r in evals}
        alone = {r["seed"]: r["floor_line"]["score"]["minari"]["mean"] for r in evals}
        ddpm = best(at_step(table, "DDPM", step))
        lines.append(f"| {step} | {mean_se(ours)} | {mean_se(ddpm[1])} ({ddpm[0]}) | "
                     f"{verdict(diff(ours, ddpm[1]), 'reaches')} | {verdict(diff(ours, alone), 'clears')} |")
    if not lines:
        return []
    return [f"### {maze}: the consistent bridge (line) by its posterior means at NFE 2", "",
            "| step | consistent bridge, `--sampler mean`, NFE 2 | DDPM best (NFE) | reaches DDPM's best | clears the "
            "line alone |", "|---|---|---|---|---|", *lines, ""]


def declared_table(maze: str) -> list[str]:
    """The goal with the candidate's setting declared before the test episodes are read: the consistent bridge
    from the line at NFE 1 or 2, by posterior draws or by posterior means, whichever has the best mean over seeds
    on the validation episodes (final snapshot; run_sampler_sweep.sh), scored on the test episodes at every
    snapshot against DDPM's best sampler and NFE at that snapshot (picked on the test episodes: favours DDPM),
    the I2SB bridge's best NFE from the line (docs/results/<maze>-v2-curves, seeds 0-2, paired by seed) and
    the line alone; per-seed differences over the sweep's 5 seeds. A second table gives every candidate on the
    test episodes against DDPM's best, for reference."""
    table = load(maze, (SWEEP,))

    def final(method: str) -> dict:  # {nfe: {seed: Eval}} on the validation episodes, final snapshot
        by_step = table[VALIDATION].get((method, 0, ""), {})
        return by_step[max(by_step)] if by_step else {}

    def validated(option) -> float:
        return float(np.mean([e.score for e in final(option[0])[option[1]].values()]))

    def named(option) -> str:  # at NFE 1 both samplers make the one call to x0 the same way
        sampler = "posterior means" if option[0].endswith("by mean") else "posterior draws"
        return "NFE 1, one call" if option[1] == 1 else f"{sampler}, NFE {option[1]}"

    def test(option, step: int) -> dict[int, Eval]:
        return table.get((option[0], 0, ""), {}).get(step, {}).get(option[1], {})

    candidates = [(m, k) for m in (CONSISTENT, f"{CONSISTENT} by mean") for k in (1, 2) if k in final(m)]
    if not candidates:
        return []
    chosen = max(candidates, key=validated)
    steps = sorted(table[(chosen[0], 0, "")])
    ddpm_best = {}  # step -> (sampler, nfe, {seed: score}): the best mean over DDPM's samplers and NFE
    for step in steps:
        per_sampler = [(name, *b) for name, m in (("ancestral", "DDPM"), ("DDIM", "DDPM by ddim"))
                       if (b := best(at_step(table, m, step)))]
        ddpm_best[step] = max(per_sampler, key=lambda o: np.mean(list(o[2].values())))
    i2sb = load(maze, ("curves",))
    lines = []
    for step in steps:
        evals = test(chosen, step)
        ours, alone = {seed: e.score for seed, e in evals.items()}, {seed: e.floor for seed, e in evals.items()}
        sampler, k, ddpm = ddpm_best[step]
        i2sb_best = best(at_step(i2sb, "bridge (line)", step))
        lines.append(" | ".join([
            f"| {step}", mean_se(ours), f"{mean_se(ddpm)} ({sampler}, NFE {k})",
            f"{mean_se(i2sb_best[1])} (NFE {i2sb_best[0]})" if i2sb_best else "-", mean_se(alone),
            verdict(diff(ours, ddpm), "reaches"), verdict(diff(ours, i2sb_best[1]) if i2sb_best else None, "reaches"),
            verdict(diff(ours, alone), "clears")]) + " |")
    on_test = []
    for option in candidates:
        cells = []
        for step in steps:
            scores = {seed: e.score for seed, e in test(option, step).items()}
            reaches = verdict(diff(scores, ddpm_best[step][2]), "reaches")
            cells.append(f"{mean_se(scores)}; {reaches}" if scores else "-")
        on_test.append(f"| {named(option)} | " + " | ".join(cells) + " |")
    validation = "; ".join(f"{named(o)}: {validated(o):.1f}" for o in candidates)
    return [f"### {maze}: the goal with the bridge's setting declared on validation episodes (5 seeds)", "",
            f"The consistent bridge from the line at NFE <= 2, its sampler and NFE chosen on the validation "
            f"episodes at the final snapshot ({validation}): **{named(chosen)}**, then scored on the test episodes "
            f"at every snapshot. DDPM's best over its samplers (ancestral, DDIM) and NFE (1, 2, 4, 16) is picked on "
            f"the test episodes at each snapshot, which favours DDPM. I2SB's best from the line: seeds 0-2 of "
            f"{maze}-v2-curves, paired by seed. (docs/results/{maze}-v2-{SWEEP}, run_sampler_sweep.sh.)", "",
            f"| step | consistent bridge ({named(chosen)}) | DDPM best (sampler, NFE) | I2SB best (line) | line alone "
            "| reaches DDPM's best | reaches I2SB's best | clears the line alone |", "|" + "---|" * 8, *lines, "",
            "Every candidate on the test episodes and whether it reaches DDPM's best there, for reference (not a "
            "choice: picking here would favour the bridge):", "",
            "| consistent bridge (line) | " + " | ".join(f"step {step}" for step in steps) + " |",
            "|" + "---|" * (len(steps) + 1), *on_test, ""]


def maze_table(table: dict, maze: str) -> list[str]:
    lines = [f"## {maze}", "",
             "| prior | step | flow NFE 1 | flow NFE 2 | flow full | bridge NFE 1 | bridge NFE 2 | bridge best "
             "(NFE) | consistent bridge best (NFE) | DDPM best (NFE) | prior alone | flow NFE 2 reaches DDPM's best "
             "| reaches the bridges' best | clears its prior |", "|" + "---|" * 14]
    ddpm_steps = table.get(("DDPM", 0, ""), {})
    for prior in PRIORS:
        flow_name, bridge_name = f"flow ({prior})", f"bridge ({prior})"
        steps = sorted(set(table.get((flow_name, 0, ""), {})) & set(ddpm_steps))
        for step in steps:
            flow, bridge = at_step(table, flow_name, step), at_step(table, bridge_name, step)
            consistent = at_step(table, f"bridge ({prior}; consistent=True)", step)
            if FLOW_NFE not in flow:
                continue
            ddpm_best, bridge_best, consistent_best = best(at_step(table, "DDPM", step)), best(bridge), best(consistent)
            either = [b for b in (bridge_best, consistent_best) if b]  # I2SB's best in either variant
            bridges_best = max(either, key=lambda b: np.mean(list(b[1].values()))) if either else None
            alone = prior_alone(table, maze, prior, flow_name, step)
            full = flow[max(flow)]

            def cell(by_nfe, nfe):
                return mean_se(by_nfe[nfe]) if nfe in by_nfe else "-"

            lines.append(" | ".join([
                f"| {prior}", str(step), cell(flow, 1), f"**{mean_se(flow[FLOW_NFE])}**", mean_se(full),
                cell(bridge, 1), cell(bridge, 2),
                f"{mean_se(bridge_best[1])} ({bridge_best[0]})" if bridge_best else "-",
                f"{mean_se(consistent_best[1])} ({consistent_best[0]})" if consistent_best else "-",
                f"{mean_se(ddpm_best[1])} ({ddpm_best[0]})" if ddpm_best else "-",
                mean_se(alone) if alone else "-",
                verdict(diff(flow[FLOW_NFE], ddpm_best[1]) if ddpm_best else None, "reaches"),
                verdict(diff(flow[FLOW_NFE], bridges_best[1]) if bridges_best else None, "reaches"),
                verdict(diff(flow[FLOW_NFE], alone) if alone else None, "clears") if alone else "n/a (noise)",
            ]) + " |")
    return lines


def main() -> int:
    lines = ["# Flow matching from each prior across training (issue 15)", "",
             "Made by `python docs/results/prior_curves.py` from docs/results/<maze>-v2-{curves,consistent-priors}/"
             "results.csv (data "
             "version 2, `cpu-small`, 200 episodes per evaluation, mean ± standard error over training seeds, "
             "Minari convention). The goal's columns compare flow at NFE 2 with the best NFE of DDPM and of the "
             "bridges (I2SB or consistent) from the same prior, picked on these episodes (which favours them), "
             "per seed; see the script's docstring.", ""]
    for maze in MAZES:
        table = load(maze)
        lines += [*maze_table(table, maze), "", reproduction(maze), "", *mean_sampler_table(table, maze),
                  *declared_table(maze)]
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
