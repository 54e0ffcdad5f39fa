"""The ``bridgeplan ogbench`` subcommands (wired into :mod:`bridgeplan.commands` by :func:`add_ogbench_commands`)."""

from __future__ import annotations

import json
from pathlib import Path

from bridgeplan.errors import BridgeplanError


def default_out_dir() -> Path:
    """``$BRIDGEPLAN_DATASETS/ogbench`` when set, else ``datasets/ogbench``."""
    from bridgeplan.layout import datasets_root

    return datasets_root() / "ogbench"


def add_ogbench_commands(sub) -> None:
    p = sub.add_parser("ogbench", help="OGBench pointmaze: generate datasets, check files, evaluation protocol")
    og = p.add_subparsers(dest="ogbench_command", required=True)
    g = og.add_parser("generate", help="a dataset in OGBench's recipe: NAME.npz and NAME-val.npz")
    g.add_argument("name", help="pointmaze-{medium,large,giant,teleport}-{navigate,stitch}-v0")
    g.add_argument("--out", default=None, help="directory (default datasets/ogbench, or $BRIDGEPLAN_DATASETS/ogbench)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--episodes", type=int, default=None, help="training episodes (default: the recipe's)")
    g.add_argument("--steps", type=int, default=None, help="steps per episode (default: the recipe's)")
    g.add_argument("--force", action="store_true", help="overwrite existing files (else an existing one is an error)")
    g.add_argument("--no-progress", action="store_true")
    g.set_defaults(func=_cmd_generate)
    i = og.add_parser("info", help="check a dataset file (ours or an official one) and summarize it")
    i.add_argument("path")
    i.add_argument("--maze", required=True, help="the maze or dataset name the file should be of")
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=_cmd_info)
    e = og.add_parser("evaluate-oracle", help="the noise-free oracle policy on the 5-task evaluation protocol")
    e.add_argument("maze", help="medium, large, giant or teleport")
    e.add_argument("--episodes", type=int, default=None, help="episodes per task (default 50, as OGBench)")
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--tasks", default=None, help="comma-separated task ids (default 1,2,3,4,5)")
    e.add_argument("--json", action="store_true")
    e.add_argument("--out", default=None, help="also write the JSON to this path")
    e.add_argument("--threads", type=int, default=None, help="accepted for the study runner; the oracle uses none")
    e.add_argument("--no-progress", action="store_true")
    e.set_defaults(func=_cmd_evaluate_oracle)
    _add_eval_command(og)
    from bridgeplan.gcbc_commands import add_gcbc_commands  # gcbc-train, gcbc-eval

    add_gcbc_commands(og)


def _cmd_generate(args) -> int:
    from bridgeplan.envs.ogbench_pointmaze.generate import generate_dataset
    from bridgeplan.envs.ogbench_pointmaze.reading import check_dataset

    g = generate_dataset(args.name, args.out or default_out_dir(), seed=args.seed, episodes=args.episodes,
                         episode_steps=args.steps, force=args.force, progress=not args.no_progress)
    for path in (g.train_path, g.val_path):
        print(check_dataset(path, args.name).summary())
    print(f"{g.steps} steps in {g.seconds:.1f} s ({g.steps / g.seconds:.0f} steps/s)")
    return 0


def _cmd_info(args) -> int:
    from dataclasses import asdict

    from bridgeplan.envs.ogbench_pointmaze.reading import check_dataset

    c = check_dataset(args.path, args.maze)
    print(json.dumps(asdict(c), indent=2) if args.json else c.summary())
    return 0


def _cmd_evaluate_oracle(args) -> int:
    from bridgeplan.envs.ogbench_pointmaze.protocol import EVAL_EPISODES_PER_TASK, evaluate_policy, oracle_policy
    from bridgeplan.files import code_version

    tasks = None
    if args.tasks is not None:
        try:
            tasks = [int(t) for t in args.tasks.split(",")]
        except ValueError:
            raise BridgeplanError(f"--tasks takes comma-separated integers, got {args.tasks!r}") from None
    r = evaluate_policy(args.maze, oracle_policy(args.maze),
                        episodes_per_task=args.episodes or EVAL_EPISODES_PER_TASK, seed=args.seed,
                        task_ids=tasks, progress=not args.no_progress)
    text = json.dumps({**r.to_dict(), "policy": "oracle", "code_version": code_version()}, indent=2)
    print(text if args.json else r.format())
    if args.out:
        from bridgeplan.files import atomic_write_text

        atomic_write_text(Path(args.out), text + "\n")
        print(f"wrote {args.out}")
    return 0


