"""Issue 27's decisive table: do consistency corrections of the x0 predictions (CDDB, bridgeplan.consistency)
bring the consistent bridge or flow matching from the line prior at NFE <= 2 up to DDPM's best, on medium and on
large, with the plans tracked and pursued?

Rows: the folders of :data:`SOURCES` under docs/results (studies/medium-cddb.toml: medium, 5 training seeds,
tracked; studies/medium-cddb-pursued.toml: medium, 3 seeds retrained, pursued; studies/large-cddb.toml: large, 3
seeds, both), 200 episodes per evaluation; ``cddb-uncorrected*`` uncorrected (tracked at every snapshot), ``cddb*``
the corrected samplers at the final snapshot, each with its ``-validation`` rows on other episodes. A correction
is a sampler tag ``cddb-<form> <residual>=<step>`` on the same trained runs; the corrections are found in the rows,
not listed here. Each folder's rows are split by their execution (tracked, pursued): one part each, compared only
within itself (a pursued bridge against the pursued DDPM of the same runs).

Choices: DDPM's bar at a step is its best NFE by mean over seeds on the test episodes themselves (the bar raised
for the bridges, as in prior-curves.md). A corrected setting (residual, step size, form; uncorrected among them)
is chosen per method and NFE on the validation episodes at the final snapshot and reported on the test ones.
Differences are per seed (first minus second, Minari score), mean ± standard error over seeds; "reaches": yes
when the mean is not below zero, "within noise" when below by less than two standard errors, else no.

Made by `bridgeplan study report cddb` (studies/cddb.toml) into docs/results/cddb.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bridgeplan.analysis.keys import OPEN_LOOP, MethodKey, execution_name, label, method
from bridgeplan.analysis.load import Point, Results, exported_rows
from bridgeplan.analysis.selection import best, split_mean
from bridgeplan.analysis.stats import Paired, goal_verdict, paired
from bridgeplan.analysis.tables import bold, fmt_diff, fmt_mean_se, table
from bridgeplan.replan import Execution

SOURCES = ("medium-cddb", "medium-cddb-pursued", "large-cddb")
"""The studies' folders under docs/results, in the report's order (a folder not exported yet is left out)."""
MAZES = ("umaze", "medium", "large")
N = 16
DDPM = method("ddpm", steps=N)
BRIDGES = (method("bridge", "line", steps=N, consistent=True), method("flow", "line", steps=N))
READS = (DDPM, *BRIDGES)
"""The trained methods the tables read (studies that make this report must train them)."""
GOAL_NFE = (1, 2)
CORRECTED = "cddb-"
"""The prefix of a corrected sampler's tag (``consistency.Correction.tag``)."""


@dataclass(frozen=True)
class Part:
    """One maze's rows of one execution: a table of its own."""

    folder: str
    maze: str
    execution: Execution
    results: Results

    @property
    def title(self) -> str:
        return f"{self.maze}, {execution_name(self.execution)}"

    @property
    def ddpm(self) -> MethodKey:
        return DDPM.replace(execution=self.execution)

    def measured(self) -> list[MethodKey]:
        """The bridges with test rows."""
        bridges = [b.replace(execution=self.execution) for b in BRIDGES]
        return [b for b in bridges if self.results.steps(b)]

    def seeds(self) -> list[int]:
        return sorted({r.seed for r in self.results})


def parts(root: Path) -> list[Part]:
    """The parts of every exported folder of :data:`SOURCES`: by maze, then tracked before the other executions."""
    found = []
    for folder, rows in exported_rows(root, SOURCES):
        for maze, execution in dict.fromkeys((r.maze, r.key.execution) for r in rows):
            found.append(Part(folder, maze, execution,
                              Results(r for r in rows if (r.maze, r.key.execution) == (maze, execution))))
    return sorted(found, key=lambda p: (MAZES.index(p.maze) if p.maze in MAZES else len(MAZES),
                                        p.execution != OPEN_LOOP))


def settings(results: Results, base: MethodKey) -> list[MethodKey]:
    """``base`` uncorrected, then each correction of it found in the rows, in the order first given."""
    found = [k for k in results.keys("validation") + results.keys("test")
             if k.sampler.startswith(CORRECTED) and k.replace(sampler="") == base]
    return [base, *dict.fromkeys(found)]


