"""A trained planner as a policy on OGBench's evaluation protocol (``bridgeplan ogbench eval``).

:class:`PlanningPolicy` is the batched ``act(observations, goals)`` that
:func:`~bridgeplan.envs.ogbench_pointmaze.protocol.evaluate_policy` calls once per step: at an episode's first step it
plans from the observed position to the goal (all the batch's episodes in one network batch), then executes
the plan with a controller (:mod:`bridgeplan.envs.ogbench_pointmaze.controllers`); with ``replan_every`` K it plans
again from the current position every K steps, so an episode of T steps gets ``ceil(T / K)`` plans. Plans come
from one torch generator seeded with the evaluation seed, so unlike the protocol's episodes a plan depends on
the batch it was sampled in (the same run, settings and seed give the same result).

Why no arrival rule as in Maze2D's closed loop (:mod:`bridgeplan.replan`): the evaluation environment ends an
episode as soon as the point is within 1.0 of the goal, so a plan that passes the goal early ends the episode
there, and nothing needs to hold it. What replanning cannot fix is the one :mod:`bridgeplan.replan` describes: each
plan is conditioned to arrive at its last state, a full span after it is made, so under ``track`` every replan
stretches what is left of the path over another span (the point slows down), and a plan for a goal closer than
a span of the data's motion spends the surplus moving (loops, detours), which a replan every K < span steps may
cut off before it passes the goal.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from bridgeplan.envs.ogbench_pointmaze.controllers import DEFAULT_LOOKAHEAD, PointFollower, check_controller
from bridgeplan.envs.ogbench_pointmaze.names import EVAL_EPISODE_STEPS, parse_dataset_name
from bridgeplan.errors import BridgeplanError
from bridgeplan.planner import Planner
from bridgeplan.trajectory import KINEMATIC_POINT, Layout, span


@dataclass(frozen=True)
class PointExecution:
    """How plans are executed: ``controller`` (``track`` or ``pursuit``, with its ``lookahead``) and
    ``replan_every`` (K steps; None: open loop, one plan per episode)."""

    controller: str = "track"
    lookahead: float = DEFAULT_LOOKAHEAD
    replan_every: int | None = None

    def validate(self) -> None:
        check_controller(self.controller, self.lookahead)
        if self.replan_every is not None and not 1 <= self.replan_every <= EVAL_EPISODE_STEPS:
            raise BridgeplanError(f"--replan-every must be in 1..{EVAL_EPISODE_STEPS} (the episode length), "
                                  f"got {self.replan_every}")

    def to_dict(self) -> dict:
        return {"mode": "open_loop" if self.replan_every is None else "closed_loop",
                "replan_every": self.replan_every, "controller": self.controller,
                "lookahead": self.lookahead if self.controller == "pursuit" else None}

    def tag(self) -> str:
        """A file-name part: ``track``, ``pursuit2``, ``track-replan50``."""
        parts = [self.controller + (f"{self.lookahead:g}" if self.controller == "pursuit" else "")]
        if self.replan_every is not None:
            parts.append(f"replan{self.replan_every}")
        return "-".join(parts)


@dataclass
class PlanningPolicy:
    """``planner`` as a batched policy (``nfe`` network calls per plan), executing its plans as ``execution``
    says. Pass :meth:`begin_batch` and :meth:`end_episodes` to ``evaluate_policy`` as its hooks. With
    ``decisions`` and no planner (the dataset graph's paths, ``graph.GraphSource``), plans need no network."""

    planner: Planner | None
    nfe: int
    execution: PointExecution
    generator: torch.Generator
    plans_per_episode: list[int] = field(default_factory=list)
    """Plans made for each finished batch's episodes, in protocol order."""
    plan_seconds: float = 0.0
    """Prior and sampler wall time of every plan (summed over batches)."""
    plans_sampled: int = 0
    decision_seconds: list[float] = field(default_factory=list)
    """Wall time of every call that planned (the whole call: plans, then actions)."""
    decision_batch: list[int] = field(default_factory=list)
    """Plans made in each of those calls."""
    step_seconds: list[float] = field(default_factory=list)
    """Wall time of every call (one per environment step of a batch)."""
    prior_only: bool = False
    """Execute the prior's sample itself (no network): the floor a planner must beat."""
    decisions: Callable[[int], Callable] | None = None
    """A hierarchy's decisions instead of ``planner``'s plans: given a batch's size n, the callable
    ``(states, goals, episodes, t) -> planned states`` (``hierarchy.HierarchySource``) that plans for it."""

    def __post_init__(self):
        self.execution.validate()
        if self.planner is not None:
            self.planner.process.validate_nfe(self.nfe)
        elif self.decisions is None:
            raise BridgeplanError("a planning policy needs a planner or decisions")
        self._n = 0

    @property
    def layout(self) -> Layout:
        return self.planner.layout if self.planner is not None else KINEMATIC_POINT

    def begin_batch(self, n: int) -> None:
        """A batch of ``n`` new episodes starts: each plans at its first step."""
        self._flush()
        self._n = n
        self._plans: np.ndarray | None = None
        self._age = np.zeros(n, dtype=np.int64)
        self._active = np.ones(n, dtype=bool)
        self._made = np.zeros(n, dtype=np.int64)
        self._follower = PointFollower(n, self.execution.controller, self.execution.lookahead)
        self._t = 0
        self._decide = self.decisions(n) if self.decisions is not None else None

    def end_episodes(self, rows: np.ndarray) -> None:
        """Rows ``rows`` of the batch have ended: they plan no more."""
        self._active[rows] = False

    def finish(self) -> None:
        """Record the last batch's plans per episode (after the protocol has run)."""
        self._flush()
        self._n = 0

    def _flush(self) -> None:
        if self._n:
            self.plans_per_episode.extend(self._made.tolist())

    def _due(self) -> np.ndarray:
        if self._plans is None:
            return np.arange(self._n)
        every = self.execution.replan_every
        return np.flatnonzero(self._active & (self._age >= every)) if every is not None else np.zeros(0, np.int64)

    def __call__(self, observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        if len(observations) != self._n:
            raise BridgeplanError(f"the policy was called on {len(observations)} episodes, its batch has {self._n} "
                                  f"(begin_batch was not called)")
        t0 = time.perf_counter()
        due = self._due()
        if len(due):
            positions = (self.plan(observations[due], goals[due]) if self._decide is None
                         else self.decide(observations[due], goals[due], due))
            if self._plans is None:
                self._plans = positions
            else:  # a plan's span is fixed, so replans fit the same array
                self._plans[due] = positions
            self._age[due] = 0
            self._made[due] += 1
            self._follower.new_plans(due)
        actions = self._follower.actions(observations, self._plans, self._age)
        self._age += 1
        self._t += 1
        seconds = time.perf_counter() - t0
        self.step_seconds.append(seconds)
        if len(due):
            self.decision_seconds.append(seconds)
            self.decision_batch.append(len(due))
        return actions

    def plan(self, positions: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """Planned positions ``[N, S, 2]`` (one per step) from ``positions`` to ``goals`` ``[N, 2]``."""
        layout = self.planner.layout
        plan = self.planner.plan(layout.at_rest(positions), goals, self.nfe, self.generator,
                                 prior_only=self.prior_only)
        self.plan_seconds += plan.prior_seconds + plan.sample_seconds
        self.plans_sampled += len(positions)
        return np.array(layout.state_positions(plan.states), dtype=np.float64)


    def decide(self, positions: np.ndarray, goals: np.ndarray, episodes: np.ndarray) -> np.ndarray:
        """Planned positions ``[N, S, 2]`` from the decisions (a hierarchy's, the graph's) for ``episodes``."""
        layout = self.layout
        t0 = time.perf_counter()
        states = self._decide(layout.at_rest(positions), goals, episodes, self._t)
        self.plan_seconds += time.perf_counter() - t0
        self.plans_sampled += len(positions)
        return np.array(layout.state_positions(states), dtype=np.float64)


def expected_plans(steps: int, replan_every: int | None) -> int:
    """Plans an episode of ``steps`` steps gets: 1 open loop, else ``ceil(steps / K)`` (at steps 0, K, 2K, ...)."""
    return 1 if replan_every is None else math.ceil(steps / replan_every)


def batch1_latency(planner: Planner, nfe: int, start: np.ndarray, goal: np.ndarray, seed: int,
                   repeats: int = 5) -> dict:
    """One plan at batch 1 (a decision of a lone episode), timed ``repeats`` times after one untimed plan."""
    from bridgeplan.replan import percentiles_ms

    gen = torch.Generator(device=planner.device).manual_seed(seed + 1)
    starts, goals = planner.layout.at_rest(start[None]), goal[None]
    planner.plan(starts, goals, nfe, gen)
    seconds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        planner.plan(starts, goals, nfe, gen)
        seconds.append(time.perf_counter() - t0)
    return percentiles_ms(seconds)


def _protocol(policy: PlanningPolicy, maze: str, episodes_per_task: int, seed: int, task_ids, progress: bool):
    """Run the protocol with ``policy``; returns the result and the first episode's start and goal (what the
    batch-1 latency plans)."""
    from bridgeplan.envs.ogbench_pointmaze.protocol import evaluate_policy

    first: list[np.ndarray] = []

    def act(observations: np.ndarray, goals: np.ndarray) -> np.ndarray:
        if not first:
            first.extend([observations[0].copy(), goals[0].copy()])
        return policy(observations, goals)

    result = evaluate_policy(maze, act, episodes_per_task=episodes_per_task, seed=seed, task_ids=task_ids,
                             progress=progress, on_batch_start=policy.begin_batch, on_episodes_end=policy.end_episodes)
    policy.finish()
    return result, first


def _floor_line(planner: Planner, nfe: int, execution: PointExecution, maze: str, episodes_per_task: int, seed: int,
                task_ids) -> dict:
    """The same episodes planned by the straight line start -> goal at ``planner``'s shape, no network, executed
    alike. Why: the kinematic point slides along walls, so stepping toward the goal through them already solves
    some tasks; what the planner adds is over that."""
    from bridgeplan.envs.ogbench_pointmaze.protocol import evaluate_policy
    from bridgeplan.priors import make_prior

    line = planner.with_prior(make_prior("line", planner.normalizer, planner.layout, stride=planner.stride))
    policy = PlanningPolicy(line, nfe, execution, torch.Generator(device=planner.device).manual_seed(seed),
                            prior_only=True)
    f = evaluate_policy(maze, policy, episodes_per_task=episodes_per_task, seed=seed, task_ids=task_ids,
                        on_batch_start=policy.begin_batch, on_episodes_end=policy.end_episodes)
    return {"floor_line": {"success_rate": f.success_rate, "tasks": {i: t.success_rate for i, t in f.tasks.items()}}}


def _row(result, policy: PlanningPolicy, execution: PointExecution, episodes_per_task: int, seed: int) -> dict:
    """The protocol's result and the policy's plans and timings, as every planner's JSON has them."""
    from bridgeplan.replan import percentiles_ms

    made = np.asarray(policy.plans_per_episode)
    per_batch = percentiles_ms(policy.decision_seconds)
    per_batch["mean_batch"] = float(np.mean(policy.decision_batch))
    protocol = result.to_dict()
    return {"env_id": result.env_id, "execution": execution.to_dict(), "episodes_per_task": episodes_per_task,
            "seed": seed, "success_rate": protocol["success_rate"], "successes": protocol["successes"],
            "episodes": protocol["episodes"], "tasks": protocol["tasks"],
            "plans_per_episode": {"mean": float(made.mean()), "min": int(made.min()), "max": int(made.max())},
            "plan_ms_per_plan": 1000.0 * policy.plan_seconds / policy.plans_sampled,
            "decision_ms_per_batch": per_batch, "step_ms": percentiles_ms(policy.step_seconds),
            "protocol_seconds": result.seconds}


def _check_episodes(episodes_per_task: int) -> None:
    if episodes_per_task <= 0:
        raise BridgeplanError(f"--episodes-per-task must be positive, got {episodes_per_task}")


def evaluate_run(run: Path, nfe: int | None = None, execution: PointExecution | None = None,
                 episodes_per_task: int = 50, seed: int = 0, task_ids: list[int] | None = None,
                 device: str = "auto", snapshot: int | None = None, progress: bool = False,
                 floor: bool = True) -> dict:
    """Load an OGBench pointmaze run and score it on its maze's protocol; returns the result as
    ``bridgeplan ogbench eval`` writes it (every setting, success per task and overall, cost and latency, the
    run's portable config and the code version). ``floor``: also the straight line alone (:func:`_floor_line`)."""
    from bridgeplan.envs.ogbench_pointmaze import FAMILY
    from bridgeplan.evaluate import environment_of
    from bridgeplan.runs import load_planner, require_family

    execution = execution or PointExecution()
    execution.validate()
    _check_episodes(episodes_per_task)
    planner, info = load_planner(run, snapshot=snapshot, device=device)
    require_family(info, FAMILY)
    nfe = planner.process.max_nfe if nfe is None else nfe
    spec = parse_dataset_name(info.config.maze)
    policy = PlanningPolicy(planner, nfe, execution, torch.Generator(device=planner.device).manual_seed(seed))
    result, first = _protocol(policy, spec.maze, episodes_per_task, seed, task_ids, progress)
    row = _row(result, policy, execution, episodes_per_task, seed)
    floors = _floor_line(planner, nfe, execution, spec.maze, episodes_per_task, seed, task_ids) if floor else {}
    process, config = planner.process, info.config
    return {
        "run": info.name, "step": info.step, "train_seconds": info.elapsed_seconds,
        "dataset": config.maze, "maze": spec.maze, "method": config.label(),
        "process": process.name, "prior": planner.prior.name, "process_params": process.to_dict(),
        "diffusion_steps": process.steps, "nfe": nfe, "horizon": planner.horizon, "stride": planner.stride,
        "plan_span": span(planner.horizon, planner.stride), **row,
        "calls_per_episode": float(nfe * np.mean(policy.plans_per_episode)),
        "decision_ms_batch1": batch1_latency(planner, nfe, first[0], first[1], seed),
        **floors, "environment": environment_of(planner), "config": info.portable_config,
    }


def _lone_decisions(decide, state: np.ndarray, goal: np.ndarray, every: int, count: int = 6) -> list[float]:
    """Seconds of ``count`` decisions of a lone episode (``decide(states, goals, episodes, t)`` at t = 0, every,
    ...): its first one also plans the coarse level (a hierarchy's) or searches the graph."""
    seconds = []
    for t in range(0, count * every, every):
        t0 = time.perf_counter()
        decide(state, goal, np.arange(1), t)
        seconds.append(time.perf_counter() - t0)
    return seconds


def evaluate_hierarchy_run(high_run: Path, low_run: Path, nfe_high: int | None = None, nfe_low: int | None = None,
                           execution: PointExecution | None = None, replan_high_every: int | None = None,
                           episodes_per_task: int = 50, seed: int = 0, task_ids: list[int] | None = None,
                           device: str = "auto", progress: bool = False, floor: bool = True) -> dict:
    """Two OGBench pointmaze runs as a hierarchy (``bridgeplan.hierarchy``: the high level's coarse plan, the low
    level through its next coarse states, replanned every ``execution.replan_every`` steps; the high level again
    every ``replan_high_every``) on the maze's protocol; returns what ``bridgeplan ogbench hierarchy-eval`` writes:
    as ``ogbench eval``'s JSON, with ``method`` naming both levels, ``nfe`` the low level's, and each level's
    settings under ``high`` and ``low``. ``floor``: the straight line alone at the high level's shape."""
    from bridgeplan.envs.ogbench_pointmaze import FAMILY
    from bridgeplan.evaluate import environment_of
    from bridgeplan.hierarchy import Hierarchy, HierarchySource, check_high_replanning, level_dict
    from bridgeplan.replan import percentiles_ms
    from bridgeplan.runs import load_planner, require_family

    execution = execution or PointExecution()
    execution.validate()
    _check_episodes(episodes_per_task)
    if execution.replan_every is None:
        raise BridgeplanError("a hierarchy replans its low level as the agent moves: give --replan-every K (one "
                              "high-level step, the high level's stride, is the natural K)")
    check_high_replanning(replan_high_every, EVAL_EPISODE_STEPS)
    high, high_info = load_planner(high_run, device=device)
    low, low_info = load_planner(low_run, device=device)
    for info in (high_info, low_info):
        require_family(info, FAMILY)
    if high_info.config.maze != low_info.config.maze:
        raise BridgeplanError(f"the levels were trained on different datasets ({high_info.config.maze} and "
                              f"{low_info.config.maze})")
    hierarchy = Hierarchy(high, low)
    gen = torch.Generator(device=high.device).manual_seed(seed)
    sources: list[HierarchySource] = []

    def decisions(n: int) -> HierarchySource:
        sources.append(HierarchySource(hierarchy, nfe_high, nfe_low, gen, n, replan_high_every))
        return sources[-1]

    probe = HierarchySource(hierarchy, nfe_high, nfe_low, gen, 1)  # the NFE defaults, checked before any episode
    nfe_high, nfe_low = probe.nfe_high, probe.nfe_low
    spec = parse_dataset_name(high_info.config.maze)
    policy = PlanningPolicy(low, nfe_low, execution, gen, decisions=decisions)
    result, first = _protocol(policy, spec.maze, episodes_per_task, seed, task_ids, progress)
    row = _row(result, policy, execution, episodes_per_task, seed)
    floors = (_floor_line(high, high.process.max_nfe, PointExecution(execution.controller, execution.lookahead),
                          spec.maze, episodes_per_task, seed, task_ids) if floor else {})
    lone = HierarchySource(hierarchy, nfe_high, nfe_low, torch.Generator(device=high.device).manual_seed(seed + 1), 1,
                           replan_high_every)
    seconds = _lone_decisions(lone, low.layout.at_rest(first[0][None]), first[1][None], execution.replan_every)
    label = f"hierarchy {high_info.config.label()} H{high.horizon}k{high.stride} -> {low_info.config.label()} " \
            f"H{low.horizon}k{low.stride}"
    return {
        "kind": "hierarchy", "run": f"{high_info.name} + {low_info.name}", "step": low_info.step,
        "dataset": high_info.config.maze, "maze": spec.maze, "method": label, "nfe": nfe_low,
        "horizon": low.horizon, "stride": low.stride, "plan_span": span(low.horizon, low.stride),
        "high": level_dict(high, high_info, nfe_high), "low": level_dict(low, low_info, nfe_low),
        "replan_high_every": replan_high_every, **row,
        "calls_per_episode": float(sum(s.calls.sum() for s in sources) / result.to_dict()["episodes"]),
        "decision_ms_batch1": percentiles_ms(seconds[1:]),
        **floors, "environment": environment_of(high), "config": low_info.portable_config,
    }


def evaluate_graph(name: str, dataset: Path, graph_settings: dict | None = None,
                   execution: PointExecution | None = None, episodes_per_task: int = 50, seed: int = 0,
                   task_ids: list[int] | None = None, progress: bool = False, low_run: Path | None = None,
                   nfe_low: int | None = None, replan_high_every: int | None = None, device: str = "auto") -> dict:
    """The dataset graph (``graph.DatasetGraph`` over dataset ``name``'s file ``dataset``, built with
    ``graph_settings``: keep, radius, neighbours, reach) on the maze's protocol; returns what ``bridgeplan ogbench
    graph-eval`` writes: ``ogbench eval``'s JSON with the graph's size and its paths.

    Alone, its paths are executed as plans (replanned from the current position every ``execution.replan_every``
    steps if given). With ``low_run`` (a planner trained with ``--subgoal-every``), the graph is a hierarchy's high
    level (``hierarchy.GraphHierarchy``): the low level plans through its path's next states every
    ``execution.replan_every`` steps, the path searched again every ``replan_high_every`` steps if given."""
    from bridgeplan.envs.ogbench_pointmaze import FAMILY
    from bridgeplan.envs.ogbench_pointmaze.reading import load_stream
    from bridgeplan.evaluate import environment_of
    from bridgeplan.files import code_version
    from bridgeplan.graph import DEFAULTS, GraphSource, for_stream
    from bridgeplan.hierarchy import GraphHierarchy, HierarchySource, check_high_replanning, level_dict
    from bridgeplan.replan import percentiles_ms
    from bridgeplan.runs import load_planner, require_family

    execution = execution or PointExecution()
    execution.validate()
    _check_episodes(episodes_per_task)
    spec = parse_dataset_name(name)
    low = low_info = None
    if low_run is not None:
        if execution.replan_every is None:
            raise BridgeplanError("a low level replans as the agent moves: give --replan-every K (its subgoal "
                                  "spacing is the natural K)")
        check_high_replanning(replan_high_every, EVAL_EPISODE_STEPS)
        low, low_info = load_planner(low_run, device=device)
        require_family(low_info, FAMILY)
        if parse_dataset_name(low_info.config.maze).maze != spec.maze:
            raise BridgeplanError(f"the low level was trained on {low_info.config.maze}, another maze than {name}")
    elif nfe_low is not None or replan_high_every is not None:
        raise BridgeplanError("--nfe-low and --replan-high-every are the low level's: give --low RUN")
    settings = {**DEFAULTS, **(graph_settings or {})}
    stream = load_stream(dataset, name)
    t0 = time.perf_counter()
    graph = for_stream(stream, settings)
    build_seconds = time.perf_counter() - t0
    if low is None:
        def decisions(n: int):
            return GraphSource(graph, EVAL_EPISODE_STEPS + 1)
        policy = PlanningPolicy(None, 0, execution, torch.Generator(), decisions=decisions)
    else:
        hierarchy = GraphHierarchy(graph, low, EVAL_EPISODE_STEPS)
        gen = torch.Generator(device=low.device).manual_seed(seed)
        sources: list[HierarchySource] = []

        def decisions(n: int):
            sources.append(HierarchySource(hierarchy, None, nfe_low, gen, n, replan_high_every))
            return sources[-1]

        nfe_low = HierarchySource(hierarchy, None, nfe_low, gen, 1).nfe_low  # the default, checked before any episode
        policy = PlanningPolicy(low, nfe_low, execution, gen, decisions=decisions)
    result, first = _protocol(policy, spec.maze, episodes_per_task, seed, task_ids, progress)
    row = _row(result, policy, execution, episodes_per_task, seed)
    graph_row = {**settings, **graph.summary(), "build_seconds": build_seconds}  # the protocol's queries only
    lone = (GraphSource(graph, EVAL_EPISODE_STEPS + 1) if low is None else
            HierarchySource(hierarchy, None, nfe_low, torch.Generator(device=low.device).manual_seed(seed + 1), 1,
                            replan_high_every))
    seconds = _lone_decisions(lone, first[0][None], first[1][None], execution.replan_every or 1)
    config = {"dataset": name, "dataset_identity": stream.identity(), "graph": settings}
    if low is None:
        return {"kind": "graph", "run": f"graph over {name}", "step": 0, "dataset": name, "maze": spec.maze,
                "method": "dataset graph", "nfe": 0, "horizon": EVAL_EPISODE_STEPS + 1, "stride": 1,
                "plan_span": EVAL_EPISODE_STEPS, **row, "calls_per_episode": 0.0,
                "decision_ms_batch1": percentiles_ms(seconds), "graph": graph_row,
                "environment": {"code_version": code_version()}, "config": config}
    label = f"dataset graph -> {low_info.config.label()} H{low.horizon}k{low.stride}"
    return {"kind": "graph", "run": f"graph over {name} + {low_info.name}", "step": low_info.step, "dataset": name,
            "maze": spec.maze, "method": label, "nfe": nfe_low, "horizon": low.horizon, "stride": low.stride,
            "plan_span": span(low.horizon, low.stride), "low": level_dict(low, low_info, nfe_low),
            "replan_high_every": replan_high_every, **row,
            "calls_per_episode": float(sum(s.calls.sum() for s in sources) / result.to_dict()["episodes"]),
            "decision_ms_batch1": percentiles_ms(seconds[1:]), "graph": graph_row,
            "environment": environment_of(low), "config": {**config, "low": low_info.portable_config}}


def format_result(r: dict) -> str:
    """The table ``bridgeplan ogbench eval`` prints."""
    ex = r["execution"]
    how = ex["controller"] + (f" (lookahead {ex['lookahead']:g})" if ex["lookahead"] is not None else "")
    how += ", open loop" if ex["replan_every"] is None else f", replan every {ex['replan_every']} steps"
    lines = [f"{r['run']} (step {r['step']}) on {r['env_id']}: {r['method']}, NFE {r['nfe']}, {how}",
             f"  plans of {r['horizon']} states, stride {r['stride']} ({r['plan_span']} steps); "
             f"{r['episodes_per_task']} episodes per task, seed {r['seed']}"]
    for i, t in r["tasks"].items():
        lines.append(f"  task {i} {tuple(t['init_cell'])} -> {tuple(t['goal_cell'])}: {t['success_rate']:6.1%} "
                     f"({t['successes']}/{t['episodes']}), mean steps {np.mean(t['steps']):.0f}")
    b1, pb, p = r["decision_ms_batch1"], r["decision_ms_per_batch"], r["plans_per_episode"]
    lines += [f"  overall: {r['success_rate']:.1%} ({r['successes']}/{r['episodes']})",
              f"  plans per episode {p['mean']:.1f} ({r['calls_per_episode']:.1f} network calls per episode); "
              f"{r['plan_ms_per_plan']:.2f} ms per plan in batches",
              f"  decision latency: batch 1 p50 {b1['p50']:.1f} ms; per batch ({pb['mean_batch']:.0f} plans) "
              f"p50 {pb['p50']:.1f} ms; per step p50 {r['step_ms']['p50']:.2f} ms; protocol "
              f"{r['protocol_seconds']:.0f} s"]
    if "floor_line" in r:
        f = r["floor_line"]
        lines.append(f"  floor (the straight line, no network, executed alike): {f['success_rate']:.1%} "
                     f"(tasks " + ", ".join(f"{v:.0%}" for v in f["tasks"].values()) + ")")
    return "\n".join(lines)
