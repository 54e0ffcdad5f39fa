"""The ``bridgeplan gcbc train`` and ``gcbc eval`` commands (torch is imported only when one runs)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from bridgeplan.errors import BridgeplanError
from bridgeplan.eval_commands import GCBC_EVAL_DESCRIPTION, GCBCEvalOptions, gcbc_eval
from bridgeplan.option_groups import Device, Environment, Progress, RunDir, Threads, Training
from bridgeplan.options import REQUIRED, add_command, group, opt, values


@dataclass(kw_only=True)
class GCBCTrainOptions:
    dataset: str = opt(help="training npz in OGBench's format")
    run: RunDir = group(RunDir, run_dir=REQUIRED)
    environment: Environment = group(Environment)
    training: Training = group(Training)
    p_curgoal: float | None = opt(None, "probability that the goal is the current state")
    p_trajgoal: float | None = opt(None, "probability that the goal is a future state of the same trajectory")
    p_randomgoal: float | None = opt(None, "probability that the goal is a random state of the dataset")
    discount: float | None = opt(None, "the geometric offsets' discount (--geom-sample)")
    alpha: float | None = opt(None, "GCIQL: the behaviour-cloning weight of the DDPG+BC actor")
    expectile: float | None = opt(None, "GCIQL: the value's expectile")
    tau: float | None = opt(None, "GCIQL: the target critics' update rate")
    hidden_dims: str | None = opt(None, "comma-separated widths (default 512,512,512)")
    agent: str | None = opt(None, "gcbc (default) or gciql (a value and critics, the policy their actor; --alpha, "
                                  "--expectile, --tau are its)")
    geom_sample: bool = opt(False, "future goals at geometric offsets")
    device: Device = group(Device, device=None)
    threads: Threads = group(Threads)
    progress: Progress = group(Progress)


def add_gcbc_commands(sub) -> None:
    """The ``bridgeplan gcbc`` group: ``train`` and ``eval``."""
    p = sub.add_parser("gcbc", help="goal-conditioned behaviour cloning, OGBench's baseline on its own data")
    og = p.add_subparsers(dest="gcbc_command", required=True)
    add_command(og, "train", GCBCTrainOptions, _cmd_gcbc_train,
                help="goal-conditioned behaviour cloning (OGBench's GCBC baseline)",
                description="Defaults: OGBench's GCBC for pointmaze (GCBCConfig in bridgeplan/gcbc.py): lr 3e-4, "
                            "batch 1024, MLP 512x3, future-state goals, 1M steps. --maze: the OGBench dataset the "
                            "data is of (pointmaze-medium-navigate-v0, cube-single-play-v0, or a bare pointmaze maze; "
                            "checked; evaluation's default).")
    add_command(og, "eval", GCBCEvalOptions, gcbc_eval, description=GCBC_EVAL_DESCRIPTION,
                help="a GCBC run's snapshots on OGBench's 5-task evaluation protocol (one snapshot on any tasks, "
                     "validation's too: `bridgeplan eval RUN --tasks 6,7,8,9,10`)")


def _cmd_gcbc_train(o: GCBCTrainOptions) -> int:
    from bridgeplan.checkpoint import load_checkpoint
    from bridgeplan.gcbc import GCBCConfig, train_gcbc
    from bridgeplan.paths import checkpoint_path

    given = values(o)
    given = {f: given[f] for f in ("maze", "steps", "minutes", "batch_size", "lr", "seed", "p_curgoal", "p_trajgoal",
                                   "p_randomgoal", "discount", "checkpoint_every", "log_every", "threads", "device",
                                   "agent", "alpha", "expectile", "tau") if given[f] is not None}
    if o.hidden_dims:
        try:
            given["hidden_dims"] = tuple(int(v) for v in o.hidden_dims.split(","))
        except ValueError:
            raise BridgeplanError(f"--hidden-dims takes comma-separated integers, got {o.hidden_dims!r}") from None
    if o.geom_sample:
        given["geom_sample"] = True
    run = train_gcbc(GCBCConfig(dataset=o.dataset, **given), Path(o.run.run_dir), resume=o.run.resume,
                     progress=not o.progress.no_progress)
    print(f"trained {run} (step {load_checkpoint(checkpoint_path(run))['step']})")
    return 0