def setting_name(key: MethodKey) -> str:
    return key.sampler if key.sampler else "uncorrected"


def ddpm_bar(part: Part, step: int) -> Point | None:
    """DDPM's NFE with the best mean over seeds on the test episodes at ``step``."""
    return best(part.results, part.results.points(part.ddpm, step), split="test")


def reaches(ours: dict[int, float], bar: dict[int, float]) -> str:
    if len(set(ours) & set(bar)) < 2:
        return "not measured"
    d = paired(ours, bar, seeds="common")
    return f"{goal_verdict(d, 'reaches')} ({fmt_diff(d)})"


def cell(values: dict[int, float], digits: int = 1) -> str:
    return fmt_mean_se(values, one_seed="mean", digits=digits) if values else "-"


def mean_of(results: Results, point: Point, field: str) -> str:
    values = [v for v in results.values(point, field=field).values() if v is not None]
    return f"{np.mean(values):.3g}" if values else "-"


def curves_table(part: Part) -> list[str]:
    """Uncorrected, at every snapshot: DDPM's bar against each bridge at NFE 1, 2, 4."""
    results, bridges = part.results, part.measured()
    nfes = sorted({n for b in bridges for s in results.steps(b) for n in results.nfes(b, s)})
    header = ["step", "DDPM best (NFE)"] + [f"{label(b)}, NFE {n}" for b in bridges for n in nfes]
    header += [f"{label(b)} at NFE <= 2 reaches DDPM's best" for b in bridges]
    rows = []
    for step in results.steps(part.ddpm):
        bar = ddpm_bar(part, step)
        bar_scores = results.values(bar) if bar else {}
        cells = [step, f"{cell(bar_scores)} ({bar.nfe})" if bar else "-"]
        cells += [cell(results.values(Point(b, step, n))) for b in bridges for n in nfes]
        for b in bridges:  # the better of NFE 1 and 2 on the test episodes: a bar lowered for the bridge, on purpose
            ours = best(results, [Point(b, step, n) for n in GOAL_NFE], split="test")
            cells.append(reaches(results.values(ours), bar_scores) + f" at NFE {ours.nfe}" if ours else "-")
        rows.append(cells)
    return table(header, rows)


def corrections_table(results: Results, base: MethodKey, step: int, bar_scores: dict[int, float]) -> list[str]:
    """Every setting of ``base`` at the final snapshot: validation and test scores, its cost, its plans'
    residuals; the setting chosen on validation per NFE in bold."""
    header = ["NFE", "setting", "validation", "test", "success", "test - uncorrected", "reaches DDPM's best",
              "network calls / plan", "ms / plan", "plan kinematics rms", "plan dynamics rms"]
    rows = []
    keys = settings(results, base)
    for nfe in sorted({n for k in keys for n in results.nfes(k, step)}):
        points = [Point(k, step, nfe) for k in keys]
        chosen = best(results, points, split="validation")
        plain = results.values(Point(base, step, nfe))
        for p in points:
            test = results.values(p)
            if not test:
                continue
            name = setting_name(p.key)
            diff = (fmt_diff(paired(test, plain, seeds="common")) if p.key != base and len(set(test) & set(plain)) >= 2
                    else "-")
            validation = split_mean(results, p, "validation")
            rows.append([nfe, bold(name) if p == chosen else name,
                         "-" if np.isnan(validation) else f"{validation:.1f}", cell(test),
                         cell(results.values(p, field="success"), digits=3), diff, reaches(test, bar_scores),
                         mean_of(results, p, "network_calls"), mean_of(results, p, "plan_ms"),
                         mean_of(results, p, "plan_kinematics"), mean_of(results, p, "plan_dynamics")])
    return table(header, rows)


def residual_of(key: MethodKey) -> str:
    """The correction's residuals and form without step sizes (``cddb-x0 dynamics``); '' uncorrected."""
    if not key.sampler:
        return ""
    form, *terms = key.sampler.split(" ")
    return " ".join([form, *(t.split("=")[0] for t in terms)])


