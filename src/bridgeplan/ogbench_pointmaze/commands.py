"""The ``bridgeplan ogbench`` subcommands (wired into :mod:`bridgeplan.cli` by :func:`add_ogbench_commands`)."""

from __future__ import annotations

import json
import os
from pathlib import Path

from bridgeplan.errors import BridgeplanError


def default_out_dir() -> Path:
    """``$BRIDGEPLAN_DATASETS/ogbench`` when set, else ``datasets/ogbench``."""
    from bridgeplan.data.datasets import DATASETS_ENV

    return Path(os.environ.get(DATASETS_ENV) or "datasets") / "ogbench"


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
    e.add_argument("--no-progress", action="store_true")
    e.set_defaults(func=_cmd_evaluate_oracle)
    from bridgeplan.gcbc_commands import add_gcbc_commands  # gcbc-train, gcbc-eval

    add_gcbc_commands(og)


def _cmd_generate(args) -> int:
    from bridgeplan.ogbench_pointmaze.generate import generate_dataset
    from bridgeplan.ogbench_pointmaze.reading import check_dataset

    g = generate_dataset(args.name, args.out or default_out_dir(), seed=args.seed, episodes=args.episodes,
                         episode_steps=args.steps, force=args.force, progress=not args.no_progress)
    for path in (g.train_path, g.val_path):
        print(check_dataset(path, args.name).summary())
    print(f"{g.steps} steps in {g.seconds:.1f} s ({g.steps / g.seconds:.0f} steps/s)")
    return 0


def _cmd_info(args) -> int:
    from dataclasses import asdict

    from bridgeplan.ogbench_pointmaze.reading import check_dataset

    c = check_dataset(args.path, args.maze)
    print(json.dumps(asdict(c), indent=2) if args.json else c.summary())
    return 0


def _cmd_evaluate_oracle(args) -> int:
    from bridgeplan.files import code_version
    from bridgeplan.ogbench_pointmaze.protocol import EVAL_EPISODES_PER_TASK, evaluate_policy, oracle_policy

    tasks = None
    if args.tasks is not None:
        try:
            tasks = [int(t) for t in args.tasks.split(",")]
        except ValueError:
            raise BridgeplanError(f"--tasks takes comma-separated integers, got {args.tasks!r}") from None
    r = evaluate_policy(args.maze, oracle_policy(args.maze),
                        episodes_per_task=args.episodes or EVAL_EPISODES_PER_TASK, seed=args.seed,
                        task_ids=tasks, progress=not args.no_progress)
    print(json.dumps({**r.to_dict(), "policy": "oracle", "code_version": code_version()}, indent=2) if args.json
          else r.format())
    return 0
