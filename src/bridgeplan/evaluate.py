"""Evaluation, one path for every environment family: :func:`evaluate` runs decisions in a family's episodes.

Decisions (:class:`Decisions`: a planner's, :class:`PlannerDecisions`; a hierarchy's; the dataset graph's) are
executed by the family's controllers (:class:`~bridgeplan.replan.PlanExecutor`), in the family's episodes
(:meth:`~bridgeplan.envs.family.Family.run`: Maze2D's batched simulator, OGBench's own environments), and scored by
the family (its normalized score, its success rate). Every evaluation also measures, the same way for every family:

- the floors: the same episodes executed from the straight line alone (``floor_line``: no network) and, for a
  prior that is neither noise nor the line, from that prior's sample (``prior_only_<name>``); open loop, or as the
  planner is executed where the family says so (``Family.floor_replans``);
- the cost: plans per episode, network calls per episode, milliseconds per plan in the evaluation's batches;
- the decision latency: every decision of the evaluation in its batch (``decision_ms_per_batch``), and at batch 1
  (``decision_ms_batch1``): the first episode run again alone by fresh decisions, after one untimed decision, every
  one of its decisions timed; and each of that episode's steps, observation to action (``step_ms_batch1``: a plan
  when one is due and the controller's action, a policy's network call among them).

:func:`evaluate_planner` scores a loaded planner; :func:`evaluate_run` loads a run and calls it.
"""

from __future__ import annotations

import json
import platform
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Protocol

import numpy as np
import torch

from bridgeplan import config as cfg
from bridgeplan.consistency import Correction
from bridgeplan.device import cpu_model
from bridgeplan.envs import Family, family_of
from bridgeplan.envs.controllers import Follower
from bridgeplan.envs.family import Tasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_text, check_writable, code_version
from bridgeplan.nets.unet import FrozenUNet
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.replan import DecisionSource, Execution, PlanExecutor, PlanSource, percentiles_ms
from bridgeplan.runs import RunInfo, load_planner, portable_process
from bridgeplan.trajectory import span

VALIDATION_SEED_OFFSET = 1000
"""Validation episodes of a run evaluated on test tasks of seed s are the tasks of seed s + this offset
(disjoint from the test seeds of any sweep with fewer training seeds): settings are chosen on them."""


class Decisions(Protocol):
    """What makes an evaluation's decisions: a fresh decision source for each batch of ``n`` episodes, planning with
    ``generator``; ``device`` is where its networks run (a torch generator lives there)."""

    device: torch.device

    def source(self, n: int, generator: torch.Generator) -> DecisionSource: ...


def generator(device: torch.device, seed: int) -> torch.Generator:
    return torch.Generator(device=device).manual_seed(seed)


@dataclass
class PlannerDecisions:
    """A planner's decisions (:class:`~bridgeplan.replan.PlanSource`) with ``nfe`` network calls per plan, executed
    as ``execution`` says, in ``family``'s environment ``env`` (its goal radius and wall map)."""

    planner: Planner
    nfe: int
    execution: Execution
    family: Family
    env: str
    batch_size: int | None = None
    prior_only: bool = False
    measure_residuals: bool = False

    @property
    def device(self) -> torch.device:
        return self.planner.device

    def source(self, n: int, generator: torch.Generator) -> PlanSource:
        return PlanSource(self.planner, self.execution, self.nfe, generator, n, self.family.goal_radius,
                          self.family.free(self.env), self.batch_size, self.prior_only, self.measure_residuals)


@dataclass
class FixedPlans:
    """Plans made beforehand (``[episodes, S, obs_dim]``, one per episode, in the tasks' order), for one run of the
    tasks: each batch takes the next plans."""

    plans: np.ndarray
    device: torch.device = torch.device("cpu")
    taken: int = 0

    def source(self, n: int, generator: torch.Generator | None = None) -> DecisionSource:
        plans = np.asarray(self.plans, np.float64)[self.taken:self.taken + n]
        self.taken += n

        def decide(states, goals, episodes, t):
            return plans[episodes]

        return decide