def goal_lines(results: Results, base: MethodKey, step: int, bar: Point) -> list[str]:
    """Per residual (its step size and NFE <= 2 chosen on validation), the verdict on the test episodes."""
    bar_scores = results.values(bar)
    by_residual: dict[str, list[Point]] = {}
    for k in settings(results, base):
        by_residual.setdefault(residual_of(k), []).extend(Point(k, step, n) for n in GOAL_NFE
                                                          if results.rows(Point(k, step, n), "validation"))
    lines = []
    for residual, points in by_residual.items():
        chosen = best(results, points, split="validation")
        if chosen is None:
            continue
        lines.append(f"- {residual or 'uncorrected'}: chosen on validation {setting_name(chosen.key)} at NFE "
                     f"{chosen.nfe}: test {cell(results.values(chosen))}, reaches DDPM's best "
                     f"({cell(bar_scores)} at NFE {bar.nfe}): {reaches(results.values(chosen), bar_scores)}")
    return lines


def correction_effects(part: Part) -> list[tuple[Paired, str]]:
    """Every corrected setting against its uncorrected sampler at the same NFE and final snapshot, on the test
    episodes: the paired difference (per seed, Minari score) and what it is of."""
    effects = []
    for base in part.measured():
        step = max(part.results.steps(base))
        for key in settings(part.results, base)[1:]:
            for nfe in part.results.nfes(key, step):
                ours, plain = part.results.values(Point(key, step, nfe)), part.results.values(Point(base, step, nfe))
                if len(set(ours) & set(plain)) >= 2:
                    effects.append((paired(ours, plain, seeds="common"),
                                    f"{part.title}, {label(base)} at NFE {nfe}, {key.sampler}"))
    return effects


def block(root: Path) -> str:
    """The README's lines: per maze, execution, method and residual, the verdict at the final snapshot
    (goal_lines); then what the corrections themselves change (correction_effects), over every part."""
    lines, effects = [], []
    for part in parts(root):
        effects += correction_effects(part)
        for base in part.measured():
            step = max(part.results.steps(base))
            bar = ddpm_bar(part, step)
            if bar is not None:
                lines += [f"- {part.title}, {label(base)}, step {step}, {len(part.seeds())} training seeds, {line[2:]}"
                          for line in goal_lines(part.results, base, step, bar)]
    if effects:
        low, high = min(effects, key=lambda e: e[0].mean), max(effects, key=lambda e: e[0].mean)
        resolved = sum(abs(d.mean) > 2 * d.se for d, _ in effects)
        lines.append(f"- what a correction changes, against its uncorrected sampler at the same NFE (test episodes, "
                     f"paired per seed; {len(effects)} settings over every maze and execution): from "
                     f"{fmt_diff(low[0])} ({low[1]}) to {fmt_diff(high[0])} ({high[1]}); beyond two standard "
                     f"errors: {resolved}")
    return "\n".join(lines)


def render(root: Path) -> str:
    lines = ["# CDDB consistency corrections: the consistent bridge and flow (line prior) against DDPM", "",
             "Generated by `bridgeplan study report cddb` from the results.csv of "
             f"{', '.join(f'docs/results/{folder}' for folder in SOURCES)} (studies/cddb.toml and the studies it "
             "uses). Scores: Minari convention, mean ± standard error over training seeds, 200 episodes per "
             "evaluation. DDPM's bar: its best NFE on the test episodes, of the same part (maze and execution). The "
             "corrections were evaluated at the final snapshot only.", ""]
    for part in parts(root):
        results = part.results
        versions = sorted({r.code_version for r in results})
        episodes = sorted({r.episodes for r in results})
        lines += [f"## {part.title}", "",
                  f"docs/results/{part.folder}: training seeds {', '.join(map(str, part.seeds()))}; "
                  f"{', '.join(map(str, episodes))} episodes per evaluation; code {', '.join(versions)}.", "",
                  "### Uncorrected", "", *curves_table(part), ""]
        for base in part.measured():
            step = max(results.steps(base))
            bar = ddpm_bar(part, step)
            if bar is None:
                continue
            lines += [f"### {label(base)} at step {step}, each setting", "",
                      f"DDPM's best at step {step}: {cell(results.values(bar))} at NFE {bar.nfe}. Bold: the setting "
                      "chosen on the validation episodes at that NFE. Residuals: rms over the plans as sampled (m/s); "
                      "network calls: NFE plus two per backward pass of a deep correction.", "",
                      *corrections_table(results, base, step, results.values(bar)), "",
                      "The goal at NFE <= 2, per residual (step size and NFE chosen on validation):", "",
                      *goal_lines(results, base, step, bar), ""]
    return "\n".join(lines).rstrip("\n")
