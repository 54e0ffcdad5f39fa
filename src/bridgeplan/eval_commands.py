"""The evaluation commands a study runs (``eval``, of a planner's run or a GCBC/GCIQL policy's, ``hierarchy eval``,
``graph``, ``oracle``): each an options dataclass (:mod:`bridgeplan.options`) and a function of it. The CLI
(:mod:`bridgeplan.commands`) parses its flags into the dataclass and calls the function; the study runner
(:mod:`bridgeplan.studies.jobs`) fills the same dataclass from a study's ``args`` table and calls the function
(:data:`STUDY_COMMANDS`). Their options are declared in :mod:`bridgeplan.option_groups` where other commands share
them. torch is imported only when a command runs."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from bridgeplan.errors import BridgeplanError
from bridgeplan.option_groups import (
    EXECUTION,
    Controller,
    Correction,
    Dataset,
    Device,
    Environment,
    LowLevel,
    Output,
    Picture,
    PlanChoice,
    Progress,
    Replanning,
    Tasks,
    Threads,
    task_ids,
)
from bridgeplan.options import from_config, group, int_tuple, leaves, opt, positive, shared, values


def execution(replanning: Replanning, controller: Controller, plans: PlanChoice | None = None, env: str | None = None):
    """The :class:`~bridgeplan.replan.Execution` the options say (``plans``: a planner's, else the defaults); where
    they give no controller, ``env``'s family's path controller (``Family.path_controller``)."""
    from bridgeplan.envs import family_of
    from bridgeplan.envs.controllers import check_controller
    from bridgeplan.replan import Execution

    kind = family_of(env).path_controller if controller.controller is None else controller.controller
    if controller.lookahead is not None and kind != "pursuit":
        raise BridgeplanError("--lookahead is the pursuit controller's: give --controller pursuit")
    check_controller(kind, controller.lookahead)
    common = {"replan_every": replanning.replan_every, "tolerance": replanning.replan_tolerance,
              "controller": kind, "lookahead": controller.lookahead}
    if plans is None:
        return Execution(**common)
    if plans.prior is not None and plans.prior != "warm":
        raise BridgeplanError(f"--prior takes warm (replans start from the previous plan; the first plan uses "
                              f"the run's own prior), got {plans.prior!r}")
    return Execution(**common, candidates=plans.candidates, select=plans.select, warm=plans.prior == "warm",
                     arrival=plans.arrival)


def parsed_correction(options: Correction):
    """The :class:`~bridgeplan.consistency.Correction` the options say, or None."""
    from bridgeplan.consistency import Correction as Parsed

    if not options.correction:
        if options.correction_form is not None:
            raise BridgeplanError("--correction-form needs --correction RESIDUAL=STEP")
        return None
    return Parsed.parse(options.correction, options.correction_form or "x0")


def _show(result, output: Output, out: Path) -> int:
    from bridgeplan.evaluate import format_table, write_and_show

    d = result.to_dict()
    write_and_show(d, out, output.json, format_table(d))
    return 0


# --- eval -----------------------------------------------------------------------------------------------------------

@dataclass(kw_only=True)
class EvalOptions:
    run: str = opt(help="run directory (a planner's or a GCBC/GCIQL policy's; or a checkpoint/snapshot file), or a "
                        "shipped planner's name (`bridgeplan planners list`)")
    nfe: int | None = opt(None, "network calls per plan (default: the full count)")
    plan_batch: int | None = opt(None, "episodes planned per network call (default: all live episodes at once; "
                                       "--batch-size of the training commands is the gradient's)")
    snapshot: int | None = opt(None, "evaluate the EMA snapshot of this training step")
    sampler: str | None = opt(None, "a process with several samplers: ddpm ancestral (default; strided below N) or "
                                    "ddim; flow euler (default) or stochastic; bridge posterior (default) or mean (no "
                                    "noise)")
    eta: float = opt(0.0, "ddpm with ddim: eta (0: deterministic)")
    correction: Correction = group(Correction)
    compile: bool = opt(False, "through the torch.compile'd network: planning compiles first, untimed (see "
                               "`bridgeplan bench`); training compiles at the first step")
    frozen: bool = opt(False, "plan through the network traced and frozen (TorchScript): the same plans, a batch-1 "
                              "decision faster on a CPU (`bridgeplan bench --frozen`)")
    no_floor: bool = opt(False, "skip the floors (the same episodes from the straight line alone, no network)")
    tasks: Tasks = group(Tasks)
    replanning: Replanning = group(Replanning)
    plans: PlanChoice = group(PlanChoice)
    controller: Controller = group(Controller)
    device: Device = group(Device)
    output: Output = group(Output)
    progress: Progress = group(Progress)
    threads: Threads = group(Threads)


EVAL_DESCRIPTION = ("Maze2D: seeded single-task or Multi2D episodes, the normalized score; OGBench: its 5-task "
                    "protocol, the success rate; your own environment (a spec file): its seeded resets, the success "
                    "rate. Beside the score: the straight line alone, the cost and the decision latency. A GCBC or "
                    "GCIQL run (`gcbc train`): its policy toward each episode's goal, acting at every step (the "
                    "options about plans do not apply). Writes RUN/eval/<settings>.json unless --out.")


def eval_run(o: EvalOptions) -> int:
    from bridgeplan.evaluate import check_result_path, evaluate_run
    from bridgeplan.gcbc import is_gcbc_run
    from bridgeplan.paths import eval_dir
    from bridgeplan.runs import run_dir_of

    if is_gcbc_run(o.run):
        return _eval_policy(o)
    if o.plan_batch is not None:
        positive("--plan-batch", o.plan_batch)
    plan = execution(o.replanning, o.controller, o.plans)
    correction = parsed_correction(o.correction)
    folder = eval_dir(run_dir_of(Path(o.run)))
    check_result_path(o.output.out, folder)
    result = evaluate_run(Path(o.run), episodes=o.tasks.episodes, nfe=o.nfe, seed=o.tasks.seed,
                          multi_task=o.tasks.multi_task, task_ids=o.tasks.ids, batch_size=o.plan_batch,
                          snapshot=o.snapshot, device=o.device.device, sampler=o.sampler, eta=o.eta,
                          compile=o.compile, execution=plan, correction=correction, floor=not o.no_floor,
                          frozen=o.frozen)
    d = result.to_dict()
    name = "-".join(part for part in (
        f"step{d['step']}-nfe{d['nfe']}", o.sampler and f"{o.sampler}{o.eta:g}",
        o.compile and "compiled", o.frozen and "frozen", plan.resolved(result.family, result.tasks.env).tag(),
        correction and correction.file_tag()) if part)
    return _show(result, o.output, _out(o.output, o.tasks, folder, name))


def _out(output: Output, tasks: Tasks, folder: Path, name: str) -> Path:
    """``--out``, else ``folder/name-<task settings>.json``."""
    return Path(output.out) if output.out else folder / f"{name}{tasks.file_tag()}.json"


POLICY_GROUPS = {("tasks",), ("device",), ("output",), ("progress",), ("threads",)}
"""The groups of ``eval``'s options that a policy's evaluation takes (with the run and its snapshot)."""


def plan_options() -> list:
    """``eval``'s options that only a planner takes: a GCBC/GCIQL policy's evaluation refuses them."""
    return [leaf for leaf in leaves(EvalOptions)
            if leaf.path not in POLICY_GROUPS and leaf.name not in ("run", "snapshot")]


def _eval_policy(o: EvalOptions) -> int:
    """``eval`` of a GCBC/GCIQL run: its policy (``--snapshot``: that step's) on its environment's tasks, its JSON
    every evaluation's; the flags about plans do not apply and are refused."""
    from bridgeplan.evaluate import check_result_path
    from bridgeplan.gcbc import evaluate_policy
    from bridgeplan.paths import eval_dir
    from bridgeplan.runs import run_dir_of

    given = values(o)
    planning = [leaf.flag for leaf in plan_options() if given[leaf.name] != leaf.default]
    if planning:
        raise BridgeplanError(f"{o.run} is a GCBC run (a policy, no plans): {', '.join(planning)} do not apply")
    folder = eval_dir(run_dir_of(Path(o.run)))
    check_result_path(o.output.out, folder)
    result = evaluate_policy(o.run, o.tasks.episodes, o.tasks.seed, o.tasks.multi_task, o.tasks.ids, o.snapshot,
                             o.device.device, progress=not o.progress.no_progress)
    name = f"{result.entries['method']}-step{result.entries['step']}"
    return _show(result, o.output, _out(o.output, o.tasks, folder, name))


# --- hierarchy eval and graph -------------------------------------------------------------------------------------

@dataclass(kw_only=True)
class LevelledEvaluation:
    """What a hierarchy's and a graph's evaluations share: a low level's settings, the tasks, replanning and the
    controller (the family's path controller by default: both follow a coarse path), and where and how they run."""

    low_level: LowLevel = group(LowLevel)
    tasks: Tasks = group(Tasks)
    replanning: Replanning = group(Replanning)
    controller: Controller = group(Controller, controller=None)
    device: Device = group(Device)
    output: Output = group(Output)
    progress: Progress = group(Progress)
    threads: Threads = group(Threads)


@dataclass(kw_only=True)
class HierarchyEvalOptions(LevelledEvaluation):
    high: str = opt(help="the high level's run directory (a long --stride)")
    low: str = opt(help="the low level's run directory (trained with --subgoal-every J; J x its stride = the high "
                        "level's stride)")
    high_snapshot: int | None = opt(None, "the high level's snapshot (training step)")
    nfe_high: int | None = opt(None, "network calls per coarse plan (default: all)")


HIERARCHY_DESCRIPTION = ("The high level plans once per episode; the low level plans from the current state through "
                         "the coarse plan's next states every --replan-every steps. Writes "
                         "LOW/eval/hierarchy-<settings>.json unless --out.")


def hierarchy_eval(o: HierarchyEvalOptions) -> int:
    from bridgeplan.evaluate import check_result_path, run_tasks
    from bridgeplan.hierarchy import evaluate_hierarchy, load_hierarchy
    from bridgeplan.paths import eval_dir
    from bridgeplan.runs import run_dir_of

    if o.tasks.episodes is not None:
        positive("--episodes", o.tasks.episodes)
    if o.controller.controller is not None:
        execution(o.replanning, o.controller)  # a controller given is refused before anything is read
    folder = eval_dir(run_dir_of(Path(o.low)))
    check_result_path(o.output.out, folder)  # before anything is loaded
    low_level = o.low_level
    hierarchy, high, low = load_hierarchy(Path(o.high), Path(o.low), o.high_snapshot, low_level.low_snapshot,
                                          o.device.device)
    tasks = run_tasks(low, o.tasks.episodes, o.tasks.seed, o.tasks.multi_task, o.tasks.ids)
    plan = execution(o.replanning, o.controller, env=tasks.env)
    if plan.replan_every is None:
        plan = dataclasses.replace(plan, replan_every=hierarchy.spacing)
    result = evaluate_hierarchy(hierarchy, high, low, tasks, o.nfe_high, low_level.nfe_low, plan,
                                low_level.replan_high_every, progress=not o.progress.no_progress)
    d = result.to_dict()
    name = (f"hierarchy-{high.name}-step{high.step}-nfe{d['high']['nfe']}-step{low.step}-nfe{d['low']['nfe']}-"
            f"{plan.resolved(result.family, tasks.env).tag()}"
            + (f"-high{low_level.replan_high_every}" if low_level.replan_high_every else ""))
    return _show(result, o.output, _out(o.output, o.tasks, folder, name))


@dataclass(kw_only=True)
class GraphSettings:
    title: ClassVar[str] = "the graph (defaults: the environment family's)"
    keep: int | None = opt(None, "every keep-th state of an episode is a node (10)")
    radius: float | None = opt(None, "nodes of other episodes (or farther along one stream) within this distance are "
                                     "joined: below a wall's thickness (Maze2D 0.2, OGBench 0.5)")
    neighbours: int | None = opt(None, "at most this many such joins per node (8)")
    reach: float | None = opt(None, "the start and the goal join the nodes within this distance, else the nearest "
                                    "(Maze2D 0.5, OGBench 2.0)")


@dataclass(kw_only=True)
class GraphOptions(LevelledEvaluation):
    environment: Environment = group(Environment)
    dataset: Dataset = group(Dataset)
    low: str | None = opt(None, "a low level: a planner trained with --subgoal-every J that plans through the "
                                "graph's path, or a GCBC or GCIQL run (`gcbc train`) whose policy acts toward the "
                                "path's state --policy-ahead steps on (default: the path alone, executed by the "
                                "family's controller)", metavar="RUN")
    policy_ahead: int | None = opt(None, "a policy low level's goal: the graph's path this many steps on (default "
                                         "25, chosen on cube-single's validation tasks)", metavar="K")
    graph: GraphSettings = group(GraphSettings)
    objects: bool = opt(False, "the objects apart (OGBench's cubes): one graph per cube over the arm and that cube, "
                               "a path moving one cube not yet at its goal after another (bridgeplan.graph."
                               "ObjectGraphs); "
                               "a puzzle's buttons: the presses solved (Lights Out), each decision the arm's way to "
                               "the next press (bridgeplan.graph.ButtonPresses); scene: one graph per part (cube, "
                               "buttons, drawer, window), a path taking the steps in order, a locked slide's button "
                               "first (bridgeplan.graph.SceneSteps)")
    hand: bool = opt(False, "with --objects on scene: the window's and its button's graphs measure the hand's "
                            "opening as well (a jump joins states whose hand is alike; chosen on validation, "
                            "bridgeplan.envs.ogbench_manipulation.HAND_SLIDES)")
    replan_after_step: int | None = from_config(EXECUTION, "after_step", metavar="S")
    replan_object_tolerance: float | None = from_config(EXECUTION, "object_tolerance", metavar="D")
    render: bool = opt(False, "also draw the first episode, its path executed again (the graph alone or by a policy "
                              "low level): a PNG beside the JSON, as `bridgeplan render` draws the environment's "
                              "episodes")
    picture: Picture = group(Picture)


GRAPH_DESCRIPTION = ("The data's states joined along their episodes and by short jumps between them "
                     "(bridgeplan.graph); alone, its shortest paths are executed as plans; with --low, its path, one "
                     "state every J x stride steps, is the subgoals a low level plans through every --replan-every "
                     "steps. --maze and --dataset default to the low level's. Writes LOW/eval/graph-<settings>.json, "
                     "or results/graph/MAZE/graph-<settings>.json, unless --out.")


def graph_eval(o: GraphOptions) -> int:
    from bridgeplan.envs import family_of
    from bridgeplan.evaluate import check_result_path, make_tasks
    from bridgeplan.gcbc import is_gcbc_run, run_env_and_dataset
    from bridgeplan.graph import check_graph_settings
    from bridgeplan.hierarchy import evaluate_graph
    from bridgeplan.paths import eval_dir
    from bridgeplan.runs import load_planner, resolve_run, run_dir_of

    if o.picture.video and not o.render:
        raise BridgeplanError("--video goes with --render")
    if o.low is not None:  # the run named first, before the flags and files that go with it
        resolve_run(Path(o.low))
    policy_low = o.low is not None and is_gcbc_run(o.low)
    if o.render and o.low is not None and not policy_low:
        raise BridgeplanError("--render draws the graph's own paths executed, alone or by a policy: not with a "
                              "planner low level")
    if o.objects and o.low is not None and not policy_low:
        raise BridgeplanError("--objects: the objects' graphs are executed alone or by a policy, not a planner low "
                              "level's high level")
    if o.policy_ahead is not None:
        positive("--policy-ahead", o.policy_ahead)
    if o.tasks.episodes is not None:
        positive("--episodes", o.tasks.episodes)
    if o.controller.controller is not None:
        execution(o.replanning, o.controller)  # a controller given is refused before anything is read
    settings = dataclasses.asdict(o.graph)
    check_graph_settings(**settings)
    env, dataset = o.environment.maze, o.dataset.dataset
    low_level = o.low_level
    if policy_low:
        trained_env, trained_data = run_env_and_dataset(o.low)
        env, dataset = env or trained_env, dataset or trained_data
    elif o.low is not None:
        _, low = load_planner(Path(o.low), snapshot=low_level.low_snapshot, device="cpu")
        env = env or low.config.maze
        dataset = dataset or low.config.dataset
    if env is None:
        raise BridgeplanError("give the environment (--maze NAME) or a low level (--low RUN)")
    if dataset is None:
        raise BridgeplanError("give the dataset the graph is made of (--dataset FILE), or a low level (--low RUN)")
    if not Path(dataset).exists():
        raise BridgeplanError(f"no dataset {dataset}: make it with `bridgeplan data generate --maze {env}`")
    family = family_of(env)
    if o.objects:
        from bridgeplan.graph import check_objects

        check_objects(family, env)  # refused before the data is read
    if o.hand:
        from bridgeplan.graph import check_hand

        check_hand(family, env, o.objects)
    if o.replan_after_step is not None and not (o.objects and family.graph_buttons(env) is None):
        raise BridgeplanError("--replan-after-step plans again where a path's first step ends: give --objects on a "
                              "cube or scene dataset (its paths are made of steps, one part at a time)")
    if o.replan_object_tolerance is not None and not (
            o.objects and (family.graph_objects(env) is not None or family.graph_scene(env) is not None)):
        raise BridgeplanError("--replan-object-tolerance plans again where an object left its plan: give --objects "
                              "on a cube or scene dataset (its paths say where every cube should be)")
    plan = dataclasses.replace(execution(o.replanning, o.controller, env=env), after_step=o.replan_after_step,
                               object_tolerance=o.replan_object_tolerance)
    folder = (eval_dir(run_dir_of(Path(o.low))) if o.low
              else Path("results") / "graph" / family.label(env))
    check_result_path(o.output.out, folder)
    draw = _graph_drawing(o, env) if o.render else None
    tasks = make_tasks(env, o.tasks.episodes, o.tasks.seed, o.tasks.multi_task, o.tasks.ids)
    plan.validate(None, tasks.episode_steps)  # before the graph is built
    heard = []  # the graph's decisions, tasks, execution and follower, drawn once the result's name is known
    result = evaluate_graph(tasks, dataset, settings, plan, Path(o.low) if o.low else None, low_level.nfe_low,
                            low_level.replan_high_every, low_level.low_snapshot, o.device.device,
                            progress=not o.progress.no_progress,
                            picture=draw and (lambda *args: heard.append(args)), objects=o.objects, hand=o.hand,
                            policy_ahead=o.policy_ahead)
    d = result.to_dict()
    g = d["graph"]
    tag = plan.resolved(result.family, env).tag()
    low_tag = (f"-{d['low']['agent']}-ahead{d['low']['ahead']}" if policy_low else
               f"-nfe{d['nfe']}" if o.low else "")
    name = f"graph-keep{g['keep']}-r{g['radius']:g}" + ("-objects" if o.objects else "") + (
        "-hand" if o.hand else "") + low_tag + (
        f"-{tag}" if tag else "") + (f"-high{low_level.replan_high_every}" if low_level.replan_high_every else "")
    out = _out(o.output, o.tasks, folder, name)
    drawn = [path for args in heard for path in draw(*args, out.with_suffix(".png"),
                                                     f"{env}: {d['method']}, {tag or 'open loop'}")]
    _show(result, o.output, out)
    if not o.output.json:  # the JSON alone on stdout; the pictures lie beside it
        print("\n".join(f"wrote {path}" for path in drawn))
    return 0


def _graph_drawing(o: GraphOptions, env: str):
    """``--render``'s drawing of the graph's first episode (checked before anything runs): a function of the graph's
    decisions, its tasks, execution and follower (a policy low level's, or None), the picture's path and title."""
    from bridgeplan.envs import family_of
    from bridgeplan.render import check_offscreen, render_episodes

    positive("--size", o.picture.size)
    family = family_of(env)
    if family.picture is None:
        raise BridgeplanError(f"--render: {family.title} episodes cannot be drawn")
    check_offscreen()

    def draw(decisions, tasks, execution, follower, path, title):
        return render_episodes(decisions, family, tasks.first(), execution, path, title, o.picture.video,
                               o.picture.size, follower)

    return draw


# --- oracle ---------------------------------------------------------------------------------------------------------

@dataclass(kw_only=True)
class OracleOptions:
    maze: list[str] = opt(help="environments (Maze2D mazes, OGBench dataset names: the maze's tasks)")
    seeds: str = opt("0", "comma-separated task seeds")
    task_sets: str = opt("single", "comma-separated: single (the family's tasks), multi (Maze2D: Multi2D's random "
                                   "goals)")
    episodes: int | None = shared(Tasks, "episodes")
    tasks: str | None = shared(Tasks, "tasks")
    output: Output = group(Output)
    progress: Progress = group(Progress)
    threads: Threads = group(Threads)


def oracle(o: OracleOptions) -> int:
    from bridgeplan.envs import family_of
    from bridgeplan.evaluate import make_tasks
    from bridgeplan.files import atomic_write_text, check_writable, code_version

    seeds = int_tuple(o.seeds, "--seeds", minimum=0)
    out = o.output.out
    if out:
        check_writable(out, "JSON file")
    sets = o.task_sets.split(",")
    rows = []
    for env in o.maze:
        family = family_of(env)
        for task_set in sets:
            if task_set not in family.task_sets:
                raise BridgeplanError(f"--task-sets: {family.title} has {', '.join(family.task_sets)}, not "
                                      f"{task_set!r}")
            for seed in seeds:
                tasks = make_tasks(env, o.episodes, seed, task_set == "multi", task_ids(o.tasks))
                agent = family.oracle(env)
                agent_outcome = family.run(tasks, agent, progress=not o.progress.no_progress)
                rows.append({**tasks.fields(), "policy": "oracle", **family.score(tasks, agent_outcome)})
                row = rows[-1]
                rate = row["success_rate"]["mean"] if isinstance(row["success_rate"], dict) else row["success_rate"]
                score = f"{row['score']['minari']['mean']:.1f} (Minari), " if "score" in row else ""
                if not o.output.json:
                    print(f"{env} {task_set} seed {seed}: {score}success {rate:.3f}")
    text = json.dumps({"code_version": code_version(), "rows": rows}, indent=2)
    if o.output.json:
        print(text)
    if out:
        atomic_write_text(Path(out), text + "\n")
        print(f"wrote {out}")
    return 0


# --- what a study runs ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StudyCommand:
    """An evaluation command as a study declares it: its options, its function, and the options its runs fill."""

    options: type
    run: Callable[..., int]
    runs: tuple[str, ...]
    """The options a study's runs fill, in order (a hierarchy: the high level, then the low one)."""
    optional_runs: bool = False
    """The runs may be left out (the dataset graph alone, without a low level)."""
    reads_dataset: bool = False
    """The runner gives it the study's dataset (``maze``, ``dataset``)."""
    seed: str = "seed"
    """The option the runner's evaluation seed fills."""


STUDY_COMMANDS = {
    "eval": StudyCommand(EvalOptions, eval_run, ("run",)),
    "hierarchy eval": StudyCommand(HierarchyEvalOptions, hierarchy_eval, ("high", "low")),
    "graph": StudyCommand(GraphOptions, graph_eval, ("low",), optional_runs=True, reads_dataset=True),
    "oracle": StudyCommand(OracleOptions, oracle, (), seed="seeds"),
}