def execute_plans(tasks: Tasks, plans: np.ndarray, execution: Execution | None = None):
    """``plans`` (``[episodes, S, obs_dim]``, one per episode) executed open loop on ``tasks`` by ``execution``'s
    controller (default: tracked); returns the family's outcome (Maze2D: returns, success, states)."""
    family = family_of(tasks.env)
    plans = np.asarray(plans, np.float64)
    obs_dim = family.layout(tasks.env).obs_dim
    if plans.ndim != 3 or plans.shape[2] != obs_dim or len(plans) != tasks.episodes:
        raise BridgeplanError(f"plans must have shape [N, S, {obs_dim}] with N = {tasks.episodes} episodes, got "
                              f"{list(plans.shape)}")
    execution = (execution or Execution()).resolved(family, tasks.env)
    return run_episodes(FixedPlans(plans), family, tasks, execution).outcome


@dataclass
class Episodes:
    """One run of a family's tasks with decisions: what happened (``outcome``, the family's) and the executor that
    made it (its plans and timings)."""

    outcome: object
    executor: PlanExecutor

    def cost(self, candidates: int = 1) -> dict:
        """Plans and network calls per episode (the decisions' and the controllers'), milliseconds per plan, every
        decision's latency in its batch."""
        ex = self.executor
        made = ex.plans_made
        calls = (sum(int(np.sum(getattr(s, "calls", 0))) for s in ex.sources)
                 + sum(int(np.sum(c)) for c in ex.follower_calls))
        sampled = sum(getattr(s, "plans_sampled", 0) for s in ex.sources)
        seconds = sum(getattr(s, "plan_seconds", 0.0) for s in ex.sources)
        per_batch = percentiles_ms(ex.decision_seconds)
        per_batch["mean_batch"] = float(np.mean(ex.decision_batch)) * candidates
        return {"plans_per_episode": {"mean": float(made.mean()), "min": int(made.min()), "max": int(made.max())},
                "calls_per_episode": float(calls / len(made)),
                "plan_ms_per_plan": 1000.0 * seconds / sampled if sampled else 0.0,
                "decision_ms_per_batch": per_batch, "step_ms": percentiles_ms(ex.step_seconds)}


def followers(family: Family, tasks: Tasks, execution: Execution,
              follower: Callable[[int], Follower] | None = None) -> Callable[[int], Follower]:
    """``follower`` (``n`` -> the controllers of ``n`` episodes) if given (a policy low level's), else the
    family's controllers of ``execution``'s kind."""
    return follower or (lambda n: family.follower(tasks.env, n, execution.controller, execution.lookahead))


def run_episodes(decisions: Decisions, family: Family, tasks: Tasks, execution: Execution, seed: int | None = None,
                 warm_up: Callable | None = None, progress: bool = False, run: Callable | None = None,
                 follower: Callable[[int], Follower] | None = None) -> Episodes:
    """Every episode of ``tasks``, decided by ``decisions`` (one generator seeded ``seed``, default the tasks',
    across the batches) and executed as ``execution`` says by ``family``'s controllers (or ``follower``'s), in
    ``run(tasks, agent, progress)`` (default ``family.run``; ``render``: its film)."""
    gen = generator(decisions.device, tasks.seed if seed is None else seed)
    executor = PlanExecutor.executing(execution, lambda n: decisions.source(n, gen),
                                      followers(family, tasks, execution, follower), warm_up)
    return Episodes((run or family.run)(tasks, executor, progress), executor)


def batch1_latency(decisions: Decisions, family: Family, tasks: Tasks, execution: Execution,
                   follower: Callable[[int], Follower] | None = None) -> tuple[dict, dict]:
    """Latency at batch 1 (p50/p95/mean ms) of a decision and of a whole step (observation to action: the decision
    when one is due, then the controller's action): the first episode of ``tasks`` run again alone by a fresh source
    (its generator seeded with the tasks' seed + 1), after one untimed decision on its first state (then forgotten),
    every one of its decisions and steps timed."""
    gen = generator(decisions.device, tasks.seed + 1)
    lone = decisions.source(1, gen)

    def warm_up(states, goals, episodes, t):
        lone(states, goals, episodes, t)
        if hasattr(lone, "reset"):
            lone.reset()

    executor = PlanExecutor.executing(execution, lambda n: lone, followers(family, tasks, execution, follower),
                                      warm_up)
    family.run(tasks.first(), executor)
    return percentiles_ms(executor.decision_seconds), percentiles_ms(executor.step_seconds)


