"""Evaluation: plan once per episode, open loop, track the plan, score the returns (or, with an
:class:`~bridgeplan.replan.Execution`, plan again closed loop, with candidates and arrival rules).

:func:`evaluate_planner` scores a loaded planner on given :class:`Tasks` and returns an
:class:`EvalResult`; :func:`evaluate` loads a run and calls it. Every episode of a batch is planned
at once and all episodes step in lockstep; closed loop, all the episodes due to replan at a step are
planned in one batch. The same episodes are also run with no model at all (the
straight-line plan, tracked by the same controller: the floor), and for a prior that is neither
noise nor the line, with the prior sample alone; sweeps compute these floors once per run.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from bridgeplan import config as cfg
from bridgeplan.consistency import Correction, sampling_tag
from bridgeplan.envs import maze2d
from bridgeplan.envs.maze2d.grids import Maze, get_maze
from bridgeplan.envs.maze2d.reference import CONVENTIONS, normalized_score
from bridgeplan.envs.maze2d.rollout import execute_closed_loop, execute_plans
from bridgeplan.envs.maze2d.tasks import sample_tasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_text, code_version
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.replan import Execution, PlanSource, percentiles_ms
from bridgeplan.runs import RunInfo, load_planner, require_family
from bridgeplan.trajectory import MAZE2D


@dataclass(frozen=True)
class Tasks:
    """Seeded evaluation episodes: where each starts (at rest) and the goal it must reach."""

    maze: Maze
    starts_xy: np.ndarray
    goals_xy: np.ndarray
    seed: int
    multi_task: bool

    @property
    def episodes(self) -> int:
        return len(self.starts_xy)

    @property
    def start_states(self) -> np.ndarray:
        """``[N, 4]`` Maze2D states (x, y, vx, vy) with zero velocity."""
        return MAZE2D.at_rest(self.starts_xy)

    def generator(self, device: torch.device) -> torch.Generator:
        """The planning generator of these tasks: the same plans for the same tasks, whatever ran before."""
        return torch.Generator(device=device).manual_seed(self.seed)


VALIDATION_SEED_OFFSET = 1000
"""Validation episodes of a run evaluated on test tasks of seed s are the tasks of seed s + this offset
(disjoint from the test seeds of any sweep with fewer training seeds): settings are chosen on them."""


def make_tasks(maze: str, episodes: int, seed: int = 0, multi_task: bool = False) -> Tasks:
    if episodes <= 0:
        raise BridgeplanError(f"episodes must be positive, got {episodes}")
    m = get_maze(maze)
    starts, goals = sample_tasks(m, episodes, seed=seed, multi_task=multi_task)
    return Tasks(m, starts, goals, seed, multi_task)


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


def prior_only(planner: Planner, tasks: Tasks, prior_name: str | None = None,
               execution: Execution | None = None) -> dict:
    """The tasks executed from a prior's sample alone (no network), open loop with ``execution``'s controller:
    the planner's prior, or ``prior_name``."""
    execution = execution or Execution()
    if prior_name is not None:
        planner = planner.with_prior(make_prior(prior_name, planner.normalizer, planner.layout, stride=planner.stride))
    plan = planner.plan(tasks.start_states, tasks.goals_xy, 1, tasks.generator(planner.device), prior_only=True)
    result = execute_plans(tasks.maze, tasks.starts_xy, tasks.goals_xy, plan.states,
                           follower=execution.follower(tasks.episodes))
    return {"prior": planner.prior.name, **score_returns(tasks.maze.name, result.returns, result.success)}


def floors(planner: Planner, tasks: Tasks, execution: Execution | None = None) -> dict[str, dict]:
    """What the planner must beat on ``tasks``: the straight line executed open loop with ``execution``'s
    controller (``floor_line``) and, for a prior that is neither noise nor the line, that prior's sample
    (``prior_only_<name>``). Executed as the planner's plans are: a controller that outruns the plan's timing
    moves the floors too."""
    out = {"floor_line": prior_only(planner, tasks, "line", execution)}
    if planner.prior.name not in ("gaussian", "line"):
        out[f"prior_only_{planner.prior.name}"] = prior_only(planner, tasks, execution=execution)
    return out


