"""Issue 43's table: does a process built for one network call (a mean flow or a shortcut model from each prior,
DDPM distilled into one or two calls) reach DDPM's best at any NFE, on medium and on large, tracked, pursued and
replanned, single-task and Multi2D?

Rows: the folders of :data:`SOURCES` under docs/results (studies/onestep-medium.toml: medium, 5 training seeds;
studies/onestep-large.toml: large, 3 seeds), 200 episodes per evaluation; ``onestep-tracked`` at every snapshot,
``onestep-pursued`` and ``onestep-replanned`` at the final one, each with its ``-validation`` rows on other
episodes. Each folder's rows are split by execution and task set: one part each, compared only within itself (a
pursued mean flow against the pursued DDPM of the same study).

Choices: DDPM's bar at a step is its NFE (1, 2, 4 or 16) with the best mean over seeds on the validation episodes
at the final snapshot where there are some, else on the test episodes of that step (the bar raised for the others,
as in cddb.md); it is reported on the test episodes. Every other method is shown at NFE 1 and at NFE 2, not chosen.
Differences are per seed (the method minus DDPM's bar, Minari score), mean ± standard error over seeds; "reaches":
yes when the mean is not below zero, "within noise" when below by less than two standard errors, else no.

The bridge's parametrizations (issue 43, item 4: DDBM's): the I2SB bridge from the line as trained by default, its
loss ablation (medium) and DDBM's parametrization, from the rows of docs/results/medium-v2-curves and large-v2-curves
(:data:`PARAMETRIZATIONS`), tracked, single-task, against DDPM's best of the same study as above, and paired with the
default bridge per seed.

Made by `bridgeplan study report onestep` (studies/onestep.toml) into docs/results/onestep.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from bridgeplan.analysis.keys import OPEN_LOOP, MethodKey, execution_name, label, tasks_label
from bridgeplan.analysis.keys import method as key
from bridgeplan.analysis.load import Point, Results, exported_rows
from bridgeplan.analysis.selection import best
from bridgeplan.analysis.stats import goal_verdict, paired
from bridgeplan.analysis.tables import fmt_diff, fmt_mean_se, table
from bridgeplan.bench.markdown import load_sentence
from bridgeplan.replan import Execution

SOURCES = ("onestep-medium", "onestep-large")
"""The studies' folders under docs/results, in the report's order (a folder not exported yet is left out)."""
N = 16
DDPM = key("ddpm", steps=N)
ONE_STEP = (key("distill", steps=N),
            *(key(process, prior, steps=N) for process in ("meanflow", "shortcut")
              for prior in ("gaussian", "line", "learned")))
PARAMETRIZATIONS_SOURCES = ("medium-v2-curves", "large-v2-curves")
BRIDGE = key("bridge", "line", steps=N)
PARAMETRIZATIONS = (BRIDGE, key("bridge", "line", steps=N, predict="x0"),
                    key("bridge", "line", steps=N, weighting="uniform"),
                    key("bridge", "line", steps=N, predict="ddbm", weighting="ddbm"))
"""The I2SB bridge from the line, its loss ablation (x0 output; equal weights) and DDBM's parametrization."""
READS = (DDPM, *ONE_STEP, *PARAMETRIZATIONS)
"""The trained methods the tables read (studies that make this report must train them)."""
GOAL_NFE = (1, 2)
LATENCY = "onestep-latency"
"""The folder under docs/results of the bench that times the decision at batch 1 (:data:`LATENCY_COMMAND`)."""
LATENCY_COMMAND = ("bridgeplan bench --presets cpu-small --mazes medium,large --batch-sizes 1 --nfes 1,2 --methods "
                   "\"DDPM [ancestral],"
                   "bridge (line),mean flow (line),shortcut (line)\" --repeats 200 --overhead-repeats 0 --no-compile "
                   "--frozen --busy-steps 0 --throughput-seconds 0 --side-by-side-seconds 0 --device cpu --out "
                   f"docs/results/{LATENCY}")
