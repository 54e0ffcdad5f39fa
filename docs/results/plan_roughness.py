"""How smooth are the plans? Issue 15 (the I2SB bridge's score falls as NFE grows) and issue 13 (pursuit, which
follows a plan's path, fails on ragged plans): the mean distance between consecutive planned positions, and the
mean size of their second difference (|p[k+1] - 2 p[k] + p[k-1]|, zero on a straight line at constant speed),
both in maze units per planned state, at each NFE and with each of the process's samplers; next to the same
for the dataset's own windows (2000 drawn at random, at the runs' stride). The seed-s runs plan the 200 test
tasks of seed s (single-task) at their final snapshot; mean ± standard error over seeds.

Usage: python docs/results/plan_roughness.py OUT.json RUN_DIR [RUN_DIR ...]
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

from bridgeplan.evaluate import make_tasks
from bridgeplan.files import atomic_write_text, code_version
from bridgeplan.runs import load_planner, load_windows
from bridgeplan.trajectory import ACT_DIM


def roughness(positions: np.ndarray) -> tuple[float, float]:
    """(mean step, mean second difference) of ``positions [N, H, 2]``."""
    step = np.linalg.norm(np.diff(positions, axis=1), axis=2).mean()
    second = np.linalg.norm(np.diff(positions, n=2, axis=1), axis=2).mean()
    return float(step), float(second)


def main(out: str, runs: list[str]) -> int:
    torch.set_num_threads(1)
    rows, data = [], {}
    for run in map(Path, runs):
        planner, info = load_planner(run, device="cpu")
        config = info.config
        tasks = make_tasks(config.maze, 200, config.seed)
        for sampler in planner.process.usable_samplers() or (None,):  # every way the trained network can be sampled
            sampled = planner.with_sampler(sampler) if sampler else planner
            method = planner.process.label(planner.prior.name) + (f" [{sampler}]" if sampler else "")
            for nfe in sorted({1, 2, 4, planner.process.max_nfe}):
                states = sampled.plan(tasks.start_states, tasks.goals_xy, nfe, tasks.generator(planner.device)).states
                step, second = roughness(np.asarray(states)[:, ::config.stride, :2])
                rows.append({"maze": config.maze, "method": method, "run": run.name, "seed": config.seed,
                             "step": info.step, "nfe": nfe, "mean_step": step, "mean_second_difference": second})
        key = (config.maze, config.dataset, config.horizon, config.stride)
        if key not in data:
            windows, normalizer = load_windows(config.dataset, config.maze, config.horizon, config.stride)
            pick = np.random.default_rng(0).choice(len(windows), size=min(2000, len(windows)), replace=False)
            physical = normalizer.unnormalize(windows.batch(torch.as_tensor(pick)).numpy())
            step, second = roughness(physical[..., ACT_DIM:ACT_DIM + 2])
            data[key] = {"maze": config.maze, "horizon": config.horizon, "stride": config.stride,
                         "mean_step": step, "mean_second_difference": second}
    summary = defaultdict(list)
    for r in rows:
        summary[(r["maze"], r["method"], r["nfe"])].append((r["mean_step"], r["mean_second_difference"]))
    lines = ["| maze | method | NFE | mean step | mean second difference | seeds |", "|---|---|---|---|---|---|"]
    for (maze, method, nfe), v in sorted(summary.items()):
        a = np.array(v)
        se = a.std(axis=0, ddof=1) / np.sqrt(len(a)) if len(a) > 1 else np.full(2, np.nan)
        lines.append(f"| {maze} | {method} | {nfe} | {a[:, 0].mean():.3f} ± {se[0]:.3f} | "
                     f"{a[:, 1].mean():.3f} ± {se[1]:.3f} | {len(a)} |")
    for d in data.values():
        lines.append(f"| {d['maze']} | the dataset's windows | - | {d['mean_step']:.3f} | "
                     f"{d['mean_second_difference']:.3f} | - |")
    atomic_write_text(Path(out), json.dumps({"code_version": code_version(), "episodes": 200, "rows": rows,
                                             "dataset": list(data.values())}, indent=2) + "\n")
    atomic_write_text(Path(out).with_suffix(".md"), "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__.split("Usage: ")[1])
    sys.exit(main(sys.argv[1], sys.argv[2:]))
