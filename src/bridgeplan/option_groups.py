"""The option groups that several commands share (:mod:`bridgeplan.options`): the environment and its dataset, the
tasks, how plans are executed, the output, the machine, the training budget. Each option is declared here once; a
command takes a group whole (``group``) or one of its options (``shared``), with its own default where it needs one."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from bridgeplan.options import from_config, int_tuple, opt

EXECUTION = "bridgeplan.replan:Execution"


@dataclass(kw_only=True)
class Environment:
    maze: str | None = opt(None, "the environment: a Maze2D maze (umaze), an OGBench dataset name "
                                 "(pointmaze-medium-navigate-v0) or your own's spec file (NAME.toml)")


@dataclass(kw_only=True)
class Dataset:
    dataset: str | None = opt(None, "the dataset: a directory (Minari), a legacy D4RL hdf5 file or an OGBench npz file")


TASKS_HELP = ("OGBench: comma-separated task ids: 1-5 its test tasks (the default), 6-10 bridgeplan's validation tasks "
              "(other cells; protocol.validation_tasks)")


@dataclass(kw_only=True)
class Tasks:
    title: ClassVar[str] = "tasks (the environment family's)"
    episodes: int | None = opt(None, "episodes per task: Maze2D's episodes (its fixed goal, or Multi2D's random ones; "
                                     "default 200), each of OGBench's tasks' (default 50, as OGBench)")
    seed: int = opt(0, "the tasks' seed (and the planning generator's)")
    multi_task: bool = opt(False, "Maze2D: random goals too (Multi2D)")
    tasks: str | None = opt(None, TASKS_HELP)

    @property
    def ids(self) -> tuple[int, ...] | None:
        return task_ids(self.tasks)

    def file_tag(self) -> str:
        """These tasks in a result's default file name."""
        tasks = "" if self.tasks is None else "-tasks" + self.tasks.replace(",", "")
        episodes = "" if self.episodes is None else f"-ep{self.episodes}"
        return f"{episodes}-seed{self.seed}{tasks}" + ("-multi" if self.multi_task else "")


def task_ids(text: str | None) -> tuple[int, ...] | None:
    return None if text is None else int_tuple(text, "--tasks")


@dataclass(kw_only=True)
class Threads:
    threads: int | None = opt(None, "torch CPU threads (default: 1 on a CPU device, which keeps its speed when other "
                                    "processes share the cores; more only warns beyond the machine's cores)")


@dataclass(kw_only=True)
class Output:
    out: str | None = opt(None, "where the command writes (default: the command's, in its description)")
    json: bool = opt(False, "print the JSON to stdout instead of the table")


@dataclass(kw_only=True)
class Picture:
    title: ClassVar[str] = "pictures (MuJoCo offscreen: MUJOCO_GL, default egl)"
    video: bool = opt(False, "also write an animated GIF of the first episode")
    size: int = opt(240, "pixels of a rendered frame's side (the video's; OGBench manipulation's picture)")


@dataclass(kw_only=True)
class Progress:
    no_progress: bool = opt(False, "no progress bars (into a file, not a terminal, a bar is redrawn once a minute)")


@dataclass(kw_only=True)
class Device:
    device: str | None = opt("auto", "auto (CUDA if present), cpu, cuda, ...")


@dataclass(kw_only=True)
class Replanning:
    title: ClassVar[str] = "closed-loop execution (default: open loop, one plan per episode)"
    replan_every: int | None = from_config(EXECUTION, "replan_every", metavar="K")
    replan_tolerance: float | None = from_config(EXECUTION, "tolerance", metavar="D")


@dataclass(kw_only=True)
class PlanChoice:
    """How a planner's plans are made (a hierarchy's and the dataset graph's decisions do not take these)."""

    title: ClassVar[str] = Replanning.title
    candidates: int = from_config(EXECUTION, "candidates", default=1, metavar="M")
    select: str = from_config(EXECUTION, "select", default="arrival")
    prior: str | None = opt(None, "what the process starts from: training a bridge, gaussian (the default), line, "
                                  "learned or coarse (a low level's: the line through its subgoals); evaluating, warm "
                                  "(replans start from the previous plan, shifted: processes with a prior, replanning; "
                                  "the first plan uses the run's own prior)")
    arrival: str | None = from_config(EXECUTION, "arrival")


@dataclass(kw_only=True)
class Controller:
    title: ClassVar[str] = "controller (how a plan is executed)"
    controller: str | None = from_config(EXECUTION, "controller", default="track")
    lookahead: float | None = from_config(EXECUTION, "lookahead", metavar="R")


@dataclass(kw_only=True)
class Correction:
    title: ClassVar[str] = "consistency correction of every x0 prediction (CDDB; default: none)"
    correction: list[str] | None = opt(None, "move each x0 prediction down the gradient of a residual, STEP (>= 0) "
                                             "its step size (repeatable, one per residual): dynamics (PointMaze's "
                                             "point mass), kinematics (positions integrate velocities) or conditions "
                                             "(start/goal, deep form only)", action="append", metavar="RESIDUAL=STEP")
    correction_form: str | None = opt(None, "x0 (CDDB: the gradient in x0 space; default) or deep (CDDB-deep: the "
                                            "gradient w.r.t. the network's input, one backward pass per call)",
                                      metavar="FORM")


@dataclass(kw_only=True)
class LowLevel:
    low_snapshot: int | None = opt(None, "the low level's snapshot (training step)")
    nfe_low: int | None = opt(None, "network calls per low-level plan (default: all)")
    replan_high_every: int | None = opt(None, "the high level (a hierarchy's high run, or the dataset graph's search) "
                                              "plans again from the current state every K steps (default: once per "
                                              "episode)", metavar="K")


@dataclass(kw_only=True)
class RunDir:
    run_dir: str | None = opt(None, "the run's directory (a planner's default: RUNS_ROOT/<name derived from the "
                                    "config>)")
    resume: bool = opt(False, "continue the run in --run-dir")


@dataclass(kw_only=True)
class Training:
    """How long and how a model is trained (None: the command's config's default, which its help shows)."""

    steps: int | None = opt(None, "optimizer steps")
    minutes: float | None = opt(None, "wall-clock budget in minutes, 0 none (stops at steps or minutes)")
    batch_size: int | None = opt(None, "windows (GCBC: transitions) per gradient")
    lr: float | None = opt(None, "Adam's learning rate")
    checkpoint_every: int | None = opt(None, "write the checkpoint (and a snapshot) every this many steps")
    log_every: int | None = opt(None, "log every this many steps")
    seed: int | None = opt(None, "the training seed")
