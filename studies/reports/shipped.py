"""docs/results/shipped.md: the shipped planners (src/bridgeplan/shipped/) and their own scores.

Each shipped planner is one training run (seed 0) of the headline's method on its maze, at the config of
the study the headline chose it from (studies/shipped-<maze>.toml), and evaluated at the headline's chosen settings
(the best tracked and the best pursued planner, single-task and Multi2D) on the 200 test episodes of seed 0. Its
rows: docs/results/shipped/<maze>/results.csv. Beside each, the headline's own score (mean ± standard error over 3
training seeds' runs, docs/results/headline.md), for scale. Whether the shipped run is the headline's seed-0 run is
read from the rows, not assumed: it is when their evaluations at every setting are equal (:func:`same_run`).

The settings are not copied from the headline: this report reads the headline's choice from its committed rows and
looks the shipped rows up at that setting; a setting the shipped study did not evaluate says so (the study file then
needs the new setting). The files' facts come from the manifest ``bridgeplan planners export`` writes.

Made by `bridgeplan study report shipped` (studies/shipped.toml) into docs/results/shipped.md and the README's
generated block.
"""

from __future__ import annotations

from pathlib import Path

from bridgeplan.analysis.keys import MethodKey, method
from bridgeplan.analysis.load import Point, Results, Row, load_csvs
from bridgeplan.analysis.selection import best
from bridgeplan.analysis.tables import table

from . import headline

ROWS = "shipped/{maze}/results.csv"
"""A shipped planner's committed rows, relative to docs/results (its study's ``data`` folder)."""
READS = (method("flow", "line", steps=16), method("ddpm", steps=16))
"""The headline's methods on umaze (flow from the line prior) and on medium and large (DDPM)."""


def headline_choice(root: Path, maze: str, multi_task: bool, pursued: bool) -> tuple[Results, Point | None]:
    """The headline's rows of ``maze`` and its chosen point (chosen on validation, as headline.md's)."""
    results = headline.load(root, maze)
    return results, best(results, headline.candidates(results, multi_task, pursued))


def shipped_point(results: Results, key: MethodKey, nfe: int) -> Point | None:
    """The shipped run's point at ``key`` and ``nfe`` (its final snapshot), None when not evaluated."""
    steps = results.steps(key)
    if not steps:
        return None
    point = Point(key, steps[-1], nfe)
    return point if results.rows(point) else None


def call_args(key: MethodKey, nfe: int) -> str:
    """``PlannerPolicy.from_run``'s keyword arguments for the setting (open loop: ``replan_every=None``)."""
    ex = key.execution
    args = [f"nfe={nfe}", f"replan_every={ex.replan_every}"]
    if ex.controller != "track":
        args += [f'controller="{ex.controller}"', f"lookahead={ex.lookahead:g}"]
    return ", ".join(args)


def eval_flags(key: MethodKey, nfe: int) -> str:
    """``bridgeplan eval``'s flags for the setting (seed 0 and 200 episodes are its defaults)."""
    ex = key.execution
    flags = [f"--nfe {nfe}"]
    if ex.replan_every:
        flags.append(f"--replan-every {ex.replan_every}")
    if ex.controller != "track":
        flags.append(f"--controller {ex.controller} --lookahead {ex.lookahead:g}")
    if key.multi_task:
        flags.append("--multi-task")
    return " ".join(flags)


def shipped_score(results: Results, point: Point) -> str:
    """``104.2 ± 1.1 (0.90)``: the one run's score ± standard error over its episodes, and its success rate."""
    (row,) = results.rows(point).values()
    return f"{row.score:.1f} ± {row.score_se:.1f} ({row.success:.2f})"


def _success(scored: str) -> str:
    """``104.2 ± 1.1 (0.90)`` as ``104.2 ± 1.1 (success 0.90)``."""
    return scored.replace(" (", " (success ")


def entries(root: Path) -> list[dict]:
    """Per maze, task set and execution: the headline's choice, its score and the shipped run's at that setting."""
    out = []
    for maze in headline.MAZES:
        path = root / ROWS.format(maze=maze)
        shipped = load_csvs([path])
        for multi_task in (False, True):
            for pursued in (False, True):
                results, chosen = headline_choice(root, maze, multi_task, pursued)
                if chosen is None:
                    continue
                point = shipped_point(shipped, chosen.key, chosen.nfe)
                rows = shipped.rows(point) if point else {}
                row = next(iter(rows.values()), None)
                out.append(dict(maze=maze, multi_task=multi_task, pursued=pursued, key=chosen.key, nfe=chosen.nfe,
                                setting=headline.describe(chosen.key, chosen.nfe),
                                headline=headline.scored(results, chosen),
                                shipped=shipped_score(shipped, point) if point else None,
                                row=row, same=row is not None and _equal(row, results.rows(chosen).get(row.seed))))
    return out


