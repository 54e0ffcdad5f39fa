"""Evaluation: plan once per episode, open loop, track the plan, score the returns.

Every episode of a batch is planned at once and all episodes step in lockstep. The same episodes
are also run with no model at all (the straight-line plan, tracked by the same controller: the
floor), and for a bridge from an informative prior, with the prior sample alone.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

from bridgeplan.checkpoint import atomic_write_text, code_version
from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import get_maze
from bridgeplan.maze.reference import CONVENTIONS, normalized_score
from bridgeplan.maze.rollout import execute_plans
from bridgeplan.maze.tasks import sample_tasks
from bridgeplan.priors import make_prior
from bridgeplan.runs import load_planner


def _mean_se(values: np.ndarray) -> dict[str, float]:
    values = np.asarray(values, dtype=np.float64)
    se = float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else float("nan")
    return {"mean": float(values.mean()), "se": se}


def score_returns(maze_name: str, returns: np.ndarray, success: np.ndarray) -> dict:
    """Scores in every convention, raw return and success rate, each as mean and standard error."""
    scores = {}
    for convention in CONVENTIONS:
        mean, se = normalized_score(maze_name, returns, convention)
        scores[convention] = {"mean": mean, "se": se}
    return {"score": scores, "return": _mean_se(returns), "success_rate": _mean_se(success)}


def prepare_episodes(run: Path, episodes: int, nfe: int | None, seed: int, multi_task: bool = False,
                     snapshot: int | None = None, device: str = "auto", sampler: str | None = None,
                     eta: float = 0.0, compile: bool = False):
    """The planner of a run, its maze, the checked NFE, seeded tasks and the planning generator.

    Returns ``(planner, info, maze, nfe, (starts_xy, goals_xy, start_states), generator)``.
    """
    if episodes <= 0:
        raise BridgeplanError(f"episodes must be positive, got {episodes}")
    planner, info = load_planner(run, snapshot=snapshot, device=device, sampler=sampler, eta=eta, compile=compile)
    nfe = planner.process.max_nfe if nfe is None else nfe
    planner.process.validate_nfe(nfe)
    maze = get_maze(info["config"].maze)
    starts_xy, goals_xy = sample_tasks(maze, episodes, seed=seed, multi_task=multi_task)
    starts = np.concatenate([starts_xy, np.zeros_like(starts_xy)], axis=1)
    gen = torch.Generator(device=planner.device).manual_seed(seed)
    return planner, info, maze, nfe, (starts_xy, goals_xy, starts), gen


def evaluate(run: Path, episodes: int = 200, nfe: int | None = None, seed: int = 0,
             multi_task: bool = False, batch_size: int | None = None, snapshot: int | None = None,
             device: str = "auto", sampler: str | None = None, eta: float = 0.0, compile: bool = False) -> dict:
    """Evaluate a trained run; returns the result dict (its fields: README, "Evaluation output").

    ``batch_size``: plans per network batch (default: all episodes at once). ``compile``: plan with
    ``torch.compile``; compilation happens in an untimed warm-up call with a generator of its own, so the
    plans and the reported planning time are those of the compiled network alone.
    """
    if batch_size is not None and batch_size <= 0:
        raise BridgeplanError(f"batch size must be positive, got {batch_size}")
    planner, info, maze, nfe, (starts_xy, goals_xy, starts), gen = prepare_episodes(
        run, episodes, nfe, seed, multi_task, snapshot, device, sampler, eta, compile)
    config = info["config"]

    batch = min(batch_size or episodes, episodes)
    compile_s = 0.0
    if compile:
        t0 = time.perf_counter()
        for size in {batch, episodes % batch} - {0}:  # every batch shape the loop below will use
            planner.plan(starts[:size], goals_xy[:size], nfe, torch.Generator(device=planner.device).manual_seed(0))
        compile_s = time.perf_counter() - t0
    plans, prior_s, sample_s = [], 0.0, 0.0
    for lo in range(0, episodes, batch):
        plan = planner.plan(starts[lo:lo + batch], goals_xy[lo:lo + batch], nfe, gen)
        plans.append(plan.states)
        prior_s += plan.prior_seconds
        sample_s += plan.sample_seconds
    planned = np.concatenate(plans)
    result = execute_plans(maze, starts_xy, goals_xy, planned)

    out = {
        "run": str(run), "step": info["step"], "train_seconds": info["elapsed_seconds"], "maze": maze.name,
        "process": config.process.name,
        "prior": config.prior if config.process.name == "bridge" else "gaussian",
        "diffusion_steps": config.process.steps, "nfe": nfe,
        "sampler": getattr(planner.process, "sampler", "i2sb"), "eta": getattr(planner.process, "eta", None),
        "episodes": episodes, "seed": seed,
        "multi_task": multi_task, "horizon": config.horizon, "episode_steps": maze.episode_steps,
        **score_returns(maze.name, result.returns, result.success),
        "plan_ms_per_plan": 1000.0 * (prior_s + sample_s) / episodes,
        "prior_ms_per_plan": 1000.0 * prior_s / episodes,
        "batch_size": batch,
        "compiled": compile, "compile_seconds": compile_s,
        "per_start_cell": _per_start_cell(maze, starts_xy, result.returns),
        "floor_line": _prior_only(planner, "line", maze, starts, starts_xy, goals_xy, seed),
    }
    if out["prior"] not in ("gaussian", "line"):
        out[f"prior_only_{out['prior']}"] = _prior_only(planner, None, maze, starts, starts_xy, goals_xy, seed)
    out["environment"] = {"device": str(planner.device), "torch": torch.__version__,
                          "machine": platform.machine(), "processor": platform.processor() or platform.machine(),
                          "cpu_threads": torch.get_num_threads(), "code_version": code_version()}
    out["config"] = info["config_dict"]
    return out


def _prior_only(planner, prior_name: str | None, maze, starts, starts_xy, goals_xy, seed: int) -> dict:
    """The same episodes executed from the prior's sample alone (no network)."""
    prior = planner.prior if prior_name is None else make_prior(prior_name, planner.normalizer)
    floor_planner = dataclasses.replace(planner, prior=prior)
    gen = torch.Generator(device=planner.device).manual_seed(seed)
    plan = floor_planner.plan(starts, goals_xy, 1, gen, prior_only=True)
    result = execute_plans(maze, starts_xy, goals_xy, plan.states)
    return {"prior": prior.name, **score_returns(maze.name, result.returns, result.success)}