GOAL_MS = 2.0
"""Issue 43's goal for one decision at batch 1 on this CPU."""


@dataclass(frozen=True)
class Part:
    """One maze's rows of one execution and task set: a table of its own."""

    maze: str
    execution: Execution
    multi_task: bool
    results: Results

    @property
    def title(self) -> str:
        return f"{self.maze}, {execution_name(self.execution)}, {tasks_label(DDPM.replace(multi_task=self.multi_task))}"

    def here(self, method: MethodKey) -> MethodKey:
        return method.replace(execution=self.execution, multi_task=self.multi_task)

    def seeds(self) -> list[int]:
        return sorted({r.seed for r in self.results})


def parts_of(root: Path, sources=SOURCES) -> list[Part]:
    """The parts of every exported folder of ``sources``, in their order; tracked single-task first."""
    found = []
    for _, rows in exported_rows(root, sources):
        groups = dict.fromkeys((r.maze, r.key.execution, r.key.multi_task) for r in rows)
        for maze, execution, multi in sorted(groups, key=lambda g: (g[1] != OPEN_LOOP, g[1].tag(), g[2])):
            found.append(Part(maze, execution, multi, Results(
                r for r in rows if (r.maze, r.key.execution, r.key.multi_task) == (maze, execution, multi))))
    return found


def ddpm_bar(part: Part, step: int) -> Point | None:
    """DDPM's NFE chosen on the validation episodes (at the final snapshot), else on the test ones at ``step``."""
    ddpm, results = part.here(DDPM), part.results
    validation_steps = results.steps(ddpm, "validation")
    if validation_steps:
        chosen = best(results, results.points(ddpm, validation_steps[-1], "validation"), split="validation")
        return Point(ddpm, step, chosen.nfe) if results.rows(Point(ddpm, step, chosen.nfe)) else None
    return best(results, results.points(ddpm, step), split="test")


def cell(values: dict[int, float]) -> str:
    return fmt_mean_se(values, one_seed="mean") if values else "-"


def reaches(ours: dict[int, float], bar: dict[int, float]) -> str:
    if len(set(ours) & set(bar)) < 2:
        return "not measured"
    d = paired(ours, bar, seeds="common")
    return f"{goal_verdict(d, 'reaches')} ({fmt_diff(d)})"


def part_table(part: Part, methods=ONE_STEP, versus: MethodKey | None = None) -> list[str]:
    """Rows: DDPM's bar, then each of ``methods`` at NFE 1 and 2; columns: the snapshots, the verdict at the last one,
    and with ``versus`` each method's difference from it at the same NFE there (paired per seed)."""
    results = part.results
    steps = results.steps(part.here(DDPM))
    if not steps:
        return ["No DDPM rows in this part: nothing to compare with."]
    bars = {step: ddpm_bar(part, step) for step in steps}
    header = ["method", "NFE", *(f"step {s}" for s in steps), f"reaches DDPM's best at step {steps[-1]}"]
    against = [f"against {label(versus)}"] if versus else []
    rows = [["DDPM's best", " / ".join(str(bars[s].nfe) if bars[s] else "-" for s in steps),
             *(cell(results.values(bars[s])) if bars[s] else "-" for s in steps), "", *[""] * len(against)]]
    final_bar = results.values(bars[steps[-1]]) if bars[steps[-1]] else {}
    for method in methods:
        here = part.here(method)
        for nfe in GOAL_NFE:
            scores = [results.values(Point(here, s, nfe)) for s in steps]
            if not any(scores):
                continue
            row = [label(method), nfe, *(cell(v) for v in scores), reaches(scores[-1], final_bar)]
            if versus:
                base = results.values(Point(part.here(versus), steps[-1], nfe))
                row.append("" if method == versus else fmt_diff(paired(scores[-1], base, seeds="common"))
                           if len(set(scores[-1]) & set(base)) >= 2 else "not measured")
            rows.append(row)
    return table(header + against, rows)