def _equal(a: Row, b: Row | None) -> bool:
    """The same evaluation of the same weights: run, snapshot, episodes and every score equal."""
    fields = ("run_name", "step", "nfe", "episodes", "eval_seed", "score", "score_se", "success")
    return b is not None and all(getattr(a, f) == getattr(b, f) for f in fields)


def same_run(found: list[dict], maze: str) -> bool:
    """The shipped run of ``maze`` is the headline's run of its seed: their rows are equal at every setting."""
    mine = [e for e in found if e["maze"] == maze]
    return bool(mine) and all(e["same"] for e in mine)


def _missing(e: dict) -> str:
    return f"not evaluated: add this setting to studies/shipped-{e['maze']}.toml and run it"


def block(root: Path) -> str:
    """The README's lines: per shipped planner, its best pursued single-task setting as a policy, with its score."""
    lines = []
    found = entries(Path(root))
    for e in found:
        if e["multi_task"] or not e["pursued"]:
            continue
        which = "seed 0 is this run" if same_run(found, e["maze"]) else "not this run"
        score = (f"{_success(e['shipped'])}, ± the standard error over its 200 test episodes (`bridgeplan eval "
                 f"{e['maze']} {eval_flags(e['key'], e['nfe'])}`)" if e["shipped"] else _missing(e))
        lines.append(f"- `PlannerPolicy.from_run(\"{e['maze']}\", {call_args(e['key'], e['nfe'])})`: {e['maze']} "
                     f"single-task, {e['setting']}: {score}; the headline's 3 training runs of the method (seeds 0-2, "
                     f"{which}): {_success(e['headline'])}, mean ± SE over seeds")
    return "\n".join(lines)


def files_table(found: list[dict]) -> list[str]:
    from bridgeplan import shipped

    planners = shipped.manifest()
    rows = [[e.name, e.maze, e.method, e.step, e.seed, f"{e.parameters:,}", f"{e.bytes / 1e6:.2f} MB",
             f"`{e.study}`", e.code_version, "yes (equal rows)" if same_run(found, e.maze) else "no (rows differ)",
             f"`{e.sha256[:16]}`"] for e in planners.values()]
    return table(["name", "maze", "method", "training step", "training seed", "parameters", "file",
                  "study", "trained at code", "the headline's run of that seed", "sha256 (first 16)"], rows)


def render(root: Path) -> str:
    root = Path(root)
    found = entries(root)
    versions = sorted({e["row"].code_version for e in found if e["row"] is not None})
    rows = [[e["maze"], "Multi2D" if e["multi_task"] else "single-task", "pursued" if e["pursued"] else "tracked",
             e["setting"], e["shipped"] or _missing(e), e["headline"],
             f"`bridgeplan eval {e['maze']} {eval_flags(e['key'], e['nfe'])}`"] for e in found]
    return "\n".join([
        "# Shipped planners", "",
        "Generated by `bridgeplan study report shipped` from docs/results/shipped/<maze>/results.csv (studies/"
        "shipped-<maze>.toml; evaluated at codes " + (", ".join(versions) or "none") + "), the headline's rows "
        "(docs/results/headline.md) and src/bridgeplan/shipped/manifest.json (`bridgeplan planners export`).", "",
        "Each shipped planner is ONE training run (seed 0) of the headline's method on its maze, at the config of "
        "the study the headline chose it from (cpu-small, dataset version 2 of 1 M steps, the same batch, optimizer "
        "steps and hold share). Where its rows equal the headline's seed-0 rows at every setting it is that run "
        "(the files' column says so); otherwise it is another run of that config, retrained, which did not "
        "reproduce that run bit for bit. It is evaluated at the headline's chosen settings (chosen on "
        "validation episodes from the headline's rows, read here, not copied) on the 200 test episodes of seed 0: "
        "its Minari score ± standard error over those episodes (success rate), beside the headline's mean ± "
        "standard error over 3 training seeds. `bridgeplan eval NAME` with the flags shown evaluates the same "
        "episodes (seed 0, 200 episodes are its defaults).", "",
        "## The files", "",
        *files_table(found), "",
        "## Their scores", "",
        *table(["planner", "tasks", "executed", "setting (the headline's choice)",
                "shipped: score ± SE over 200 episodes (success), one run", "headline: mean ± SE over 3 seeds "
                "(success)", "command"], rows)])
