"""Benchmarks: planning latency, overheads, threads on a busy machine, torch.compile, training throughput
against the machine's limit, two training jobs side by side, evaluation throughput and score per planning budget.

``harness.py`` times, ``suites.py`` measures (one function per figure), ``markdown.py`` writes the
tables. Timings are medians over repeats after warm-up; the machine is recorded beside them. Not
part of the tests: ``bridgeplan bench`` writes ``bench.json`` (with its settings) and ``bench.md``.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass
from pathlib import Path

from bridgeplan.bench import suites
from bridgeplan.bench.harness import machine
from bridgeplan.bench.markdown import format_bench
from bridgeplan.config import PRESETS
from bridgeplan.device import resolve_device
from bridgeplan.envs.maze2d.grids import MAZE_NAMES
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.files import atomic_write_text
from bridgeplan.paths import snapshot_path, snapshot_steps


@dataclass(frozen=True)
class BenchConfig:
    """What ``bridgeplan bench`` measures."""

    presets: tuple[str, ...] = ("cpu-small", "diffuser")
    """Networks to time (untrained; timing does not depend on the weights)."""
    mazes: tuple[str, ...] = ("umaze",)
    """The Maze2D mazes whose plans the latency table times, each at its preset's shape (cpu-small: umaze 128 states
    one step apart; medium 32 and large 48, 8 steps apart)."""
    batch_sizes: tuple[int, ...] = (1, 64)
    """Plans per call for the latency, overhead and compile figures."""
    nfes: tuple[int, ...] = (1, 2, 4, 8, 15)
    """Network calls per plan for the latency table."""
    methods: tuple[str, ...] = ()
    """Methods to time in the latency and overhead tables, named as in them (``DDPM [ancestral]``,
    ``bridge (line)``, ...); empty: every method."""
    repeats: int = 5
    """Timed repeats per latency figure (after 2 warm-up calls)."""
    overhead_repeats: int = 30
    """Interleaved rounds for the overhead ratios (plan vs bare forward; train step vs bare step); 0: skip them."""
    busy_steps: int = 30
    """Training steps per rate of the busy-core figure (0: skip it; CPU devices only)."""
    throughput_seconds: float = 2.0
    """Seconds of training steps per figure of the training-throughput table (0: skip it)."""
    throughput_batch_sizes: tuple[int, ...] = (32, 256)
    """Batches of the throughput table (on a CPU for ``cpu-small`` only: there ``diffuser``'s network is timed at
    its own 32, a batch of 256 taking seconds per step)."""
    side_by_side_seconds: float = 2.0
    """Seconds of training steps per figure of the two-jobs table: each maze's step with the other core quiet,
    spinning, or training the same step in another process, alternating (0: skip it; CPU devices with 2+ cores,
    POSIX only: the other processes are paused between turns)."""
    compile: bool = True
    """Also time ``torch.compile``'d forward passes against eager ones, and ``train --compile``'s step in the
    training-throughput table (compilation takes minutes on a CPU)."""
    frozen: bool = False
    """Also time each method's plan through its network traced and frozen (:class:`~bridgeplan.nets.unet.FrozenUNet`,
    ``eval --frozen``): a latency row each, its method named ``..., frozen``."""
    eval_run: str = ""
    """A trained run: time 200 of its umaze episodes at NFE 1, planning included."""
    budget_runs: tuple[str, ...] = ()
    """Trained runs for the score-per-budget table, one row each (ideally one per method, at equal training steps)."""
    budget_steps: tuple[int, ...] = ()
    """Training budgets: evaluate each budget run's EMA snapshot at these steps (empty: its latest checkpoint)."""
    budgets: tuple[int, ...] = (1, 2, 4, 8)
    """Network-call budgets K of the score-per-budget table."""
    budget_episodes: int = 200
    """Episodes per evaluation of the score-per-budget table, on validation tasks (seed 1: choosing NFE and
    sampler) and on test tasks (seed 0: the reported score)."""
    device: str = "auto"
    """``auto`` (CUDA if present), ``cpu``, ``cuda``, ..."""

    def validate(self) -> None:
        for name in ("repeats", "budget_episodes"):
            if getattr(self, name) <= 0:
                raise BridgeplanError(f"{name.replace('_', '-')} must be positive, got {getattr(self, name)}")
        if self.overhead_repeats < 0:
            raise BridgeplanError(f"overhead-repeats must be >= 0, got {self.overhead_repeats}")
        if self.side_by_side_seconds < 0:
            raise BridgeplanError(f"side-by-side-seconds must be >= 0, got {self.side_by_side_seconds}")
        if self.throughput_seconds < 0 or min(self.throughput_batch_sizes, default=1) <= 0:
            raise BridgeplanError("throughput-seconds must be >= 0 and its batch sizes positive")
        if self.busy_steps < 0:
            raise BridgeplanError(f"busy-steps must be >= 0, got {self.busy_steps}")
        for name in ("batch_sizes", "nfes", "budgets", "budget_steps"):
            values = getattr(self, name)
            if (name != "budget_steps" and not values) or min(values, default=1) <= 0:
                raise BridgeplanError(f"{name.replace('_', '-')} must be positive integers, got {list(values)}")
        for preset in self.presets:
            check_choice("preset", preset, PRESETS)
        if not self.mazes:
            raise BridgeplanError("mazes must name at least one maze")
        for maze in self.mazes:
            check_choice("maze", maze, MAZE_NAMES)
        known = suites.method_configs(self.presets[0] if self.presets else "cpu-small")
        unknown = [m for m in self.methods if m not in known]
        if unknown:
            raise BridgeplanError(f"unknown method {unknown[0]!r}: choose from {', '.join(known)}")
        for run in (self.eval_run, *self.budget_runs):
            if run and not Path(run).exists():
                raise BridgeplanError(f"no run at {run}")
        for run in self.budget_runs:
            missing = [step for step in self.budget_steps if not snapshot_path(run, step).exists()]
            if missing:
                raise BridgeplanError(f"no snapshot at step {missing[0]} in {run} (have: {snapshot_steps(run)})")
        resolve_device(self.device)