@dataclass
class EvalResult:
    """One evaluation: a planner at one NFE on one set of tasks."""

    planner: Planner
    tasks: Tasks
    nfe: int
    run: RunInfo | None
    scores: dict
    """``score`` (per convention), ``return``, ``success_rate``: each mean and standard error."""
    per_start_cell: list[dict]
    floors: dict[str, dict]
    plan_ms_per_plan: float
    prior_ms_per_plan: float
    batch_size: int
    compile_seconds: float | None = None
    """Seconds spent compiling (untimed warm-up), None when the network was not compiled."""
    environment: dict = field(default_factory=dict)
    execution: Execution = field(default_factory=Execution)
    plans_made: np.ndarray | None = None
    """``[episodes]`` plans (decisions) made per episode; None: one each (open loop)."""
    decisions: dict = field(default_factory=dict)
    """Closed-loop / candidate runs: decision latency at batch 1 and per batch (``decision_ms_*``)."""
    plan_residuals: dict | None = None
    """Open loop: mean and standard error over the plans of ``Plan.residuals`` (m/s); None closed loop."""

    @property
    def prior(self) -> str:
        return self.planner.prior.name

    def score(self, convention: str = "minari") -> dict:
        return self.scores["score"][convention]

    def sampling_tag(self) -> str:
        """The process's :meth:`~bridgeplan.processes.Process.sampling_tag` and the correction's, if any."""
        return sampling_tag(self.planner.process.sampling_tag(), self.planner.correction)

    def cost_fields(self) -> dict:
        """``correction`` (its settings and passes per plan; None: uncorrected) and
        ``network_call_equivalents_per_plan`` (NFE, plus 2 per backward pass of a deep correction)."""
        c = self.planner.correction
        return {"correction": None if c is None else c.to_dict(self.nfe),
                "network_call_equivalents_per_plan": self.nfe if c is None else c.network_call_equivalents(self.nfe),
                "plan_residuals": self.plan_residuals}

    def to_dict(self) -> dict:
        """The JSON that ``bridgeplan eval`` writes (fields: README, "Evaluation output")."""
        process, run = self.planner.process, self.run
        out = {
            "run": run.name if run else None, "dataset": run.dataset if run else None,
            "step": run.step if run else None,
            "train_seconds": run.elapsed_seconds if run else None, "maze": self.tasks.maze.name,
            "method": cfg.method_label(process, self.prior, run.config.hold_share if run else 0.0),
            "process": process.name, "prior": self.prior,
            "process_params": process.to_dict(), "diffusion_steps": process.steps, "nfe": self.nfe,
            "episodes": self.tasks.episodes, "seed": self.tasks.seed, "multi_task": self.tasks.multi_task,
            "horizon": self.planner.horizon, "stride": self.planner.stride,
            "episode_steps": self.tasks.maze.episode_steps,
            **self.scores,
            "plan_ms_per_plan": self.plan_ms_per_plan, "prior_ms_per_plan": self.prior_ms_per_plan,
            "batch_size": self.batch_size, "compiled": self.compile_seconds is not None,
            "compile_seconds": self.compile_seconds or 0.0,
            "per_start_cell": self.per_start_cell, **self.floors, "environment": self.environment,
            **self.execution_fields(), **self.cost_fields(),
        }
        out["config"] = run.portable_config if run else None
        return out

    def execution_fields(self) -> dict:
        """How the plans were executed and what it cost per episode: ``execution`` (the settings),
        ``plans_per_episode`` (decisions: mean, min, max), ``calls_per_episode`` (NFE x plans made: the
        network calls one episode needs, candidates of a decision sharing a batch), ``candidate_plans_per_episode``
        (plans sampled: decisions x candidates) and, except for plain open loop, the decision latency
        ``decision_ms_batch1`` and ``decision_ms_per_batch`` (p50/p95/mean ms; see :func:`evaluate_planner`)."""
        made = (np.ones(self.tasks.episodes, dtype=np.int64) if self.plans_made is None
                else np.asarray(self.plans_made))
        return {"execution": self.execution.to_dict(self.prior),
                "plans_per_episode": {"mean": float(made.mean()), "min": int(made.min()), "max": int(made.max())},
                "calls_per_episode": float(self.nfe * made.mean()),
                "candidate_plans_per_episode": float(made.mean() * self.execution.candidates),
                **self.decisions}

    def to_row(self, split: str = "test") -> dict:
        """A results-store row (``experiments.store.COLUMNS``) made on ``split``'s episodes, as the store reads
        :meth:`to_dict`'s JSON (``store.row_from_eval_json``); needs the run the planner came from."""
        from bridgeplan.experiments.store import row_from_eval_json

        if self.run is None:
            raise BridgeplanError("a store row needs the run the planner was loaded from")
        return row_from_eval_json(self.to_dict(), split)