@dataclass
class EvalResult:
    """One evaluation: decisions on one set of tasks, scored by their family.

    ``to_dict`` is the JSON every evaluation command writes: what was evaluated (``entries``: the run, the method,
    its settings), the tasks (their family's fields), the score (their family's), the floors, the execution, the
    cost and latency, where it ran, and the run's portable config."""

    family: Family
    tasks: Tasks
    entries: dict
    scores: dict
    """The family's score fields (``Family.score``)."""
    floors: dict
    execution: dict
    cost: dict
    environment: dict
    config: dict | None = None
    extra: dict = field(default_factory=dict)
    """What a kind of decisions adds (a hierarchy's levels, the dataset graph's size, a correction's cost)."""
    planner: Planner | None = None

    def to_dict(self) -> dict:
        return {**self.entries, **self.tasks.fields(), **self.scores, **self.floors, "execution": self.execution,
                **self.cost, **self.extra, "environment": self.environment, "config": self.config}


def environment_of(device: torch.device) -> dict:
    """The machine a result was made on: its CPU too, since the same code and seeds give other floating-point
    results, and so other episodes, on another CPU (docs/results/rerun)."""
    return {"device": str(device), "torch": torch.__version__, "machine": platform.machine(),
            "processor": platform.processor() or platform.machine(), "cpu": cpu_model(),
            "cpu_threads": torch.get_num_threads(), "code_version": code_version()}


def prior_floor(planner: Planner, family: Family, tasks: Tasks, execution: Execution,
                prior_name: str | None = None) -> dict:
    """The tasks executed from a prior's sample alone (no network): ``prior_name``'s (default the planner's own),
    as ``execution`` says."""
    if prior_name is not None:
        planner = planner.with_prior(make_prior(prior_name, planner.normalizer, planner.layout, stride=planner.stride))
    decisions = PlannerDecisions(planner, 1, execution, family, tasks.env, prior_only=True)
    episodes = run_episodes(decisions, family, tasks, execution)
    return {"prior": planner.prior.name, **family.floor_score(tasks, episodes.outcome)}


def floors(planner: Planner, family: Family, tasks: Tasks, execution: Execution) -> dict[str, dict]:
    """What the planner must beat on ``tasks``: the straight line (``floor_line``) and, for a prior that is neither
    noise nor the line, that prior's sample (``prior_only_<name>``); executed as the planner is where its family
    says so (``Family.floor_replans``), else open loop with its controller."""
    if not family.floor_replans:
        execution = Execution(controller=execution.controller, lookahead=execution.lookahead,
                              arrival_default=execution.arrival_default)
    out = {"floor_line": prior_floor(planner, family, tasks, execution, "line")}
    if planner.prior.name not in ("gaussian", "line"):
        out[f"prior_only_{planner.prior.name}"] = prior_floor(planner, family, tasks, execution)
    return out


def planner_entries(planner: Planner, nfe: int, run: RunInfo | None) -> dict:
    """What a planner's evaluation names: its run, its method and settings."""
    process = planner.process
    return {"run": run.name if run else None, "dataset": run.dataset if run else None,
            "step": run.step if run else None, "train_seconds": run.elapsed_seconds if run else None,
            "method": cfg.method_label(process, planner.prior.name, run.config.hold_share if run else 0.0),
            "process": process.name, "prior": planner.prior.name, "process_params": portable_process(process.to_dict()),
            "diffusion_steps": process.steps, "nfe": nfe, "horizon": planner.horizon, "stride": planner.stride,
            "plan_span": span(planner.horizon, planner.stride)}