def _task_ids(text: str | None) -> list[int] | None:
    if text is None:
        return None
    try:
        return [int(t) for t in text.split(",")]
    except ValueError:
        raise BridgeplanError(f"--tasks takes comma-separated integers, got {text!r}") from None


def _add_eval_command(og) -> None:
    p = og.add_parser("eval", help="a trained planner (bridgeplan train on an OGBench dataset) on the 5-task protocol")
    p.add_argument("run", help="run directory (or a checkpoint/snapshot file)")
    p.add_argument("--nfe", type=int, default=None, help="network calls per plan (default: the full count)")
    p.add_argument("--snapshot", type=int, default=None, help="evaluate the EMA snapshot of this training step")
    _protocol_flags(p, "plan again from the current position every K steps (default: open loop)")
    p.set_defaults(func=_cmd_eval)
    h = og.add_parser("hierarchy-eval", help="two runs as a hierarchy (a coarse plan, a low level through it) on the "
                                             "5-task protocol")
    h.add_argument("high", help="the high level's run directory (a long --stride)")
    h.add_argument("low", help="the low level's run directory (trained with --subgoal-every J; J x its stride = "
                               "the high level's stride)")
    h.add_argument("--nfe-high", type=int, default=None, help="network calls per coarse plan (default: all)")
    h.add_argument("--nfe-low", type=int, default=None, help="network calls per low-level plan (default: all)")
    h.add_argument("--replan-high-every", type=int, default=None, metavar="K",
                   help="plan the coarse plan again from the current position every K steps (default: once)")
    _protocol_flags(h, "plan the low level again every K steps (required: one high-level step is the natural K)")
    h.set_defaults(func=_cmd_hierarchy_eval)
    from bridgeplan.graph import DEFAULTS, add_graph_flags

    g = og.add_parser("graph-eval", help="the dataset's own states as a graph (no network, no map): its shortest "
                                         "paths executed on the 5-task protocol, the floor of stitching")
    g.add_argument("name", help="the dataset's name (pointmaze-large-stitch-v0)")
    g.add_argument("--dataset", default=None,
                   help="its .npz (default: NAME.npz where `ogbench generate` writes, datasets/ogbench)")
    add_graph_flags(g, DEFAULTS)
    g.add_argument("--low", default=None, metavar="RUN",
                   help="a low level (trained with --subgoal-every J) that plans through the graph's path, one "
                        "state every J x its stride steps, from its next states (default: the path alone)")
    g.add_argument("--nfe-low", type=int, default=None, help="network calls per low-level plan (default: all)")
    g.add_argument("--replan-high-every", type=int, default=None, metavar="K",
                   help="with --low: search the graph again from the current position every K steps (default: once)")
    _protocol_flags(g, "plan again from the current position every K steps (default: open loop)")
    g.set_defaults(func=_cmd_graph_eval)


def _protocol_flags(p, replan_help: str) -> None:
    """The flags ``eval`` and ``hierarchy-eval`` share: the protocol's episodes and tasks, the execution, output."""
    p.add_argument("--episodes-per-task", type=int, default=None, help="default 50, as OGBench")
    p.add_argument("--controller", default="track",
                   help="track (the plan's next state at each step; default) or pursuit (the plan's path at the "
                        "expert's pace, toward the first planned position --lookahead away)")
    p.add_argument("--lookahead", type=float, default=None, metavar="R",
                   help="pursuit: distance to the planned position stepped toward (default 2.0, half a cell)")
    p.add_argument("--replan-every", type=int, default=None, metavar="K", help=replan_help)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tasks", default=None, help="comma-separated task ids (default 1,2,3,4,5)")
    p.add_argument("--device", default="auto")
    p.add_argument("--out", default=None, help="JSON path (default RUN/eval/ogbench-<settings>.json; graph-eval: "
                                               "results/graph/NAME/ogbench-graph-<settings>.json)")
    p.add_argument("--json", action="store_true", help="print the JSON to stdout instead of the table")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: 1 on a CPU device)")
    p.add_argument("--no-floor", action="store_true",
                   help="skip the floor (the same episodes from the straight line, no network)")
    p.add_argument("--no-progress", action="store_true")


