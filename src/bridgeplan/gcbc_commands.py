"""The ``bridgeplan gcbc train`` and ``gcbc eval`` commands (torch is imported only when one runs)."""

from __future__ import annotations

import json
from pathlib import Path

from bridgeplan.errors import BridgeplanError


def add_gcbc_commands(sub) -> None:
    """The ``bridgeplan gcbc`` group: ``train`` and ``eval``."""
    p = sub.add_parser("gcbc", help="goal-conditioned behaviour cloning, OGBench's baseline on its own data")
    og = p.add_subparsers(dest="gcbc_command", required=True)
    t = og.add_parser("train", help="goal-conditioned behaviour cloning (OGBench's GCBC baseline)",
                      description="Defaults: OGBench's GCBC for pointmaze (GCBCConfig in bridgeplan/gcbc.py): "
                                  "lr 3e-4, batch 1024, MLP 512x3, future-state goals, 1M steps.")
    t.add_argument("dataset", help="training npz in OGBench's format")
    t.add_argument("--run-dir", required=True)
    t.add_argument("--maze", help="the OGBench dataset the data is of (pointmaze-medium-navigate-v0, cube-single-play-"
                                  "v0, or a bare pointmaze maze; checked; evaluation's default)")
    for name, kind in (("steps", int), ("minutes", float), ("batch-size", int), ("lr", float), ("seed", int),
                       ("p-curgoal", float), ("p-trajgoal", float), ("p-randomgoal", float), ("discount", float),
                       ("checkpoint-every", int), ("log-every", int), ("threads", int), ("alpha", float),
                       ("expectile", float), ("tau", float)):
        t.add_argument(f"--{name}", type=kind)
    t.add_argument("--hidden-dims", help="comma-separated widths (default 512,512,512)")
    t.add_argument("--agent", help="gcbc (default) or gciql (a value and critics, the policy their actor; --alpha, "
                                   "--expectile, --tau are its)")
    t.add_argument("--geom-sample", action="store_true", help="future goals at geometric offsets")
    t.add_argument("--device", help="auto (CUDA if present), cpu, cuda, ...")
    t.add_argument("--resume", action="store_true")
    t.add_argument("--no-progress", action="store_true")
    t.set_defaults(func=_cmd_gcbc_train)
    e = og.add_parser("eval", help="a GCBC run's snapshots on OGBench's 5-task evaluation protocol (one snapshot on "
                                   "any tasks, validation's too: `bridgeplan eval RUN --tasks 6,7,8,9,10`)")
    e.add_argument("run", help="a `gcbc train` run directory")
    e.add_argument("--maze", help="default: the environment the run was trained with")
    e.add_argument("--steps", help="comma-separated snapshot steps, or 'all' (default: the latest checkpoint)")
    e.add_argument("--episodes", type=int, default=0, help="episodes per task (default 50, as OGBench)")
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--json", action="store_true")
    e.add_argument("--out", default=None, help="also write the JSON to this path (one step only)")
    e.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: 1 on a CPU device)")
    e.add_argument("--no-progress", action="store_true")
    e.set_defaults(func=_cmd_gcbc_eval)


def _cmd_gcbc_train(args) -> int:
    from bridgeplan.checkpoint import load_checkpoint
    from bridgeplan.gcbc import GCBCConfig, train_gcbc
    from bridgeplan.paths import checkpoint_path

    given = {f: getattr(args, f) for f in ("maze", "steps", "minutes", "batch_size", "lr", "seed", "p_curgoal",
                                           "p_trajgoal", "p_randomgoal", "discount", "checkpoint_every",
                                           "log_every", "threads", "device", "agent", "alpha", "expectile",
                                           "tau")}
    given = {k: v for k, v in given.items() if v is not None}
    if args.hidden_dims:
        try:
            given["hidden_dims"] = tuple(int(v) for v in args.hidden_dims.split(","))
        except ValueError:
            raise BridgeplanError(f"--hidden-dims takes comma-separated integers, got {args.hidden_dims!r}") from None
    if args.geom_sample:
        given["geom_sample"] = True
    run = train_gcbc(GCBCConfig(dataset=args.dataset, **given), Path(args.run_dir), resume=args.resume,
                     progress=not args.no_progress)
    print(f"trained {run} (step {load_checkpoint(checkpoint_path(run))['step']})")
    return 0


def _cmd_gcbc_eval(args) -> int:
    from bridgeplan.gcbc import evaluate_gcbc, policy_snapshots

    steps = None
    if args.steps == "all":
        steps = [s for s, _ in policy_snapshots(args.run)]
    elif args.steps:
        try:
            steps = [int(v) for v in args.steps.split(",")]
        except ValueError:
            raise BridgeplanError(f"--steps takes comma-separated integers or 'all', got {args.steps!r}") from None
    if args.out and (steps is None or len(steps) != 1):
        raise BridgeplanError("--out takes one evaluation: give one snapshot with --steps N")
    if args.out:
        from bridgeplan.files import check_writable

        check_writable(args.out, "JSON file")
    if args.threads is not None:
        from bridgeplan.device import configure_threads

        configure_threads(args.threads)
    rows = evaluate_gcbc(args.run, args.maze or "", steps, args.episodes, args.seed, progress=not args.no_progress)
    for row in rows:
        text = row.pop("text")
        print(json.dumps(row, indent=2) if args.json else f"step {row['step']}: {text}")
    if args.out:
        from bridgeplan.files import atomic_write_text

        atomic_write_text(Path(args.out), json.dumps(rows[0], indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0