def evaluate(decisions: Decisions, family: Family, tasks: Tasks, execution: Execution, entries: dict,
             floors: dict | None = None, candidates: int = 1, warm_up: Callable | None = None,
             after_run: Callable[[Episodes], None] | None = None, progress: bool = False,
             follower: Callable[[int], Follower] | None = None) -> tuple[EvalResult, Episodes]:
    """The one evaluation: ``decisions`` on ``tasks`` of ``family``, executed as ``execution`` says (resolved for
    the family: :meth:`Execution.resolved`) by the family's controllers, or by ``follower``'s (a policy low level's);
    ``entries`` name what is evaluated, ``floors`` are what it must beat. ``after_run(episodes)`` hears the episodes
    before the batch-1 latency's lone episode runs. Returns the result and the episodes (their outcome and executor,
    for what a kind of decisions adds)."""
    execution.validate(None, tasks.episode_steps)
    episodes = run_episodes(decisions, family, tasks, execution, warm_up=warm_up, progress=progress,
                            follower=follower)
    if after_run is not None:
        after_run(episodes)
    decision, step = batch1_latency(decisions, family, tasks, execution, follower)
    cost = {**episodes.cost(candidates), "decision_ms_batch1": decision, "step_ms_batch1": step}
    described = {**execution.to_dict(entries.get("prior") or ""), **episodes.executor.follower.described()}
    result = EvalResult(family, tasks, entries, family.score(tasks, episodes.outcome), floors or {}, described, cost,
                        environment_of(decisions.device))
    return result, episodes


def evaluate_planner(planner: Planner, tasks: Tasks, nfe: int | None = None, run: RunInfo | None = None,
                     batch_size: int | None = None, compiled: bool = False,
                     precomputed_floors: dict[str, dict] | None = None, execution: Execution | None = None,
                     floor: bool = True, progress: bool = False) -> EvalResult:
    """Score ``planner`` on ``tasks`` (of its environment's family) with ``nfe`` network calls per plan (default:
    the process's most).

    ``batch_size``: plans per network batch (default: all the episodes due at once). ``compiled``: the network is
    ``torch.compile``'d; it is compiled in an untimed warm-up decision first, with a generator of its own, so the
    plans and the planning time are those of the compiled network alone. ``precomputed_floors``: :func:`floors` of
    the same planner's prior on the same tasks, to skip them (``floor``: False skips them too). ``execution``:
    replanning, candidates, arrival rule, controller (default: open loop, tracked).
    """
    family = family_of(tasks.env)
    nfe = planner.process.max_nfe if nfe is None else nfe
    planner.process.validate_nfe(nfe)
    if batch_size is not None and batch_size <= 0:
        raise BridgeplanError(f"batch size must be positive, got {batch_size}")
    execution = (execution or Execution()).resolved(family, tasks.env)
    execution.validate(planner.process, tasks.episode_steps)
    residuals = execution.plans_once and planner.layout.has_velocity  # the plans as sampled: open loop
    decisions = PlannerDecisions(planner, nfe, execution, family, tasks.env, batch_size,
                                 measure_residuals=residuals)
    warm_up = None
    compile_seconds = None
    if compiled:  # every batch shape of the first decision; replans at other shapes compile when they first occur
        warm = PlannerDecisions(planner, nfe, execution, family, tasks.env, batch_size)

        def warm_up(states, goals, episodes, t):
            warm.source(len(states), generator(planner.device, 0))(states, goals, episodes, t)

    if precomputed_floors is None:
        precomputed_floors = floors(planner, family, tasks, execution) if floor else {}
    result, episodes = evaluate(decisions, family, tasks, execution, planner_entries(planner, nfe, run),
                                precomputed_floors, execution.candidates, warm_up)
    if compiled:
        compile_seconds = episodes.executor.warm_up_seconds
    m, n = execution.candidates, tasks.episodes
    prior_seconds = sum(s.prior_seconds for s in episodes.executor.sources)
    sampled = sum(s.plans_sampled for s in episodes.executor.sources)
    c = planner.correction
    result.cost.update({
        "prior_ms_per_plan": 1000.0 * prior_seconds / sampled, "batch_size": min(batch_size or n * m, n * m),
        "compiled": compile_seconds is not None, "compile_seconds": compile_seconds or 0.0,
        "frozen": isinstance(planner.model, FrozenUNet),
        "candidate_plans_per_episode": float(episodes.executor.plans_made.mean() * m)})
    result.extra.update({
        "correction": None if c is None else c.to_dict(nfe),
        "network_call_equivalents_per_plan": nfe if c is None else c.network_call_equivalents(nfe),
        "plan_residuals": _residuals(episodes.executor.sources) if residuals else None})
    result.config, result.planner = (run.portable_config if run else None), planner
    return result


