"""The ``bridgeplan gcbc train`` and ``gcbc eval`` commands (torch is imported only when one runs)."""

from __future__ import annotations

from pathlib import Path

from bridgeplan.errors import BridgeplanError
from bridgeplan.eval_commands import GCBC_EVAL_DESCRIPTION, GCBCEvalOptions, gcbc_eval
from bridgeplan.options import add_command


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
    add_command(og, "eval", GCBCEvalOptions, gcbc_eval, description=GCBC_EVAL_DESCRIPTION,
                help="a GCBC run's snapshots on OGBench's 5-task evaluation protocol (one snapshot on any tasks, "
                     "validation's too: `bridgeplan eval RUN --tasks 6,7,8,9,10`)")


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
