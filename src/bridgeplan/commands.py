"""The ``bridgeplan`` subcommands that make data, train, evaluate, draw and measure: everything a study's
evaluations run (through :func:`main`). :mod:`bridgeplan.cli` adds the commands that run studies and ship their
planners. Each subcommand maps its flags onto a module's function; user mistakes (BridgeplanError) print one
``error:`` line and exit 2."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

from bridgeplan import eval_commands as _ec
from bridgeplan.errors import BridgeplanError
from bridgeplan.options import add_command, group, int_tuple, opt, positive, shared

DESCRIPTION = "planning with diffusion models and bridges from informative priors, in Maze2D and OGBench pointmaze"


def _add_data_commands(sub) -> None:
    p = sub.add_parser("data", help="generate, inspect offline datasets (any environment family)")
    data = p.add_subparsers(dest="data_command", required=True)
    g = data.add_parser("generate", help="a dataset by the environment's family's recipe: Maze2D's noisy expert "
                                         "stream (Minari format, Minari's D4RL recipe), OGBench's (its npz format)")
    g.add_argument("--maze", required=True, help="the environment: open, umaze, medium or large; or an OGBench "
                                                 "dataset name (pointmaze-{medium,large,giant,teleport}-"
                                                 "{navigate,stitch}-v0)")
    g.add_argument("--steps", type=int, default=None, help="Maze2D: transitions (default 1 M)")
    g.add_argument("--piece-steps", type=int, default=None, metavar="N",
                   help="Maze2D: independent pieces of N steps, each from a random start, instead of one stream per "
                        "worker: a stitching dataset (as OGBench's stitch; default directory <maze>-<steps>-piecesN)")
    g.add_argument("--workers", type=int, default=1,
                   help="Maze2D: parallel processes, each generating its own independently seeded stream (default 1)")
    g.add_argument("--episodes", type=int, default=None, help="OGBench: training episodes (default: the recipe's)")
    g.add_argument("--episode-steps", type=int, default=None, help="OGBench: steps per episode (default: the "
                                                                   "recipe's)")
    g.add_argument("--seed", type=int, default=None, help="default 123 (Maze2D), 0 (OGBench, as its scripts)")
    g.add_argument("--out", default=None,
                   help="dataset directory (Maze2D; default datasets/<maze>-<steps>) or folder of NAME.npz and "
                        "NAME-val.npz (OGBench; default datasets/ogbench), under $BRIDGEPLAN_DATASETS when set")
    g.add_argument("--force", action="store_true", help="overwrite an existing dataset")
    g.add_argument("--no-progress", action="store_true")
    g.set_defaults(func=_cmd_data_generate)
    i = data.add_parser("info", help="check and summarize a dataset (Minari directory or id, D4RL maze2d hdf5, "
                                     "OGBench npz)")
    i.add_argument("path")
    i.add_argument("--maze", default=None, help="the environment it should be of (needed for an OGBench file; a "
                                                "Minari dataset names its maze)")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=_cmd_data_info)


def _cmd_data_generate(args) -> int:
    from bridgeplan.envs import family_of

    family = family_of(args.maze)
    for flag in ("steps", "workers", "episodes", "episode_steps"):
        if getattr(args, flag) is not None:
            positive("--" + flag.replace("_", "-"), getattr(args, flag))
    out = family.generate_dataset(args.maze, Path(args.out) if args.out else None,
                                  seed=family.data_seed if args.seed is None else args.seed,
                                  steps=args.steps, piece_steps=args.piece_steps, episodes=args.episodes,
                                  episode_steps=args.episode_steps, workers=args.workers, force=args.force,
                                  progress=not args.no_progress)
    print(family.dataset_info(str(out), args.maze)[1])
    print(f"wrote {out}")
    return 0


def _cmd_data_info(args) -> int:
    from bridgeplan.envs import family_of, family_of_dataset

    family = family_of(args.maze) if args.maze else family_of_dataset(args.path)
    info, text = family.dataset_info(args.path, args.maze)
    print(json.dumps(info, indent=2) if args.json else text)
    return 0


def _add_reference_commands(sub) -> None:
    p = sub.add_parser("reference", help="reference returns of the normalized score")
    ref = p.add_subparsers(dest="reference_command", required=True)
    s = ref.add_parser("show", help="the shipped reference returns")
    s.set_defaults(func=_cmd_reference_show)
    m = ref.add_parser("measure", help="measure them again in this environment")
    m.add_argument("--maze", default=None, help="one maze (default: all)")
    m.add_argument("--episodes", type=int, default=100)
    m.add_argument("--seed", type=int, default=123)
    m.add_argument("--out", default=None, help="also write the measured values to this JSON file")
    m.set_defaults(func=_cmd_reference_measure)


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


def _cmd_reference_measure(args) -> int:
    from bridgeplan.envs.maze2d.grids import MAZE_NAMES, get_maze
    from bridgeplan.envs.maze2d.reference import measure_reference_returns
    from bridgeplan.files import atomic_write_text, check_writable

    names = [get_maze(args.maze).name] if args.maze else list(MAZE_NAMES)
    positive("--episodes", args.episodes)
    if args.out:
        check_writable(args.out, "JSON file")
    measured = {n: measure_reference_returns(n, args.episodes, args.seed) for n in names}
    print(_reference_table(measured))
    if args.out:
        atomic_write_text(Path(args.out), json.dumps(measured, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


def _add_train_commands(sub) -> None:
    p = sub.add_parser("train", help="train a planner (DDPM, the I2SB bridge or flow matching)",
                       description="Train a planner. Defaults come from --preset per maze; flags override them.")
    _common_train_flags(p)
    p.add_argument("--preset", default="diffuser", help="diffuser (Diffuser's Maze2D settings) or cpu-small")
    p.add_argument("--process", default=None, help="ddpm, bridge or flow (default ddpm)")
    _process_param_flag(p)
    p.add_argument("--prior", default=None,
                   help="bridge prior: gaussian, line, learned or coarse (a low level's: the line through its "
                        "subgoals) (default gaussian)")
    p.add_argument("--prior-run", default=None, help="run directory of `bridgeplan train-prior` (learned prior)")
    p.add_argument("--diffusion-steps", type=int, default=None, help="diffusion steps N")
    p.add_argument("--beta-max", type=float, default=None, help="bridge: largest beta of the schedule")
    p.add_argument("--ot-ode", action="store_true", help="bridge: noise-free marginal and sampler")
    p.add_argument("--consistent", action="store_true",
                   help="bridge: train on the marginals the sampling chain implies (exact at any N; I2SB's "
                        "differ at small N)")
    p.add_argument("--dim", type=int, default=None, help="U-Net base width")
    p.add_argument("--dim-mults", default=None, help="U-Net channel multipliers, e.g. 1,4,8")
    p.add_argument("--grad-accum", type=int, default=None)
    p.add_argument("--ema-decay", type=float, default=None)
    p.add_argument("--ema-every", type=int, default=None)
    p.add_argument("--ema-start", type=int, default=None)
    _hold_share_flag(p)
    p.add_argument("--subgoal-every", type=int, default=None,
                   help="train a hierarchy's low level: every J-th planned state is a condition (a high level's "
                        "subgoals when planning; `bridgeplan hierarchy eval`)")
    p.add_argument("--precision", default=None,
                   help="bf16: forward and backward under bfloat16 autocast (refused where the device lacks it)")
    p.add_argument("--compile", action="store_true", default=None,
                   help="train through the torch.compile'd network (compiles at the first step)")
    p.set_defaults(func=_cmd_train)

    p = sub.add_parser("train-prior", help="train the learned prior (MLP on start and goal)")
    _common_train_flags(p)
    p.add_argument("--preset", default="diffuser",
                   help="the planner preset the prior serves: its horizon and stride are the defaults")
    p.set_defaults(func=_cmd_train_prior)


def _common_train_flags(p) -> None:
    p.add_argument("--maze", required=True, help="the environment: a Maze2D maze (umaze), an OGBench dataset name "
                                                 "(pointmaze-medium-navigate-v0) or your own's spec file (NAME.toml)")
    p.add_argument("--dataset", required=True, help="dataset directory (Minari), legacy D4RL hdf5 file or OGBench "
                                                    "npz file")
    p.add_argument("--run-dir", default=None, help="default: runs/<name derived from the config>")
    p.add_argument("--runs-root", default="runs")
    p.add_argument("--resume", action="store_true", help="continue the run in --run-dir")
    p.add_argument("--horizon", type=int, default=None, help="planned states (default: the preset's for the maze)")
    p.add_argument("--stride", type=int, default=None,
                   help="environment steps between planned states (default: the preset's for the maze)")
    p.add_argument("--steps", type=int, default=None, help="optimizer steps")
    p.add_argument("--minutes", type=float, default=None, help="wall-clock budget (stops at steps or minutes)")
    p.add_argument("--batch-size", type=int, default=None,
                   help="windows per gradient (default: the config's, for a planner its preset's for the maze)")
    p.add_argument("--lr", type=float, default=None, help="Adam's learning rate (default as --batch-size)")
    p.add_argument("--checkpoint-every", type=int, default=None)
    p.add_argument("--log-every", type=int, default=None)
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--device", default=None, help="auto (CUDA if present), cpu, cuda, ...")
    _threads_flag(p)
    p.add_argument("--no-progress", action="store_true")


def _process_param_flag(p) -> None:
    p.add_argument("--process-param", action="append", metavar="FIELD=VALUE",
                   help="any field of the process's dataclass, e.g. beta_max=0.3 (repeatable)")


def _hold_share_flag(p) -> None:
    p.add_argument("--hold-share", type=float, default=None,
                   help="share of training windows that arrive early and wait still at their end, so plans may "
                        "reach the goal before the horizon's end (default 0, Diffuser's)")


def _threads_flag(p) -> None:
    p.add_argument("--threads", type=int, default=None,
                   help="torch CPU threads (default: 1 on a CPU device, which keeps its speed when other "
                        "processes share the cores; more only warns beyond the machine's cores)")


def _overrides(args, names) -> dict:
    return {n: getattr(args, n) for n in names if getattr(args, n, None) is not None}


_COMMON = ("horizon", "stride", "steps", "minutes", "batch_size", "lr", "checkpoint_every", "log_every", "seed",
           "device", "threads")


def _cmd_train(args) -> int:
    from bridgeplan import config as cfg
    from bridgeplan.train import train

    base = cfg.preset_config(args.maze, args.preset)
    over = _overrides(args, _COMMON + ("prior", "prior_run", "grad_accum", "ema_decay", "ema_every", "ema_start",
                                       "hold_share", "precision", "compile", "subgoal_every"))
    process = _process_params(args, args.process or base.process.name)
    if args.process is not None:
        process["name"] = args.process
    model = {"dim": args.dim} if args.dim is not None else {}
    if args.dim_mults is not None:
        model["dim_mults"] = int_tuple(args.dim_mults, "--dim-mults")
    config = cfg.replace(base, dataset=_dataset_ref(args.dataset), process=process, model=model, **over)
    run_dir = Path(args.run_dir) if args.run_dir else Path(args.runs_root) / config.run_name()
    train(config, run_dir, resume=args.resume, progress=not args.no_progress)
    print(f"run: {run_dir}")
    return 0


def _process_params(args, name: str) -> dict:
    """The process fields given on the command line (checked by the process itself): ``--process-param``
    for any field, and shortcuts for the common ones."""
    from bridgeplan.processes import parse_process_params

    params = parse_process_params(name, args.process_param or [])
    params |= _overrides(args, ("beta_max",))
    if args.diffusion_steps is not None:
        params["steps"] = args.diffusion_steps
    if params.get("teacher"):  # a distillation's teacher run, found from anywhere (as the dataset is)
        params["teacher"] = _dataset_ref(params["teacher"])
    for flag in ("ot_ode", "consistent"):
        if getattr(args, flag):
            params[flag] = True
    return params


def _dataset_ref(dataset: str) -> str:
    """A dataset path made absolute (so a run finds it from anywhere); a Minari id stays as it is."""
    return str(Path(dataset).resolve()) if Path(dataset).exists() else dataset


def _cmd_train_prior(args) -> int:
    from bridgeplan import config as cfg
    from bridgeplan.train import train_prior

    config = cfg.PriorTrainConfig(maze=args.maze, dataset=_dataset_ref(args.dataset),
                                  **_overrides(args, _COMMON + ("preset",)))
    run_dir = Path(args.run_dir) if args.run_dir else Path(args.runs_root) / config.run_name()
    train_prior(config, run_dir, resume=args.resume, progress=not args.no_progress)
    print(f"run: {run_dir}")
    return 0


def _add_eval_commands(sub) -> None:
    add_command(sub, "eval", _ec.EvalOptions, _ec.eval_run, description=_ec.EVAL_DESCRIPTION,
                help="evaluate a trained run (any environment family) on its environment's tasks")
    add_command(sub, "render", RenderOptions, _cmd_render, description="Writes PNGs under RUN/render/ unless --out.",
                help="draw planned and executed trajectories (PNG), optionally a video")
    p = sub.add_parser("hierarchy", help="hierarchical planning: a coarse plan over the episode, refined by a low "
                                         "level (bridgeplan.hierarchy)")
    h = p.add_subparsers(dest="hierarchy_command", required=True)
    add_command(h, "eval", _ec.HierarchyEvalOptions, _ec.hierarchy_eval, description=_ec.HIERARCHY_DESCRIPTION,
                help="evaluate a high-level run and a low-level run (--subgoal-every) together, in any environment "
                     "family")
    add_command(sub, "graph", _ec.GraphOptions, _ec.graph_eval, description=_ec.GRAPH_DESCRIPTION,
                help="the dataset graph (the data's own states; no network, no map) on an environment's tasks, alone "
                     "or as a low level's high level")
    add_command(sub, "oracle", _ec.OracleOptions, _ec.oracle,
                help="the environment family's expert, noise-free, on its evaluation tasks (what the reports show "
                     "beside the planners)")


@dataclasses.dataclass(kw_only=True)
class RenderOptions:
    run: str = opt(help="run directory (or a checkpoint/snapshot file), or a shipped planner's name")
    episodes: int | None = shared(_ec.Tasks, "episodes", default=8)
    nfe: int | None = shared(_ec.EvalOptions, "nfe")
    seed: int = shared(_ec.Tasks, "seed")
    multi_task: bool = shared(_ec.Tasks, "multi_task")
    out: str | None = shared(_ec.Output, "out")
    pairs: bool = opt(False, "also draw prior/target pairs from the training data")
    video: bool = opt(False, "also write an animated GIF of the first episode (MuJoCo)")
    device: _ec.Device = group(_ec.Device)
    replanning: _ec.Replanning = group(_ec.Replanning)
    plans: _ec.PlanChoice = group(_ec.PlanChoice)
    controller: _ec.Controller = group(_ec.Controller)
    threads: _ec.Threads = group(_ec.Threads)


def _cmd_render(o: RenderOptions) -> int:
    from bridgeplan.eval_commands import execution
    from bridgeplan.files import check_writable
    from bridgeplan.render import render_run

    plan = execution(o.replanning, o.controller, o.plans)
    if o.out:
        check_writable(o.out, "picture")
    for path in render_run(Path(o.run), episodes=o.episodes, nfe=o.nfe, seed=o.seed, multi_task=o.multi_task,
                           out=o.out, pairs=o.pairs, video=o.video, device=o.device.device, execution=plan):
        print(f"wrote {path}")
    return 0


def _add_report_command(sub) -> None:
    p = sub.add_parser("report", help="figures and a Markdown page from the results store")
    p.add_argument("--results", default="results")
    p.add_argument("--out", default=None, help="output directory (default RESULTS/report)")
    p.add_argument("--csv", default=None, help="also export every result row to this CSV file")
    p.set_defaults(func=_cmd_report)


def _cmd_report(args) -> int:
    from bridgeplan.experiments.store import ResultsStore
    from bridgeplan.files import check_writable
    from bridgeplan.paths import report_dir, store_path
    from bridgeplan.report import write_report

    store = store_path(args.results)
    if not store.exists():
        raise BridgeplanError(f"no results store at {store}; run `bridgeplan study run` first")
    check_writable(args.out or report_dir(args.results), "report folder", folder=True)
    if args.csv:
        check_writable(args.csv, "CSV file")
    path = write_report(Path(args.results), Path(args.out) if args.out else None)
    print(f"wrote {path}")
    if args.csv:
        n = ResultsStore(store).export_csv(Path(args.csv))
        print(f"wrote {args.csv} ({n} rows)")
    return 0


def _add_bench_command(sub) -> None:
    p = sub.add_parser("bench", help="planning latency, overheads, torch.compile, evaluation throughput and score "
                                     "per planning budget (JSON + Markdown)",
                       description="Defaults: the fields of BenchConfig in bridgeplan/bench.py (cpu-small and "
                                   "diffuser networks, batches 1 and 64, NFE 1-15, budgets 1,2,4,8, 200 episodes).")
    p.add_argument("--out", default="bench", help="output directory (bench.json, bench.md)")
    p.add_argument("--presets", help="comma-separated presets to time")
    p.add_argument("--batch-sizes", help="comma-separated plans per call")
    p.add_argument("--nfes", help="comma-separated network calls per plan (latency table)")
    p.add_argument("--methods", help="comma-separated methods of the latency and overhead tables, named as there "
                                     "(default: all)")
    p.add_argument("--repeats", type=int, help="timed repeats per latency figure")
    p.add_argument("--overhead-repeats", type=int, help="interleaved rounds per overhead ratio (0: skip them)")
    p.add_argument("--no-compile", action="store_true", help="skip the torch.compile timings (minutes on a CPU)")
    p.add_argument("--eval-run", help="a trained run: also time 200 umaze episodes at NFE 1")
    p.add_argument("--budget-runs", help="comma-separated trained runs, a row each (one per method, at equal "
                                         "training steps): the score-per-budget table")
    p.add_argument("--budget-steps", help="comma-separated training steps: evaluate the budget runs' EMA "
                                          "snapshots there (default: their latest checkpoints)")
    p.add_argument("--budgets", help="comma-separated network-call budgets K")
    p.add_argument("--budget-episodes", type=int, help="episodes per evaluation of the budget table")
    p.add_argument("--busy-steps", type=int, help="training steps per rate of the busy-core figure (0: skip)")
    p.add_argument("--throughput-seconds", type=float,
                   help="seconds of training per figure of the training-throughput table (0: skip)")
    p.add_argument("--throughput-batch-sizes", help="comma-separated batches of the training-throughput table")
    p.add_argument("--side-by-side-seconds", type=float,
                   help="seconds of training per figure of the two-jobs table (0: skip)")
    p.add_argument("--device", help="auto (CUDA if present), cpu, cuda, ...")
    _threads_flag(p)
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(args) -> int:
    from bridgeplan.bench import BenchConfig, run_bench
    from bridgeplan.files import check_writable

    given = {"presets": args.presets and tuple(args.presets.split(",")),
             "methods": args.methods and tuple(args.methods.split(",")),
             "budget_runs": args.budget_runs and tuple(r for r in args.budget_runs.split(",") if r),
             "repeats": args.repeats, "overhead_repeats": args.overhead_repeats, "eval_run": args.eval_run,
             "budget_episodes": args.budget_episodes, "device": args.device, "busy_steps": args.busy_steps,
             "throughput_seconds": args.throughput_seconds, "side_by_side_seconds": args.side_by_side_seconds,
             "compile": False if args.no_compile else None}
    for name in ("batch_sizes", "nfes", "budgets", "budget_steps", "throughput_batch_sizes"):
        text = getattr(args, name)
        given[name] = text and int_tuple(text, "--" + name.replace("_", "-"))
    bench = BenchConfig(**{k: v for k, v in given.items() if v is not None})
    check_writable(args.out, "bench folder", folder=True)
    path = run_bench(Path(args.out), bench, progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(path.read_text())
    return 0


def _add_demo_command(sub) -> None:
    p = sub.add_parser("demo", help="the main job on a small default: data, DDPM and bridge runs, eval, report",
                       description="Generates a small dataset, trains a DDPM planner and a bridge from the straight "
                                   "line for a few minutes on a CPU, scores both on the maze's test episodes at "
                                   "their full NFE and at NFE 1, prints the scores and writes a report with "
                                   "figures. Resumable: run again, only what is missing is done.")
    p.add_argument("--maze", default="umaze", help="umaze (default), medium or large")
    p.add_argument("--out", default="demo", help="output folder (default demo/, ignored by git)")
    p.add_argument("--dataset-steps", type=int, default=200_000, help="transitions generated (default 200 000)")
    p.add_argument("--steps", type=int, default=1500, help="optimizer steps per run (default 1500)")
    p.add_argument("--episodes", type=int, default=100, help="test episodes per evaluation (default 100)")
    p.add_argument("--seed", type=int, default=0, help="the runs' training seed (default 0)")
    _threads_flag(p)
    p.set_defaults(func=_cmd_demo)


DEMO_READING = ("Reading: 100 is the expert, 0 a random policy. The bridge starts from the straight line to the goal, "
                "so a few minutes of training and one network call already plan; DDPM starts from noise: it needs "
                "its full NFE and more training than this (at NFE 1 it scores about as a random policy).")


def _cmd_demo(args) -> int:
    """Data -> reference scores -> DDPM and bridge (line prior) runs -> evaluation -> a table and a report."""
    from bridgeplan.envs.maze2d.grids import get_maze
    from bridgeplan.envs.maze2d.reference import load_reference_returns
    from bridgeplan.experiments.grids import get_experiment
    from bridgeplan.experiments.runner import SweepSettings, run_sweep
    from bridgeplan.experiments.store import ResultsStore
    from bridgeplan.files import check_writable
    from bridgeplan.paths import store_path
    from bridgeplan.report import last_snapshot_table, write_report

    maze = get_maze(args.maze).name
    for flag in ("--dataset-steps", "--steps", "--episodes"):
        positive(flag, getattr(args, flag[2:].replace("-", "_")))
    check_writable(args.out, "demo folder", folder=True)
    print(_reference_table({maze: load_reference_returns()[maze]}))
    demo = get_experiment("demo")  # studies/demo.toml runs the same grid: the README's expected range
    settings = SweepSettings(maze=maze, dataset_steps=args.dataset_steps, preset="cpu-small",
                             train_steps=args.steps, checkpoint_every=max(1, args.steps // 3),
                             episodes=args.episodes, seeds=(args.seed,), results_dir=args.out,
                             overrides=_overrides(args, ("threads",)))
    added = run_sweep([demo], settings)
    report = write_report(Path(args.out))
    print(f"\n{last_snapshot_table(ResultsStore(store_path(args.out)), demo.name)}\n{DEMO_READING}")
    print(f"demo: {added} new results in {store_path(args.out)}; every snapshot and figure: {report}")
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


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


def run(args: argparse.Namespace) -> int:
    """Run the parsed command: a user mistake is one ``error:`` line and exit 2, an interrupt exit 130."""
    warnings.filterwarnings("ignore", module="gymnasium_robotics")
    warnings.formatwarning = _one_line_warning
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


def main(argv: list[str] | None = None) -> int:
    """``bridgeplan`` restricted to these commands (what a study runs)."""
    return run(build_parser().parse_args(argv))