def _residuals(sources: list[PlanSource]) -> dict:
    """Mean and standard error over the plans of each ``Plan.residuals`` (m/s) the sources collected."""
    keys = dict.fromkeys(k for s in sources for k in s.residuals)
    return {k: _mean_se(np.concatenate([v for s in sources for v in s.residuals.get(k, [])])) for k in keys}


def _mean_se(values: np.ndarray) -> dict[str, float]:
    values = np.asarray(values, dtype=np.float64)
    se = float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else float("nan")
    return {"mean": float(values.mean()), "se": se}


def make_tasks(env: str, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
               task_ids: tuple[int, ...] | None = None) -> Tasks:
    """``env``'s family's evaluation tasks (:meth:`~bridgeplan.envs.family.Family.tasks`)."""
    if episodes is not None and episodes <= 0:
        raise BridgeplanError(f"episodes must be positive, got {episodes}")
    if seed < 0:
        raise BridgeplanError(f"the tasks' seed must be >= 0, got {seed}")
    return family_of(env).tasks(env, episodes, seed, multi_task, task_ids)


def run_tasks(info: RunInfo, episodes: int | None = None, seed: int = 0, multi_task: bool = False,
              task_ids: tuple[int, ...] | None = None) -> Tasks:
    """The tasks a loaded run is evaluated on: its environment's, refused where its data cannot have prepared it
    (``Family.check_run_data``)."""
    tasks = make_tasks(info.config.maze, episodes, seed, multi_task, task_ids)
    family_of(info.config.maze).check_run_data(tasks, info.config.dataset, info.dataset_covers_every_cell)
    return tasks


def evaluate_run(run: Path, episodes: int | None = None, nfe: int | None = None, seed: int = 0,
                 multi_task: bool = False, task_ids: tuple[int, ...] | None = None, batch_size: int | None = None,
                 snapshot: int | None = None, device: str = "auto", sampler: str | None = None, eta: float = 0.0,
                 compile: bool = False, execution: Execution | None = None, correction: Correction | None = None,
                 floor: bool = True, frozen: bool = False) -> EvalResult:
    """Load a trained run (or one of its snapshots) of any family and :func:`evaluate_planner` it on its
    environment's seeded tasks (``execution``: closed loop, candidates, arrival; default open loop; ``correction``: a
    consistency correction of the x0 predictions, ``consistency.Correction``; ``frozen``: through the network traced
    and frozen, ``runs.load_planner``)."""
    planner, info = load_planner(run, snapshot=snapshot, device=device, sampler=sampler, eta=eta, compile=compile,
                                 frozen=frozen)
    planner = planner.with_correction(correction)
    tasks = run_tasks(info, episodes, seed, multi_task, task_ids)
    return evaluate_planner(planner, tasks, nfe, run=info, batch_size=batch_size, compiled=compile,
                            execution=execution, floor=floor)


def check_result_path(out: str | Path | None, default_dir: Path) -> None:
    """Before anything is evaluated: the JSON's path can be written (``out``, a file; else ``default_dir``, where the
    result is named by its settings). :class:`BridgeplanError` otherwise."""
    if out:
        check_writable(out, "evaluation JSON")
    else:
        check_writable(default_dir, "evaluation folder", folder=True)


def write_result(result: dict, path: Path) -> None:
    atomic_write_text(path, json.dumps(result, indent=2) + "\n")


def write_and_show(result: dict, path: Path, as_json: bool, summary: str) -> None:
    """An evaluation command's ending: ``result`` written to ``path``, then printed as JSON (``--json``), else
    its human-readable ``summary`` and where it went."""
    write_result(result, path)
    print(json.dumps(result, indent=2) if as_json else f"{summary}\nwrote {path}")