def evaluate_planner(planner: Planner, tasks: Tasks, nfe: int | None = None, run: RunInfo | None = None,
                     batch_size: int | None = None, compiled: bool = False,
                     precomputed_floors: dict[str, dict] | None = None,
                     execution: Execution | None = None) -> EvalResult:
    """Score ``planner`` on ``tasks`` with ``nfe`` network calls per plan (default: the process's most).

    ``batch_size``: plans per network batch (default: all episodes at once). ``compiled``: the network is
    ``torch.compile``'d; it is compiled in an untimed warm-up at every batch shape first, with a generator
    of its own, so the plans and the planning time are those of the compiled network alone.
    ``precomputed_floors``: :func:`floors` of the same planner's prior on the same tasks, to skip them.
    ``execution``: replanning, candidates, arrival rule (default: open loop, one plan per episode). Closed loop,
    ``batch_size`` caps the plans per network batch (candidates included), the floors stay open loop, and the
    decisions are timed twice: every batched decision of the evaluation (``decision_ms_per_batch``, with
    ``mean_batch`` plans per decision: due episodes x candidates) and, at batch 1, every decision of the first
    episode run again alone after one untimed warm-up decision (``decision_ms_batch1``).
    """
    nfe = planner.process.max_nfe if nfe is None else nfe
    planner.process.validate_nfe(nfe)
    if batch_size is not None and batch_size <= 0:
        raise BridgeplanError(f"batch size must be positive, got {batch_size}")
    execution = execution or Execution()
    execution.validate(planner.process, tasks.maze.episode_steps)
    if not execution.plans_once:
        return _evaluate_closed_loop(planner, tasks, nfe, run, batch_size, compiled, precomputed_floors, execution)
    n = tasks.episodes
    batch = min(batch_size or n, n)
    starts, goals = tasks.start_states, tasks.goals_xy
    compile_s = None
    if compiled:
        t0 = time.perf_counter()
        for size in {batch, n % batch} - {0}:  # every batch shape the loop below will use
            planner.plan(starts[:size], goals[:size], nfe, torch.Generator(device=planner.device).manual_seed(0))
        compile_s = time.perf_counter() - t0
    gen = tasks.generator(planner.device)
    plans, prior_s, sample_s, residuals = [], 0.0, 0.0, defaultdict(list)
    for lo in range(0, n, batch):
        plan = planner.plan(starts[lo:lo + batch], goals[lo:lo + batch], nfe, gen)
        plans.append(plan.states)
        for key, values in planner.residuals(plan).items():
            residuals[key].append(values)
        prior_s += plan.prior_seconds
        sample_s += plan.sample_seconds
    result = execute_plans(tasks.maze, tasks.starts_xy, goals, np.concatenate(plans), follower=execution.follower(n))
    environment = environment_of(planner)
    return EvalResult(
        planner=planner, tasks=tasks, nfe=nfe, run=run,
        scores=score_returns(tasks.maze.name, result.returns, result.success),
        per_start_cell=_per_start_cell(tasks.maze, tasks.starts_xy, result.returns),
        floors=precomputed_floors if precomputed_floors is not None else floors(planner, tasks, execution),
        plan_ms_per_plan=1000.0 * (prior_s + sample_s) / n, prior_ms_per_plan=1000.0 * prior_s / n,
        batch_size=batch, compile_seconds=compile_s, environment=environment, execution=execution,
        plan_residuals={k: _mean_se(np.concatenate(v)) for k, v in residuals.items()})


def environment_of(planner: Planner) -> dict:
    return {"device": str(planner.device), "torch": torch.__version__, "machine": platform.machine(),
            "processor": platform.processor() or platform.machine(),
            "cpu_threads": torch.get_num_threads(), "code_version": code_version()}