def run_bench(out_dir: Path, bench: BenchConfig, progress=print) -> Path:
    """Run the suite and write ``bench.json`` and ``bench.md`` into ``out_dir``; returns the Markdown path."""
    bench.validate()
    dev = resolve_device(bench.device)
    result = {"bench": dataclasses.asdict(bench), "machine": machine(dev), "latency_interleaved": True, "latency": [],
              "plan_overhead": [], "train_overhead": [], "busy_core": [], "compile": [], "throughput": [],
              "side_by_side": []}
    for preset in bench.presets:
        for maze in bench.mazes:
            progress(f"[{preset}] planning latency ({maze})")
            result["latency"] += suites.planning_latency(preset, bench.batch_sizes, bench.nfes, bench.repeats, dev,
                                                         bench.methods, bench.frozen, maze)
        if bench.overhead_repeats:
            progress(f"[{preset}] overheads")
            result["plan_overhead"] += [suites.plan_overhead(preset, b, bench.overhead_repeats, dev, bench.methods)
                                        for b in bench.batch_sizes]
            result["train_overhead"].append(suites.train_overhead(preset, bench.overhead_repeats, dev))
        if bench.busy_steps and dev.type == "cpu":
            progress(f"[{preset}] training with a busy core")
            result["busy_core"].append(suites.busy_core_training(preset, bench.busy_steps, dev))
        if bench.throughput_seconds:
            progress(f"[{preset}] training throughput")
            batches = (32,) if preset == "diffuser" and dev.type == "cpu" else bench.throughput_batch_sizes
            result["throughput"] += suites.training_throughput(preset, batches, bench.throughput_seconds, dev,
                                                               compiled=bench.compile)
        if bench.side_by_side_seconds and dev.type == "cpu" and (os.cpu_count() or 1) > 1 and os.name == "posix":
            progress(f"[{preset}] two training jobs side by side")
            result["side_by_side"] += suites.side_by_side_training(preset, bench.side_by_side_seconds, dev)
        if bench.compile:
            progress(f"[{preset}] torch.compile")
            result["compile"] += suites.compile_speedup(preset, bench.batch_sizes, bench.overhead_repeats, dev)
    if bench.eval_run:
        progress("evaluation throughput")
        result["eval_throughput"] = suites.eval_throughput(bench.eval_run, bench.device)
    if bench.budget_runs:
        progress("score per planning budget")
        result["score_per_budget"] = suites.score_per_budget(bench.budget_runs, bench.budget_steps, bench.budgets,
                                                             bench.budget_episodes, bench.device)
    if "load_1min_start" in result["machine"]:
        result["machine"]["load_1min_end"] = os.getloadavg()[0]
    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "bench.json", json.dumps(result, indent=2) + "\n")
    atomic_write_text(out_dir / "bench.md", format_bench(result))
    return out_dir / "bench.md"


__all__ = ["BenchConfig", "run_bench"]
