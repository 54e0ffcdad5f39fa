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

A shipped policy (OGBench manipulation: the dataset graph over a GCIQL policy, the best planner of
docs/results/manipulation.md) is one training run (seed 0) at its study's config (studies/shipped-<name>.toml),
evaluated alone and under the graph as docs/results/manip-<name>/ evaluates it: its rows are
docs/results/shipped/<name>/*.json, beside manip-<name>'s rows of the same method over 3 training seeds.

Made by `bridgeplan study report shipped` (studies/shipped.toml) into docs/results/shipped.md and the README's
generated block.
"""

from __future__ import annotations

import json
from pathlib import Path

from bridgeplan.analysis.keys import MethodKey, method
from bridgeplan.analysis.load import Point, Results, Row, load_csvs
from bridgeplan.analysis.selection import best
from bridgeplan.analysis.tables import fmt_mean_se, table

from . import headline, manipulation

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
    return "\n".join(lines + [policy_line(p) for p in policies(Path(root))])


def policies(root: Path) -> list[dict]:
    """Per shipped policy of the manifest: its committed rows (the graph over it and the policy alone), the graph's
    flags, and manip-NAME's test success of the same method by training seed; ``same``: its graph row's episodes equal
    that study's row of the same training seed."""
    from bridgeplan import shipped

    out = []
    for e in shipped.manifest().values():
        if e.kind != "policy":
            continue
        home = Path(root) / Path(e.rows).relative_to("docs/results")
        found = {p: json.loads(p.read_text()) for p in sorted(home.rglob("*.json"))}
        graph = next(((p, r) for p, r in found.items() if "graph" in r), None)
        if graph is None:
            out.append(dict(entry=e, graph=None))
            continue
        path, row = graph
        method = path.parent.name.split("-s")[0]  # its folder's, as manip-NAME's
        theirs = manipulation.rows(root, e.name)
        seed_row = next((r for r in theirs if r["method"] == method and not r["validation"]
                         and r["config"]["low"]["seed"] == e.seed), None)
        g = row["graph"]
        out.append(dict(entry=e, graph=row, alone=next((r for r in found.values() if "graph" not in r), None),
                        label=manipulation.label(method, theirs),
                        theirs=manipulation.test_rates(theirs).get(method, []),
                        same=seed_row is not None and seed_row["tasks"] == row["tasks"],
                        flags=f"--keep {g['keep']} --radius {g['radius']:g} --replan-every "
                              f"{row['execution']['replan_every']} --policy-ahead {row['low']['ahead']}",
                        call=f"replan_every={row['execution']['replan_every']}, graph={{\"keep\": {g['keep']}, "
                             f"\"radius\": {g['radius']:g}}}, policy_ahead={row['low']['ahead']}"))
    return out


def policy_line(p: dict) -> str:
    """The README's line of a shipped policy."""
    e = p["entry"]
    if p["graph"] is None:
        return f"- `{e.name}`: not evaluated: run studies/shipped-{e.name}.toml and export it"
    row, alone = p["graph"], p["alone"]
    which = f"seed {e.seed} is this run" if p["same"] else "not this run"
    return (f"- `bridgeplan graph --low {e.name} {p['flags']}` (`PlannerPolicy.from_graph(\"{e.name}\", {p['call']})`; "
            f"the graph over your own `bridgeplan data generate --maze {e.maze}`): {e.maze}, {p['label']}: "
            f"{100 * row['success_rate']:.1f}% of its 5 test tasks' {row['episodes']} episodes, one run"
            + (f" (the policy alone: {100 * alone['success_rate']:.1f}%, `bridgeplan eval {e.name}`)" if alone else "")
            + f"; docs/results/manip-{e.name}'s {len(p['theirs'])} training runs ({which}): "
              f"{fmt_mean_se(p['theirs'], one_seed='mean')}%, mean ± SE over seeds")


def files_table(found: list[dict], policy_list: list[dict]) -> list[str]:
    from bridgeplan import shipped

    same = {p["entry"].name: p["graph"] is not None and p["same"] for p in policy_list}
    rows = [[e.name, e.maze, e.method, e.step, e.seed, f"{e.parameters:,}", f"{e.bytes / 1e6:.2f} MB",
             f"`{e.study}`", e.code_version,
             "yes (equal rows)" if same.get(e.name, same_run(found, e.maze)) else "no (rows differ)",
             f"`{e.sha256[:16]}`"] for e in shipped.manifest().values()]
    return table(["name", "maze", "method", "training step", "training seed", "parameters", "file",
                  "study", "trained at code", "its campaign's run of that seed", "sha256 (first 16)"], rows)


def render(root: Path) -> str:
    root = Path(root)
    found = entries(root)
    policy_list = policies(root)
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
        *files_table(found, policy_list), "",
        "## Their scores", "",
        *table(["planner", "tasks", "executed", "setting (the headline's choice)",
                "shipped: score ± SE over 200 episodes (success), one run", "headline: mean ± SE over 3 seeds "
                "(success)", "command"], rows),
        *(["", "## Shipped policies: OGBench manipulation", "",
           "The dataset graph over the user's own data, its paths executed by the shipped policy: docs/results/"
           "shipped/<name>/ (studies/shipped-<name>.toml), OGBench's 5 test tasks, 50 episodes each, evaluation seed "
           "0, beside the same method's runs in docs/results/manip-<name>/ (mean ± SE over training seeds). The "
           "graph is refused over data of another identity than its rows'.", "",
           *[policy_line(p) for p in policy_list]] if policy_list else [])])