def _evaluate_closed_loop(planner: Planner, tasks: Tasks, nfe: int, run: RunInfo | None, batch_size: int | None,
                          compiled: bool, precomputed_floors: dict[str, dict] | None,
                          execution: Execution) -> EvalResult:
    """:func:`evaluate_planner` with replanning, candidates or an arrival rule (``execution``)."""
    n, maze, m = tasks.episodes, tasks.maze, execution.candidates
    starts, goals = tasks.starts_xy, tasks.goals_xy
    compile_s = None
    if compiled:  # the first decision's shape; replans at other shapes compile when they first occur
        t0 = time.perf_counter()
        warm_up = PlanSource(planner, execution, nfe, torch.Generator(device=planner.device).manual_seed(0), n,
                             maze, batch_size)
        warm_up(tasks.start_states, goals, np.arange(n), 0)
        compile_s = time.perf_counter() - t0
    source = PlanSource(planner, execution, nfe, tasks.generator(planner.device), n, maze, batch_size)
    result = execute_closed_loop(maze, starts, goals, source, execution.replan_every, execution.tolerance,
                                 follower=execution.follower(n))
    single = PlanSource(planner, execution, nfe, torch.Generator(device=planner.device).manual_seed(tasks.seed + 1),
                        1, maze)
    per_batch = percentiles_ms(source.decision_seconds)
    per_batch["mean_batch"] = float(np.mean(source.decision_batch)) * m
    decisions = {"decision_ms_batch1": batch1_latency(single, tasks, execution), "decision_ms_per_batch": per_batch}
    return EvalResult(
        planner=planner, tasks=tasks, nfe=nfe, run=run,
        scores=score_returns(maze.name, result.returns, result.success),
        per_start_cell=_per_start_cell(maze, starts, result.returns),
        floors=precomputed_floors if precomputed_floors is not None else floors(planner, tasks, execution),
        plan_ms_per_plan=1000.0 * (source.prior_seconds + source.sample_seconds) / source.plans_sampled,
        prior_ms_per_plan=1000.0 * source.prior_seconds / source.plans_sampled,
        batch_size=min(batch_size or n * m, n * m), compile_seconds=compile_s, environment=environment_of(planner),
        execution=execution, plans_made=result.plans_made, decisions=decisions)


def batch1_latency(single, tasks: Tasks, execution: Execution) -> dict:
    """Decision latency at batch 1 (p50/p95/mean ms): the first episode of ``tasks`` run again alone by
    ``single`` (a closed loop's ``plan_fn`` for one episode, fresh, with ``decision_seconds`` and ``reset``),
    after one untimed decision."""
    goals = tasks.goals_xy[:1]
    single(tasks.start_states[:1], goals, np.zeros(1, dtype=np.int64), 0)
    single.decision_seconds.clear()
    single.reset()
    execute_closed_loop(tasks.maze, tasks.starts_xy[:1], goals, single, execution.replan_every, execution.tolerance,
                        follower=execution.follower(1))
    return percentiles_ms(single.decision_seconds)


def evaluate(run: Path, episodes: int = 200, nfe: int | None = None, seed: int = 0,
             multi_task: bool = False, batch_size: int | None = None, snapshot: int | None = None,
             device: str = "auto", sampler: str | None = None, eta: float = 0.0, compile: bool = False,
             execution: Execution | None = None, correction: Correction | None = None) -> EvalResult:
    """Load a trained run (or one of its snapshots) and :func:`evaluate_planner` it on seeded tasks
    (``execution``: closed loop, candidates, arrival; default open loop; ``correction``: a consistency
    correction of the x0 predictions, ``consistency.Correction``)."""
    if episodes <= 0:
        raise BridgeplanError(f"episodes must be positive, got {episodes}")
    planner, info = load_planner(run, snapshot=snapshot, device=device, sampler=sampler, eta=eta, compile=compile)
    require_family(info, maze2d.FAMILY)
    planner = planner.with_correction(correction)
    if multi_task:
        check_multi_task_run(info)
    tasks = make_tasks(info.config.maze, episodes, seed, multi_task)
    return evaluate_planner(planner, tasks, nfe, run=info, batch_size=batch_size, compiled=compile,
                            execution=execution)


def check_multi_task_run(info: RunInfo) -> None:
    """:func:`check_multi_task_data` for a loaded run, unless its dataset is known to cover every cell (a shipped
    planner's, checked when exported)."""
    if not info.dataset_covers_every_cell:
        check_multi_task_data(info.config.maze, info.config.dataset)