def _per_start_cell(maze, starts_xy: np.ndarray, returns: np.ndarray) -> list[dict]:
    by_cell: dict[tuple[int, int], list[float]] = defaultdict(list)
    for xy, ret in zip(starts_xy, returns):
        by_cell[tuple(int(v) for v in maze.xy_to_cell(xy))].append(float(ret))
    rows = []
    for cell in sorted(by_cell):
        rets = np.asarray(by_cell[cell])
        mean, se = normalized_score(maze.name, rets, "minari")
        rows.append({"cell": list(cell), "episodes": len(rets), "score_minari": mean, "score_minari_se": se})
    return rows


def write_result(result: dict, path: Path) -> None:
    atomic_write_text(path, json.dumps(result, indent=2) + "\n")


def format_table(result: dict) -> str:
    """Human-readable summary of one evaluation."""
    s = result["score"]
    lines = [
        f"{result['maze']}  {result['process']}  prior={result['prior']}  NFE={result['nfe']}  "
        f"step={result['step']}  episodes={result['episodes']}  seed={result['seed']}",
        f"  normalized score (minari): {s['minari']['mean']:7.1f} ± {s['minari']['se']:.1f}",
        f"  normalized score (d4rl):   {s['d4rl']['mean']:7.1f} ± {s['d4rl']['se']:.1f}",
        f"  return:                    {result['return']['mean']:7.1f} ± {result['return']['se']:.1f}",
        f"  success rate:              {result['success_rate']['mean']:7.3f}",
        f"  plan time:                 {result['plan_ms_per_plan']:7.2f} ms/plan "
        f"(prior {result['prior_ms_per_plan']:.2f} ms; batch {result['batch_size']}"
        + (f"; compiled in {result['compile_seconds']:.0f} s, untimed)" if result["compiled"] else ")"),
    ]
    for key in [k for k in result if k.startswith(("floor_", "prior_only_"))]:
        f = result[key]
        lines.append(f"  {key:<26} {f['score']['minari']['mean']:7.1f} ± {f['score']['minari']['se']:.1f} "
                     f"(minari), success {f['success_rate']['mean']:.3f}")
    return "\n".join(lines)
