"""The ``bridgeplan`` subcommands that make data, train, evaluate, draw and measure (the evaluation commands a study
runs are :mod:`bridgeplan.eval_commands`'); :mod:`bridgeplan.cli` adds the commands that run studies and ship their
planners. Each subcommand is an options dataclass (:mod:`bridgeplan.options`; the groups several share:
:mod:`bridgeplan.option_groups`) and a function of it; user mistakes (BridgeplanError) print one ``error:`` line and
exit 2."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path

from bridgeplan import eval_commands as _ec
from bridgeplan import option_groups as og
from bridgeplan.errors import BridgeplanError, one_line_warnings
from bridgeplan.options import (
    REQUIRED,
    add_command,
    config_fields,
    from_config,
    group,
    int_tuple,
    opt,
    positive,
    shared,
)

TRAIN_CONFIG = "bridgeplan.config:TrainConfig"
DESCRIPTION = ("planning with diffusion models and bridges from informative priors, in Maze2D, OGBench (pointmaze "
               "and manipulation) and your own goal-conditioned environment")


@dataclasses.dataclass(kw_only=True)
class DataGenerateOptions:
    environment: og.Environment = group(og.Environment, maze=REQUIRED)
    steps: int | None = opt(None, "Maze2D: transitions (default 1 M)")
    piece_steps: int | None = opt(None, "Maze2D: independent pieces of N steps, each from a random start, instead of "
                                        "one stream per worker: a stitching dataset (as OGBench's stitch; default "
                                        "directory <maze>-<steps>-piecesN)", metavar="N")
    workers: int = opt(1, "Maze2D: parallel processes, each generating its own independently seeded stream")
    episodes: int | None = opt(None, "OGBench: training episodes (default: the recipe's)")
    episode_steps: int | None = opt(None, "OGBench: steps per episode (default: the recipe's)")
    seed: int | None = opt(None, "the data's seed (default 123 (Maze2D), 0 (OGBench, as its scripts))")
    out: str | None = shared(og.Output, "out")
    force: bool = opt(False, "overwrite an existing dataset")
    progress: og.Progress = group(og.Progress)


@dataclasses.dataclass(kw_only=True)
class DataInfoOptions:
    path: str = opt(help="a Minari directory or id, a D4RL maze2d hdf5 file or an OGBench npz file")
    environment: og.Environment = group(og.Environment)
    json: bool = shared(og.Output, "json")


def _add_data_commands(sub) -> None:
    p = sub.add_parser("data", help="generate, inspect offline datasets (any environment family)")
    data = p.add_subparsers(dest="data_command", required=True)
    add_command(data, "generate", DataGenerateOptions, _cmd_data_generate,
                help="a dataset by the environment's family's recipe: Maze2D's noisy expert stream (Minari format, "
                     "Minari's D4RL recipe), OGBench's (its npz format)",
                description="--out: the dataset directory (Maze2D; default datasets/<maze>-<steps>) or folder of "
                            "NAME.npz and NAME-val.npz (OGBench; default datasets/ogbench), under $BRIDGEPLAN_DATASETS "
                            "when set.")
    add_command(data, "info", DataInfoOptions, _cmd_data_info,
                help="check and summarize a dataset (Minari directory or id, D4RL maze2d hdf5, OGBench npz)",
                description="--maze: the environment it should be of (needed for an OGBench file; a Minari dataset "
                            "names its maze).")


def _cmd_data_generate(o: DataGenerateOptions) -> int:
    from bridgeplan.envs import family_of

    maze = o.environment.maze
    family = family_of(maze)
    for flag in ("steps", "workers", "episodes", "episode_steps"):
        if getattr(o, flag) is not None:
            positive("--" + flag.replace("_", "-"), getattr(o, flag))
    if o.seed is not None and o.seed < 0:
        raise BridgeplanError(f"--seed must be >= 0, got {o.seed}")
    out, written = family.generate_dataset(maze, Path(o.out) if o.out else None,
                                  seed=family.data_seed if o.seed is None else o.seed,
                                  steps=o.steps, piece_steps=o.piece_steps, episodes=o.episodes,
                                  episode_steps=o.episode_steps, workers=o.workers, force=o.force,
                                  progress=not o.progress.no_progress)
    print(family.dataset_info(str(out), maze)[1])
    print(f"wrote {out}" if written else f"cached: {out} has this identity (nothing written; --force remakes it)")
    return 0


def _cmd_data_info(o: DataInfoOptions) -> int:
    from bridgeplan.envs import family_of, family_of_dataset

    maze = o.environment.maze
    family = family_of(maze) if maze else family_of_dataset(o.path)
    info, text = family.dataset_info(o.path, maze)
    print(json.dumps(info, indent=2) if o.json else text)
    return 0


@dataclasses.dataclass(kw_only=True)
class ReferenceOptions:
    environment: og.Environment = group(og.Environment)
    episodes: int | None = shared(og.Tasks, "episodes", default=100)
    seed: int = shared(og.Tasks, "seed", default=123)
    out: str | None = shared(og.Output, "out")


def _add_reference_commands(sub) -> None:
    p = sub.add_parser("reference", help="reference returns of the normalized score")
    ref = p.add_subparsers(dest="reference_command", required=True)
    s = ref.add_parser("show", help="the shipped reference returns")
    s.set_defaults(func=_cmd_reference_show)
    add_command(ref, "measure", ReferenceOptions, _cmd_reference_measure,
                help="measure them again in this environment",
                description="--maze: one maze (default: all); --out: also write the measured values to this JSON "
                            "file.")


def _reference_table(ref: dict) -> str:
    lines = [f"{'maze':<8} {'episodes':>8} {'seed':>5} {'random':>8} {'expert':>8} {'stale expert':>13}"]
    for name, r in ref.items():
        lines.append(f"{name:<8} {r['episodes']:>8} {r['seed']:>5} {r['random']:>8.2f} {r['expert']:>8.2f} "
                     f"{r['expert_stale']:>13.2f}")
    return "\n".join(lines) + ("\nscore conventions: minari = random..expert, d4rl = random..stale expert "
                               "(D4RL's reference procedure)")


def _cmd_reference_show(args) -> int:
    from bridgeplan.envs.maze2d.reference import load_reference_returns

    print(_reference_table(load_reference_returns()))
    return 0


def _cmd_reference_measure(o: ReferenceOptions) -> int:
    from bridgeplan.envs.maze2d.grids import MAZE_NAMES, get_maze
    from bridgeplan.envs.maze2d.reference import measure_reference_returns
    from bridgeplan.files import atomic_write_text, check_writable

    names = [get_maze(o.environment.maze).name] if o.environment.maze else list(MAZE_NAMES)
    positive("--episodes", o.episodes)
    if o.out:
        check_writable(o.out, "JSON file")
    measured = {n: measure_reference_returns(n, o.episodes, o.seed) for n in names}
    print(_reference_table(measured))
    if o.out:
        atomic_write_text(Path(o.out), json.dumps(measured, indent=2) + "\n")
        print(f"wrote {o.out}")
    return 0


@dataclasses.dataclass(kw_only=True)
class TrainCommon:
    """What a planner's and the learned prior's training take."""

    environment: og.Environment = group(og.Environment, maze=REQUIRED)
    dataset: og.Dataset = group(og.Dataset, dataset=REQUIRED)
    run: og.RunDir = group(og.RunDir)
    runs_root: str = opt("runs", "where a run's directory goes unless --run-dir")
    preset: str = opt("diffuser", "the defaults per maze: diffuser (Diffuser's Maze2D settings) or cpu-small; a "
                                  "learned prior takes its planners' horizon and stride")
    horizon: int | None = from_config(TRAIN_CONFIG, "horizon")
    stride: int | None = from_config(TRAIN_CONFIG, "stride")
    training: og.Training = group(og.Training)
    device: og.Device = group(og.Device, device=None)
    threads: og.Threads = group(og.Threads)
    progress: og.Progress = group(og.Progress)


@dataclasses.dataclass(kw_only=True)
class TrainOptions:
    common: TrainCommon = group(TrainCommon)
    process: str | None = opt(None, "ddpm, bridge, flow, meanflow, shortcut or distill (default ddpm; "
                                    "bridgeplan.processes)")
    process_param: list[str] | None = opt(None, "any field of the process's dataclass, e.g. beta_max=0.3 "
                                                "(repeatable)", action="append", metavar="FIELD=VALUE")
    prior: str | None = shared(og.PlanChoice, "prior")
    prior_run: str | None = from_config(TRAIN_CONFIG, "prior_run")
    diffusion_steps: int | None = opt(None, "diffusion steps N")
    beta_max: float | None = opt(None, "bridge: largest beta of the schedule")
    ot_ode: bool = opt(False, "bridge: noise-free marginal and sampler")
    consistent: bool = opt(False, "bridge: train on the marginals the sampling chain implies (exact at any N; I2SB's "
                                  "differ at small N)")
    dim: int | None = from_config("bridgeplan.nets.unet:UNetConfig", "dim")
    dim_mults: str | None = from_config("bridgeplan.nets.unet:UNetConfig", "dim_mults", metavar="M1,M2,...")
    grad_accum: int | None = from_config(TRAIN_CONFIG, "grad_accum")
    ema_decay: float | None = from_config(TRAIN_CONFIG, "ema_decay")
    ema_every: int | None = from_config(TRAIN_CONFIG, "ema_every")
    ema_start: int | None = from_config(TRAIN_CONFIG, "ema_start")
    hold_share: float | None = from_config(TRAIN_CONFIG, "hold_share")
    subgoal_every: int | None = from_config(TRAIN_CONFIG, "subgoal_every")
    precision: str | None = from_config(TRAIN_CONFIG, "precision")
    compile: bool | None = shared(_ec.EvalOptions, "compile", default=None)


def _add_train_commands(sub) -> None:
    add_command(sub, "train", TrainOptions, _cmd_train, TRAIN_CONFIG, ("training",),
                help="train a planner (DDPM, the I2SB bridge or flow matching)",
                description="Train a planner. Defaults come from --preset per maze (the training defaults shown are "
                            "--preset diffuser's; cpu-small's are smaller, per maze); flags override them.")
    add_command(sub, "train-prior", TrainCommon, _cmd_train_prior, "bridgeplan.config:PriorTrainConfig", ("training",),
                help="train the learned prior (MLP on start and goal)")


def _cmd_train(o: TrainOptions) -> int:
    from bridgeplan import config as cfg
    from bridgeplan.train import train

    c = o.common
    base = cfg.preset_config(c.environment.maze, c.preset)
    over = config_fields(o, cfg.TrainConfig, leave=("maze", "dataset", "preset", "process", "model"))
    process = _process_params(o, o.process or base.process.name)
    if o.process is not None:
        process["name"] = o.process
    model = {"dim": o.dim} if o.dim is not None else {}
    if o.dim_mults is not None:
        model["dim_mults"] = int_tuple(o.dim_mults, "--dim-mults")
    config = cfg.replace(base, dataset=_dataset_ref(c.dataset.dataset), process=process, model=model, **over)
    run_dir = Path(c.run.run_dir) if c.run.run_dir else Path(c.runs_root) / config.run_name()
    train(config, run_dir, resume=c.run.resume, progress=not c.progress.no_progress)
    print(f"run: {run_dir}")
    return 0


def _process_params(o: TrainOptions, name: str) -> dict:
    """The process fields given on the command line (checked by the process itself): ``--process-param``
    for any field, and shortcuts for the common ones."""
    from bridgeplan.processes import parse_process_params

    params = parse_process_params(name, o.process_param or [])
    if o.beta_max is not None:
        params["beta_max"] = o.beta_max
    if o.diffusion_steps is not None:
        params["steps"] = o.diffusion_steps
    if params.get("teacher"):  # a distillation's teacher run, found from anywhere (as the dataset is)
        params["teacher"] = _dataset_ref(params["teacher"])
    for flag in ("ot_ode", "consistent"):
        if getattr(o, flag):
            params[flag] = True
    return params


def _dataset_ref(dataset: str) -> str:
    """A dataset path made absolute (so a run finds it from anywhere); a Minari id stays as it is."""
    return str(Path(dataset).resolve()) if Path(dataset).exists() else dataset


def _cmd_train_prior(o: TrainCommon) -> int:
    from bridgeplan import config as cfg
    from bridgeplan.train import train_prior

    config = cfg.PriorTrainConfig(maze=o.environment.maze, dataset=_dataset_ref(o.dataset.dataset),
                                  **config_fields(o, cfg.PriorTrainConfig, leave=("maze", "dataset")))
    run_dir = Path(o.run.run_dir) if o.run.run_dir else Path(o.runs_root) / config.run_name()
    train_prior(config, run_dir, resume=o.run.resume, progress=not o.progress.no_progress)
    print(f"run: {run_dir}")
    return 0


def _add_eval_commands(sub) -> None:
    add_command(sub, "eval", _ec.EvalOptions, _ec.eval_run, description=_ec.EVAL_DESCRIPTION,
                help="evaluate a trained run (any environment family) on its environment's tasks")
    add_command(sub, "render", RenderOptions, _cmd_render,
                description="Maze2D: plans and executed states over the maze, one panel per episode; OGBench "
                            "manipulation: the first episode's start, middle and end in the simulator's camera. "
                            "Writes PNGs under RUN/render/ unless --out.",
                help="draw planned and executed trajectories (PNG), optionally a video")
    p = sub.add_parser("hierarchy", help="hierarchical planning: a coarse plan over the episode, refined by a low "
                                         "level (bridgeplan.hierarchy)")
    h = p.add_subparsers(dest="hierarchy_command", required=True)
    add_command(h, "eval", _ec.HierarchyEvalOptions, _ec.hierarchy_eval, description=_ec.HIERARCHY_DESCRIPTION,
                help="evaluate a high-level run and a low-level run (--subgoal-every) together, in any environment "
                     "family")
    add_command(sub, "graph", _ec.GraphOptions, _ec.graph_eval, description=_ec.GRAPH_DESCRIPTION,
                help="the dataset graph (the data's own states; no network, no map) on an environment's tasks, alone, "
                     "executed by a GCBC/GCIQL policy, or as a planner low level's high level")
    add_command(sub, "oracle", _ec.OracleOptions, _ec.oracle,
                help="the environment family's expert, noise-free, on its evaluation tasks (what the reports show "
                     "beside the planners)")


@dataclasses.dataclass(kw_only=True)
class RenderOptions:
    run: str = shared(_ec.EvalOptions, "run")
    episodes: int | None = shared(og.Tasks, "episodes", default=8)
    nfe: int | None = shared(_ec.EvalOptions, "nfe")
    seed: int = shared(og.Tasks, "seed")
    multi_task: bool = shared(og.Tasks, "multi_task")
    tasks: str | None = shared(og.Tasks, "tasks")
    out: str | None = shared(og.Output, "out")
    pairs: bool = opt(False, "also draw prior/target pairs from the training data")
    picture: og.Picture = group(og.Picture)
    device: og.Device = group(og.Device)
    replanning: og.Replanning = group(og.Replanning)
    plans: og.PlanChoice = group(og.PlanChoice)
    controller: og.Controller = group(og.Controller)
    threads: og.Threads = group(og.Threads)


def _cmd_render(o: RenderOptions) -> int:
    from bridgeplan.eval_commands import execution
    from bridgeplan.files import check_writable
    from bridgeplan.render import render_run

    plan = execution(o.replanning, o.controller, o.plans)
    if o.out:
        check_writable(o.out, "picture")
    positive("--size", o.picture.size)
    for path in render_run(Path(o.run), episodes=o.episodes, nfe=o.nfe, seed=o.seed, multi_task=o.multi_task,
                           task_ids=og.task_ids(o.tasks), out=o.out, pairs=o.pairs, video=o.picture.video,
                           size=o.picture.size, device=o.device.device, execution=plan):
        print(f"wrote {path}")
    return 0


@dataclasses.dataclass(kw_only=True)
class ReportOptions:
    results: str = opt("results", "the results folder (its store)")
    out: str | None = shared(og.Output, "out")
    csv: str | None = opt(None, "also export every result row to this CSV file")


def _add_report_command(sub) -> None:
    add_command(sub, "report", ReportOptions, _cmd_report, help="figures and a Markdown page from the results store",
                description="--out: the output directory (default RESULTS/report).")


def _cmd_report(o: ReportOptions) -> int:
    from bridgeplan.experiments.store import ResultsStore
    from bridgeplan.files import check_writable
    from bridgeplan.paths import report_dir, store_path
    from bridgeplan.report import write_report

    store = store_path(o.results)
    if not store.exists():
        raise BridgeplanError(f"no results store at {store}; run `bridgeplan study run` first")
    check_writable(o.out or report_dir(o.results), "report folder", folder=True)
    if o.csv:
        check_writable(o.csv, "CSV file")
    path = write_report(Path(o.results), Path(o.out) if o.out else None)
    print(f"wrote {path}")
    if o.csv:
        n = ResultsStore(store).export_csv(Path(o.csv))
        print(f"wrote {o.csv} ({n} rows)")
    return 0


@dataclasses.dataclass(kw_only=True)
class BenchOptions:
    out: str | None = shared(og.Output, "out", default="bench")
    presets: str | None = opt(None, "comma-separated presets to time")
    mazes: str | None = opt(None, "comma-separated Maze2D mazes whose plans (their preset's shape) the latency table "
                                  "times")
    batch_sizes: str | None = opt(None, "comma-separated plans per call")
    nfes: str | None = opt(None, "comma-separated network calls per plan (latency table)")
    methods: str | None = opt(None, "comma-separated methods of the latency and overhead tables, named as there "
                                    "(default: all)")
    repeats: int | None = opt(None, "timed repeats per latency figure")
    overhead_repeats: int | None = opt(None, "interleaved rounds per overhead ratio (0: skip them)")
    no_compile: bool = opt(False, "skip the torch.compile timings (minutes on a CPU)")
    frozen: bool = opt(False, "also time each method's plan through its network traced and frozen (`eval --frozen`), "
                              "a latency row each named '..., frozen'")
    eval_run: str | None = opt(None, "a trained run: also time 200 umaze episodes at NFE 1")
    budget_runs: str | None = opt(None, "comma-separated trained runs, a row each (one per method, at equal training "
                                        "steps): the score-per-budget table")
    budget_steps: str | None = opt(None, "comma-separated training steps: evaluate the budget runs' EMA snapshots "
                                         "there (default: their latest checkpoints)")
    budgets: str | None = opt(None, "comma-separated network-call budgets K")
    budget_episodes: int | None = opt(None, "episodes per evaluation of the budget table")
    busy_steps: int | None = opt(None, "training steps per rate of the busy-core figure (0: skip)")
    throughput_seconds: float | None = opt(None, "seconds of training per figure of the training-throughput table "
                                                 "(0: skip)")
    throughput_batch_sizes: str | None = opt(None, "comma-separated batches of the training-throughput table")
    side_by_side_seconds: float | None = opt(None, "seconds of training per figure of the two-jobs table (0: skip)")
    device: og.Device = group(og.Device, device=None)
    threads: og.Threads = group(og.Threads)


def _add_bench_command(sub) -> None:
    add_command(sub, "bench", BenchOptions, _cmd_bench,
                help="planning latency, overheads, torch.compile, evaluation throughput and score per planning budget "
                     "(JSON + Markdown)",
                description="Defaults: the fields of BenchConfig in bridgeplan/bench.py (cpu-small and diffuser "
                            "networks, umaze's plans, batches 1 and 64, NFE 1-15, budgets 1,2,4,8, 200 episodes). "
                            "--out: the output "
                            "directory (bench.json, bench.md).")


def _cmd_bench(o: BenchOptions) -> int:
    from bridgeplan.bench import BenchConfig, run_bench
    from bridgeplan.files import check_writable

    given = {"presets": o.presets and tuple(o.presets.split(",")), "mazes": o.mazes and tuple(o.mazes.split(",")),
             "methods": o.methods and tuple(o.methods.split(",")),
             "budget_runs": o.budget_runs and tuple(r for r in o.budget_runs.split(",") if r),
             "repeats": o.repeats, "overhead_repeats": o.overhead_repeats, "eval_run": o.eval_run,
             "budget_episodes": o.budget_episodes, "device": o.device.device, "busy_steps": o.busy_steps,
             "throughput_seconds": o.throughput_seconds, "side_by_side_seconds": o.side_by_side_seconds,
             "compile": False if o.no_compile else None, "frozen": o.frozen}
    for name in ("batch_sizes", "nfes", "budgets", "budget_steps", "throughput_batch_sizes"):
        text = getattr(o, name)
        given[name] = text and int_tuple(text, "--" + name.replace("_", "-"))
    bench = BenchConfig(**{k: v for k, v in given.items() if v is not None})
    check_writable(o.out, "bench folder", folder=True)
    path = run_bench(Path(o.out), bench, progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(path.read_text())
    return 0


@dataclasses.dataclass(kw_only=True)
class DemoOptions:
    environment: og.Environment = group(og.Environment, maze="umaze")
    out: str | None = shared(og.Output, "out", default="demo")
    dataset_steps: int = opt(200_000, "transitions generated")
    steps: int | None = shared(og.Training, "steps", default=1500)
    episodes: int | None = shared(og.Tasks, "episodes", default=100)
    seed: int | None = shared(og.Training, "seed", default=0)
    threads: og.Threads = group(og.Threads)


def _add_demo_command(sub) -> None:
    add_command(sub, "demo", DemoOptions, _cmd_demo,
                help="the main job on a small default: data, DDPM and bridge runs, eval, report",
                description="Generates a small dataset, trains a DDPM planner and a bridge from the straight line for "
                            "a few minutes on a CPU, scores both on the maze's test episodes at their full NFE and at "
                            "NFE 1, prints the scores and writes a report with figures. Resumable: run again, only "
                            "what is missing is done. --maze: umaze, medium or large; --out: the output folder "
                            "(ignored by git); --steps: per run; --episodes: test episodes per evaluation; --seed: "
                            "the runs' training seed.")


DEMO_READING = ("Reading: 100 is the expert, 0 a random policy. The bridge starts from the straight line to the goal, "
                "so a few minutes of training and one network call already plan; DDPM starts from noise: it needs "
                "its full NFE and more training than this (at NFE 1 it scores about as a random policy).")


def _cmd_demo(o: DemoOptions) -> int:
    """Data -> reference scores -> DDPM and bridge (line prior) runs -> evaluation -> a table and a report."""
    from bridgeplan.envs.maze2d.grids import get_maze
    from bridgeplan.envs.maze2d.reference import load_reference_returns
    from bridgeplan.experiments.grids import get_experiment
    from bridgeplan.experiments.runner import SweepSettings, run_sweep
    from bridgeplan.experiments.store import ResultsStore
    from bridgeplan.files import check_writable
    from bridgeplan.paths import store_path
    from bridgeplan.report import last_snapshot_table, write_report

    maze = get_maze(o.environment.maze).name
    for flag in ("--dataset-steps", "--steps", "--episodes"):
        positive(flag, getattr(o, flag[2:].replace("-", "_")))
    check_writable(o.out, "demo folder", folder=True)
    print(_reference_table({maze: load_reference_returns()[maze]}))
    demo = get_experiment("demo")  # studies/demo.toml runs the same grid: the README's expected range
    settings = SweepSettings(maze=maze, dataset_steps=o.dataset_steps, preset="cpu-small",
                             train_steps=o.steps, checkpoint_every=max(1, o.steps // 3),
                             episodes=o.episodes, seeds=(o.seed,), results_dir=o.out,
                             overrides={} if o.threads.threads is None else {"threads": o.threads.threads})
    added = run_sweep([demo], settings)
    report = write_report(Path(o.out))
    print(f"\n{last_snapshot_table(ResultsStore(store_path(o.out)), demo.name)}\n{DEMO_READING}")
    print(f"demo: {added} new results in {store_path(o.out)}; every snapshot and figure: {report}")
    return 0


def _add_gcbc_commands(sub) -> None:
    from bridgeplan.gcbc_commands import add_gcbc_commands

    add_gcbc_commands(sub)


def build_parser(*more: Callable[[argparse._SubParsersAction], None]) -> argparse.ArgumentParser:
    """The parser of these commands, and of the command groups that each of ``more`` adds to the subparsers."""
    parser = argparse.ArgumentParser(prog="bridgeplan", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True)
    for add in (_add_data_commands, _add_reference_commands, _add_train_commands, _add_eval_commands,
                _add_gcbc_commands, _add_report_command, _add_bench_command, _add_demo_command, *more):
        add(sub)
    return parser


def run(args: argparse.Namespace) -> int:
    """Run the parsed command: a user mistake is one ``error:`` line and exit 2, an interrupt exit 130."""
    one_line_warnings()
    try:
        from bridgeplan.device import configure_threads

        configure_threads(getattr(args, "threads", None) or 0)
        code = args.func(args)
        sys.stdout.flush()  # here, where a closed pipe is caught, not at exit
        return code
    except BridgeplanError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted (finished work and checkpoints are kept)", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader closed the pipe (`bridgeplan study list | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