def check_multi_task_data(maze_name: str, dataset: str) -> None:
    """Multi2D draws starts and goals in every free cell: refuse a run whose dataset never visits some of them
    (its planner has never seen a state there); warn when the dataset is not at hand to check."""
    from bridgeplan.envs.maze2d.datasets import load_stream
    from bridgeplan.envs.maze2d.info import visited_cells

    if not Path(dataset).exists():
        print(f"warning: the run's dataset {dataset!r} is not here: cannot check that it covers every cell "
              f"that --multi-task draws goals in", file=sys.stderr)
        return
    maze = get_maze(maze_name)
    free = maze.free_cells
    missing = free[~visited_cells(load_stream(dataset))[free[:, 0], free[:, 1]]]
    if len(missing):
        cells = ", ".join(f"({r}, {c})" for r, c in missing[:5]) + (" ..." if len(missing) > 5 else "")
        raise BridgeplanError(f"--multi-task draws goals in every free cell, but the run's dataset never visits "
                              f"{len(missing)} of the {len(free)}: {cells}; evaluate single-task, or train on "
                              f"data that covers the maze")


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


def write_and_show(result: dict, path: Path, as_json: bool, summary: str) -> None:
    """An evaluation command's ending: ``result`` written to ``path``, then printed as JSON (``--json``), else
    its human-readable ``summary`` and where it went."""
    write_result(result, path)
    print(json.dumps(result, indent=2) if as_json else f"{summary}\nwrote {path}")


def format_table(result: dict) -> str:
    """Human-readable summary of one evaluation (:meth:`EvalResult.to_dict`)."""
    s = result["score"]
    lines = [
        f"{result['maze']}  {result['method']}  NFE={result['nfe']}  "
        f"step={result['step']}  episodes={result['episodes']}  seed={result['seed']}"
        + ("  multi-task" if result["multi_task"] else ""),
        f"  normalized score (minari): {s['minari']['mean']:7.1f} ± {s['minari']['se']:.1f}",
        f"  normalized score (d4rl):   {s['d4rl']['mean']:7.1f} ± {s['d4rl']['se']:.1f}",
        f"  return:                    {result['return']['mean']:7.1f} ± {result['return']['se']:.1f}",
        f"  success rate:              {result['success_rate']['mean']:7.3f}",
        f"  plan time:                 {result['plan_ms_per_plan']:7.2f} ms/plan "
        f"(prior {result['prior_ms_per_plan']:.2f} ms; batch {result['batch_size']}"
        + (f"; compiled in {result['compile_seconds']:.0f} s, untimed)" if result["compiled"] else ")"),
    ]
    c = result.get("correction")
    if c is not None:
        lines.append(f"  correction:                {c['tag']}: {c['network_call_equivalents_per_plan']} "
                     f"network-call equivalents per plan ({c['forward_passes_per_plan']} forward, "
                     f"{c['backward_passes_per_plan']} backward passes)")
    if result.get("plan_residuals"):
        r = result["plan_residuals"]
        lines.append(f"  plan residuals (rms, m/s): kinematics {r['kinematics_rms']['mean']:.3f}, "
                     f"dynamics {r['dynamics_rms']['mean']:.3f}")
    ex = result.get("execution")
    if ex is not None and (ex["mode"] == "closed_loop" or ex["candidates"] > 1 or ex["arrival"] != "end"):
        b1, pb = result["decision_ms_batch1"], result["decision_ms_per_batch"]
        lines.append(f"  execution:                 {ex['mode']}, replan every {ex['replan_every']}, tolerance "
                     f"{ex['replan_tolerance']}, candidates {ex['candidates']}"
                     + (f" ({ex['select']})" if ex["select"] else "")
                     + f", arrival {ex['arrival']}, replan prior {ex['replan_prior']}")
        lines.append(f"  plans per episode:         {result['plans_per_episode']['mean']:7.1f} "
                     f"({result['calls_per_episode']:.1f} network calls per episode)")
        lines.append(f"  decision latency:          batch 1: p50 {b1['p50']:.2f} ms, p95 {b1['p95']:.2f} ms; "
                     f"per batch ({pb['mean_batch']:.0f} plans): p50 {pb['p50']:.2f} ms, p95 {pb['p95']:.2f} ms")
    for key in [k for k in result if k.startswith(("floor_", "prior_only_"))]:
        f = result[key]
        lines.append(f"  {key:<26} {f['score']['minari']['mean']:7.1f} ± {f['score']['minari']['se']:.1f} "
                     f"(minari), success {f['success_rate']['mean']:.3f}")
    return "\n".join(lines)