def parametrizations_section(root: Path) -> list[str]:
    """The bridge's parametrizations, tracked, single-task: a table per maze of :data:`PARAMETRIZATIONS_SOURCES`."""
    lines = []
    for source in PARAMETRIZATIONS_SOURCES:
        found = [p for p in parts_of(root, (source,)) if p.execution == OPEN_LOOP and not p.multi_task]
        if not found:
            continue
        part = found[0]
        lines += [f"## The bridge's parametrizations ({part.maze}, tracked, single-task)", "",
                  f"From docs/results/{source} (studies/{source}.toml: cpu-small at batch 32, lr 1e-3, training seeds "
                  f"{', '.join(map(str, part.seeds()))}): I2SB's bridge from the line as trained by default (its "
                  "network predicts the scaled difference, I2SB's weighting), where the study has them its loss "
                  "ablation (`predict=x0`; `weighting=uniform`), and DDBM's parametrization (`predict=ddbm`, "
                  "`weighting=ddbm`: EDM's preconditioning on the bridge's marginal at DDBM's assumed moments, "
                  "docs/conventions.md), at NFE 1 and 2, against DDPM's best of the same study (chosen as above) and "
                  "against the default bridge at the same NFE; Minari score, mean ± SE over seeds, differences per "
                  "seed.", "", *part_table(part, PARAMETRIZATIONS, BRIDGE), ""]
    return lines


def latency_section(root: Path) -> list[str]:
    """One plan call at batch 1 (the decision of a replanning agent, prior included; the controller's step is not
    timed) of the campaigns' network (cpu-small, untrained: time does not depend on the weights) against
    :data:`GOAL_MS`."""
    path = Path(root) / LATENCY / "bench.json"
    lines = ["## The decision at batch 1", ""]
    if not path.exists():
        return lines + [f"Not measured yet: `{LATENCY_COMMAND}`."]
    bench = json.loads(path.read_text())
    m = bench["machine"]
    # a bench made before the latency table named its plans' shape timed umaze's (128 states one step apart)
    rows = [[f"{r.get('maze', 'umaze')}, {r.get('horizon', 128)} x {r.get('stride', 1)}", r["method"], r["nfe"],
             f"{r['plan_ms']:.2f}", "yes" if r["plan_ms"] < GOAL_MS else "no"]
            for r in bench["latency"] if r["batch"] == 1]
    return lines + [f"Milliseconds per plan call at batch 1 (the prior's sample included), cpu-small's U-Net, "
                    f"median of {bench['bench']['repeats']} calls; code {m['code_version']}, {m['device']} "
                    f"({m.get('cpu') or m['processor']}, {m['cpu_count']} cores, {m['torch_threads']} torch "
                    f"thread).{load_sentence(m)} A method named '..., frozen' plans through its network traced and "
                    f"frozen (`eval --frozen`: the same plans). Made by `{LATENCY_COMMAND}` "
                    f"(docs/results/{LATENCY}/bench.md).", "",
                    *table(["plans (states x steps apart)", "method", "NFE", "plan ms", f"under {GOAL_MS:g} ms"], rows)]


def render(root: Path) -> str:
    lines = ["# One network call against DDPM's best at any NFE (issue 43)", "",
             "Generated by `bridgeplan study report onestep` from the committed rows of "
             + ", ".join(f"docs/results/{s}" for s in SOURCES) + " (studies/onestep-medium.toml, "
             "studies/onestep-large.toml); how the bar and the verdicts are made: studies/reports/onestep.py.", ""]
    found = parts_of(root)
    if not found:
        lines += ["No rows committed yet. The campaigns: `bridgeplan study run onestep-medium` then "
                  "`bridgeplan study export onestep-medium`, and the same for onestep-large.", ""]
    for part in found:
        lines += [f"## {part.title}", "",
                  f"Training seeds {', '.join(map(str, part.seeds()))}; Minari score, mean ± SE over seeds.", "",
                  *part_table(part), ""]
    lines += parametrizations_section(root)
    lines += latency_section(root)
    return "\n".join(lines).rstrip("\n")