def _execution(args):
    from bridgeplan.envs.ogbench_pointmaze.planning import PointExecution
    from bridgeplan.envs.ogbench_pointmaze.protocol import EVAL_EPISODES_PER_TASK

    if args.lookahead is not None and args.controller != "pursuit":
        raise BridgeplanError("--lookahead is the pursuit controller's: give --controller pursuit")
    execution = PointExecution(args.controller, replan_every=args.replan_every,
                               **({} if args.lookahead is None else {"lookahead": args.lookahead}))
    return execution, EVAL_EPISODES_PER_TASK if args.episodes_per_task is None else args.episodes_per_task


def _run_eval_dir(run: Path) -> Path:
    from bridgeplan.layout import eval_dir
    from bridgeplan.runs import run_dir_of

    return eval_dir(run_dir_of(run))


def _write(result: dict, args, out_dir: Path, prefix: str, suffix: str) -> int:
    """Write ``result`` to ``--out``, else into ``out_dir`` named by its settings; print it."""
    from bridgeplan.envs.ogbench_pointmaze.planning import format_result
    from bridgeplan.evaluate import write_and_show

    tasks = "" if args.tasks is None else "-tasks" + args.tasks.replace(",", "")
    out = Path(args.out) if args.out else out_dir / f"{prefix}-seed{args.seed}{tasks}-{suffix}.json"
    write_and_show(result, out, args.json, format_result(result))
    return 0


def _cmd_eval(args) -> int:
    from bridgeplan.envs.ogbench_pointmaze.planning import evaluate_run

    execution, episodes = _execution(args)
    result = evaluate_run(Path(args.run), nfe=args.nfe, execution=execution, episodes_per_task=episodes,
                          seed=args.seed, task_ids=_task_ids(args.tasks), device=args.device,
                          snapshot=args.snapshot, progress=not args.no_progress,
                          floor=not args.no_floor)
    prefix = f"ogbench-step{result['step']}-nfe{result['nfe']}-ep{episodes}"
    return _write(result, args, _run_eval_dir(Path(args.run)), prefix, execution.tag())


def _cmd_hierarchy_eval(args) -> int:
    from bridgeplan.envs.ogbench_pointmaze.planning import evaluate_hierarchy_run

    execution, episodes = _execution(args)
    result = evaluate_hierarchy_run(Path(args.high), Path(args.low), args.nfe_high, args.nfe_low, execution,
                                    args.replan_high_every, episodes, args.seed, _task_ids(args.tasks), args.device,
                                    progress=not args.no_progress, floor=not args.no_floor)
    high = "" if args.replan_high_every is None else f"-high{args.replan_high_every}"
    prefix = f"ogbench-hierarchy-nfe{result['high']['nfe']}-{result['nfe']}-ep{episodes}"
    return _write(result, args, _run_eval_dir(Path(args.low)), prefix, execution.tag() + high)


def _cmd_graph_eval(args) -> int:
    from bridgeplan.envs.ogbench_pointmaze.names import parse_dataset_name
    from bridgeplan.envs.ogbench_pointmaze.planning import evaluate_graph
    from bridgeplan.graph import graph_settings

    parse_dataset_name(args.name)
    dataset = Path(args.dataset) if args.dataset else default_out_dir() / f"{args.name}.npz"
    if not dataset.exists():
        raise BridgeplanError(f"no dataset file {dataset}: give --dataset FILE, or make it with `bridgeplan ogbench "
                              f"generate {args.name}`")
    execution, episodes = _execution(args)
    result = evaluate_graph(args.name, dataset, graph_settings(args), execution, episodes, args.seed,
                            _task_ids(args.tasks),
                            progress=not args.no_progress, low_run=Path(args.low) if args.low else None,
                            nfe_low=args.nfe_low, replan_high_every=args.replan_high_every, device=args.device)
    prefix = f"ogbench-graph-keep{args.keep}-r{args.radius:g}-ep{episodes}"
    if args.low:
        high = "" if args.replan_high_every is None else f"-high{args.replan_high_every}"
        return _write(result, args, _run_eval_dir(Path(args.low)), f"{prefix}-nfe{result['nfe']}",
                      execution.tag() + high)
    return _write(result, args, Path("results") / "graph" / args.name, prefix, execution.tag())
