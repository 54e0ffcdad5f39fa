"""The ``bridgeplan gcbc train`` command (torch is imported only when it runs); ``bridgeplan eval RUN`` evaluates its
runs as any other."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from bridgeplan.option_groups import Device, Environment, Progress, RunDir, Threads, Training
from bridgeplan.options import REQUIRED, add_command, config_fields, from_config, group, int_tuple, opt

GCBC_CONFIG = "bridgeplan.gcbc:GCBCConfig"


@dataclass(kw_only=True)
class GCBCTrainOptions:
    dataset: str = opt(help="training npz in OGBench's format")
    run: RunDir = group(RunDir, run_dir=REQUIRED)
    environment: Environment = group(Environment)
    training: Training = group(Training)
    p_curgoal: float | None = from_config(GCBC_CONFIG, "p_curgoal")
    p_trajgoal: float | None = from_config(GCBC_CONFIG, "p_trajgoal")
    p_randomgoal: float | None = from_config(GCBC_CONFIG, "p_randomgoal")
    discount: float | None = from_config(GCBC_CONFIG, "discount")
    alpha: float | None = from_config(GCBC_CONFIG, "alpha")
    expectile: float | None = from_config(GCBC_CONFIG, "expectile")
    tau: float | None = from_config(GCBC_CONFIG, "tau")
    hidden_dims: str | None = from_config(GCBC_CONFIG, "hidden_dims", metavar="W1,W2,...")
    agent: str | None = from_config(GCBC_CONFIG, "agent")
    geom_sample: bool = from_config(GCBC_CONFIG, "geom_sample", default=False)
    device: Device = group(Device, device=None)
    threads: Threads = group(Threads)
    progress: Progress = group(Progress)


def add_gcbc_commands(sub) -> None:
    """The ``bridgeplan gcbc`` group: ``train``."""
    p = sub.add_parser("gcbc", help="OGBench's goal-conditioned baselines on its own data: GCBC and GCIQL")
    og = p.add_subparsers(dest="gcbc_command", required=True)
    add_command(og, "train", GCBCTrainOptions, _cmd_gcbc_train, GCBC_CONFIG,
                help="OGBench's GCBC (goal-conditioned behaviour cloning) or, with --agent gciql, its GCIQL; "
                     "`bridgeplan eval RUN` evaluates either",
                description="Defaults (shown): OGBench's GCBC for pointmaze, its GCIQL's where marked GCIQL "
                            "(GCBCConfig in bridgeplan/gcbc.py). "
                            "--maze: the OGBench dataset the data is of (pointmaze-medium-navigate-v0, "
                            "cube-single-play-v0, or a bare pointmaze maze; checked; evaluation's default).")


def _cmd_gcbc_train(o: GCBCTrainOptions) -> int:
    from bridgeplan.checkpoint import load_checkpoint
    from bridgeplan.gcbc import GCBCConfig, train_gcbc
    from bridgeplan.paths import checkpoint_path

    given = config_fields(o, GCBCConfig, leave=("hidden_dims",))  # given as text, read below
    if o.hidden_dims is not None:
        given["hidden_dims"] = int_tuple(o.hidden_dims, "--hidden-dims")
    run = train_gcbc(GCBCConfig(**given), Path(o.run.run_dir), resume=o.run.resume,
                     progress=not o.progress.no_progress)
    print(f"trained {run} (step {load_checkpoint(checkpoint_path(run))['step']})")
    return 0