def format_table(r: dict) -> str:
    """Human-readable summary of one evaluation (:meth:`EvalResult.to_dict`), for any family."""
    ex = r.get("execution") or {}
    how = ex.get("controller", "")
    if ex.get("lookahead") is not None:
        how += f" (lookahead {ex['lookahead']:g})"
    replans = [text.format(ex[key]) for key, text in (("replan_every", "every {} steps"),
                                                       ("replan_tolerance", "past {:g} from the plan"),
                                                       ("replan_after_step", "{} steps after a first step ends"),
                                                       ("replan_object_tolerance",
                                                        "past {:g} of an object from the plan"))
               if ex.get(key) is not None]
    how += f", replan {', '.join(replans)}" if replans else ", open loop"
    tasks = (f"{r['episodes_per_task']} episodes per task" if "episodes_per_task" in r
             else f"{r['episodes']} episodes" + (", multi-task" if r.get("multi_task") else ""))
    nfe = "" if r.get("nfe") is None else f", NFE {r['nfe']}"  # a policy's: one call per step, no plans
    lines = [f"{r.get('run')} (step {r.get('step')}): {r.get('method')}{nfe}, {how}",
             f"  {tasks}, seed {r['seed']}"]
    if isinstance(r.get("score"), dict):
        s = r["score"]
        lines += [f"  normalized score (minari): {s['minari']['mean']:7.1f} ± {s['minari']['se']:.1f}",
                  f"  normalized score (d4rl):   {s['d4rl']['mean']:7.1f} ± {s['d4rl']['se']:.1f}",
                  f"  success rate:              {r['success_rate']['mean']:7.3f}"]
    else:
        for i, t in r.get("tasks", {}).items():
            task = f"{tuple(t['init_cell'])} -> {tuple(t['goal_cell'])}" if "init_cell" in t else t["task_name"]
            lines.append(f"  task {i} {task}: {t['success_rate']:6.1%} "
                         f"({t['successes']}/{t['episodes']}), mean steps {np.mean(t['steps']):.0f}")
        lines.append(f"  overall: {r['success_rate']:.1%} ({r['successes']}/{r['episodes']})")
    b1, pb, p = r["decision_ms_batch1"], r["decision_ms_per_batch"], r["plans_per_episode"]
    lines.append(f"  plans per episode {p['mean']:.1f} ({r['calls_per_episode']:.1f} network calls per episode); "
                 f"{r['plan_ms_per_plan']:.2f} ms per plan in batches")
    if b1["p50"] is not None:
        lines.append(f"  decision latency: batch 1 p50 {b1['p50']:.2f} ms, p95 {b1['p95']:.2f} ms; per batch "
                     f"({pb['mean_batch']:.0f} plans) p50 {pb['p50']:.2f} ms")
    if (s1 := r.get("step_ms_batch1")) and s1["p50"] is not None:
        lines.append(f"  a step at batch 1 (observation to action): p50 {s1['p50']:.2f} ms, p95 {s1['p95']:.2f} ms")
    c = r.get("correction")
    if c is not None:
        lines.append(f"  correction:                {c['tag']}: {c['network_call_equivalents_per_plan']} "
                     f"network-call equivalents per plan ({c['forward_passes_per_plan']} forward, "
                     f"{c['backward_passes_per_plan']} backward passes)")
    if r.get("plan_residuals"):
        res = r["plan_residuals"]
        lines.append(f"  plan residuals (rms, m/s): kinematics {res['kinematics_rms']['mean']:.3f}, "
                     f"dynamics {res['dynamics_rms']['mean']:.3f}")
    for key in [k for k in r if k.startswith(("floor_", "prior_only_"))]:
        f = r[key]
        rate = f["success_rate"]["mean"] if isinstance(f["success_rate"], dict) else f["success_rate"]
        score = (f" {f['score']['minari']['mean']:.1f} ± {f['score']['minari']['se']:.1f} (minari),"
                 if "score" in f else "")
        lines.append(f"  {key} (no network, executed alike):{score} success {rate:.3f}")
    return "\n".join(lines)
