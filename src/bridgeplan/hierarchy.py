"""Hierarchical planning: a coarse plan over the whole episode, refined stretch by stretch by a low level.

The high level is an ordinary planner whose states lie far apart (a long ``stride``, Hierarchical Diffuser's
jump): one plan spans the episode, from the start to the goal. The low level is a planner trained with
``subgoal_every = j`` (``TrainConfig``): its every j-th planned state is a condition, so it plans from the
current state through the next ``m = (H - 1) / j`` states of the coarse plan; its prior is either noise
(DDPM inpainting the subgoals, as Hierarchical Diffuser does) or the coarse plan itself, densified
(``coarse``: the line through the subgoals, which a bridge or flow refines). The levels fit when a low-level
subgoal step is one high-level step: ``low.subgoal_every * low.stride == high.stride``.

Executed closed loop (:class:`HierarchySource` is the decision source of ``replan.PlanExecutor``, in any family):
the high level plans at an episode's first step (and again from the current state every ``replan_high_every``
steps, if given: on large that is what pays, docs/results/hierarchy.md), and its plan holds the goal from its
first arrival on (a plan conditioned to end at the goal fills its whole span, however short the way: a high
level trained with holds, ``hold_share``, may arrive early instead); every decision, the low level plans from
the current state through the coarse states that follow the one nearest the agent (searched forward from the
last, so progress never runs back), the goal at rest repeating once the coarse plan runs out.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, ClassVar

import numpy as np
import torch

from bridgeplan import config as cfg
from bridgeplan.envs import Family, family_of
from bridgeplan.envs.controllers import check_controller
from bridgeplan.envs.family import Tasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import EvalResult, evaluate, execute_plans, prior_floor
from bridgeplan.graph import DatasetGraph, fixed_length
from bridgeplan.planner import Planner
from bridgeplan.replan import Execution, check_replanning, truncate_at_arrival
from bridgeplan.runs import RunInfo, load_planner, portable_process
from bridgeplan.trajectory import densify, span

COARSE_ARRIVAL = 0.45
"""How close to the goal a coarse plan has arrived (it holds the goal from there on): Maze2D's goal radius, in every
family, as the committed hierarchies were made."""


@dataclass(frozen=True)
class Hierarchy:
    """Two planners that fit (:func:`check_levels`)."""

    high: Planner
    low: Planner
    progress_rule: ClassVar[str] = "nearest"
    """How :class:`HierarchySource` advances along a coarse plan (:meth:`HierarchySource.advance`)."""

    def __post_init__(self):
        check_levels(self.high, self.low)

    @property
    def spacing(self) -> int:
        """Steps between coarse states: the high level's stride."""
        return self.high.stride

    @property
    def subgoals_per_plan(self) -> int:
        return self.low.subgoals_per_plan

    def points(self, states: np.ndarray) -> np.ndarray:
        """Where states are along a coarse plan (:meth:`HierarchySource.advance`): their positions."""
        return self.low.layout.state_positions(states)

    def resolve_high_nfe(self, nfe: int | None) -> int:
        """Network calls per coarse plan: ``nfe``, checked, or (None) the high level's process's most."""
        nfe = self.high.process.max_nfe if nfe is None else nfe
        self.high.process.validate_nfe(nfe)
        return nfe

    def coarse_plans(self, starts: np.ndarray, goals: np.ndarray, nfe: int,
                     generator: torch.Generator) -> tuple[np.ndarray, float]:
        """The high level's plans ``[N, H_high, obs_dim]`` (physical states at its planned indices, not
        densified), each cut at its first state within 0.45 of the goal and holding the goal from there on
        (``replan.truncate_at_arrival``: a high level trained with holds may arrive early), and the seconds its
        prior and sampler took."""
        plan = self.high.plan(starts, goals, nfe, generator)
        traj = self.high.normalizer.unnormalize(plan.sampled.double().cpu().numpy())
        traj, _ = truncate_at_arrival(traj, goals, self.high.layout, COARSE_ARRIVAL)
        return self.high.layout.states(traj), plan.prior_seconds + plan.sample_seconds

    def subgoals(self, coarse: np.ndarray, progress: np.ndarray) -> np.ndarray:
        return next_subgoals(coarse, progress, self.subgoals_per_plan)

    def high_entry(self, info: RunInfo, nfe: int) -> dict:
        """The high level's entry in the hierarchy's JSON."""
        return level_dict(self.high, info, nfe)

    def label(self, info: RunInfo) -> str:
        """The high level's part of the hierarchy's name in tables."""
        return f"hierarchy {info.config.label()} H{self.high.horizon}k{self.high.stride}"

    def line_floor(self, family: Family, tasks: Tasks, execution: Execution) -> dict:
        """``floor_line``: the straight line over the high level's span, executed open loop by the hierarchy's
        controller."""
        open_loop = Execution(controller=execution.controller, lookahead=execution.lookahead,
                              arrival_default=execution.arrival_default)
        return {"floor_line": prior_floor(self.high, family, tasks, open_loop, "line")}


@dataclass
class GraphHierarchy:
    """The dataset graph as the high level of a hierarchy over ``low`` (a planner trained with
    ``--subgoal-every``): coarse plans are the graph's paths, one state every ``low.subgoal_every * low.stride``
    steps, as many as cover ``episode_steps`` (the goal repeated past the path's end); no network call."""

    graph: DatasetGraph
    low: Planner
    episode_steps: int
    progress_rule: ClassVar[str] = "sequential"
    """The data's paths wind, passing near their own later states across walls: progress along them moves one
    coarse state at a time (:meth:`HierarchySource.advance`), never skipping ahead to a nearer later one."""

    def __post_init__(self):
        if not self.low.subgoal_every:
            raise BridgeplanError("the low level must plan between subgoals: train it with --subgoal-every J")
        if self.low.layout != self.graph.layout:
            raise BridgeplanError(f"the dataset graph holds {self.graph.layout.name} states; the low level plans "
                                  f"in {self.low.layout.name} (a planner of another environment)")

    @property
    def spacing(self) -> int:
        """Steps between coarse states: the low level's subgoal spacing."""
        return self.low.subgoal_every * self.low.stride

    @property
    def coarse_length(self) -> int:
        return self.episode_steps // self.spacing + 2

    @property
    def subgoals_per_plan(self) -> int:
        return self.low.subgoals_per_plan

    def points(self, states: np.ndarray) -> np.ndarray:
        """Where states are along a coarse plan: their points in the graph's space (a maze's positions; an arm's
        effector and objects, standardized)."""
        return self.graph.space.point(states)

    def resolve_high_nfe(self, nfe: int | None) -> int:
        if nfe not in (None, 0):
            raise BridgeplanError("the dataset graph calls no network: it takes no high-level NFE")
        return 0

    def coarse_plans(self, starts: np.ndarray, goals: np.ndarray, nfe: int,
                     generator) -> tuple[np.ndarray, float]:
        """``[N, coarse_length, obs_dim]`` each episode's path from states ``starts`` to positions ``goals``, every
        :attr:`spacing`-th state (its last, the goal at rest, kept), and the seconds the searches took."""
        t0 = time.perf_counter()
        out = np.empty((len(starts), self.coarse_length, self.graph.layout.obs_dim))
        for k, (s, g) in enumerate(zip(np.asarray(starts, np.float64), np.asarray(goals, np.float64))):
            path = self.graph.path(s, g)
            coarse = path[::self.spacing]
            if len(path) - 1 > (len(coarse) - 1) * self.spacing:
                coarse = np.concatenate([coarse, path[-1:]])
            out[k] = fixed_length(coarse, self.coarse_length)
        return out, time.perf_counter() - t0

    def subgoals(self, coarse: np.ndarray, progress: np.ndarray) -> np.ndarray:
        return next_subgoals(coarse, progress, self.subgoals_per_plan)

    def high_entry(self, settings: dict, nfe: int = 0) -> dict:
        """The high level's entry in a hierarchy's JSON (as :func:`level_dict` a planner's): the graph's
        ``settings``, its size and what its queries so far found."""
        return {"run": "dataset graph", "step": 0, "method": "dataset graph", "process": "graph", "nfe": 0,
                "horizon": self.coarse_length, "stride": self.spacing, "subgoal_every": None,
                "graph": {**settings, **self.graph.summary()}}

    def label(self, settings: dict) -> str:
        return "dataset graph"

    def line_floor(self, family, tasks, execution) -> dict:
        """None: the graph has no span for a straight line to fill."""
        return {}


def next_subgoals(coarse: np.ndarray, progress: np.ndarray, m: int) -> np.ndarray:
    """``[N, m, obs_dim]``: the ``m`` coarse states after index ``progress [N]``, the last one repeated past the
    plan's end (the goal at rest: a coarse plan's last state is its goal)."""
    index = np.minimum(progress[:, None] + 1 + np.arange(m)[None, :], coarse.shape[1] - 1)
    return np.take_along_axis(coarse, index[..., None], axis=1)


def check_levels(high: Planner, low: Planner) -> None:
    """Levels whose shapes do not fit raise BridgeplanError (the CLI's one-line ``error:``)."""
    if high.layout != low.layout:
        raise BridgeplanError(f"the levels plan in different environments ({high.layout.name} and "
                              f"{low.layout.name}): a hierarchy is two runs of one environment")
    if high.subgoal_every:
        raise BridgeplanError("the high level must plan from a start to a goal: it was trained with "
                              f"--subgoal-every {high.subgoal_every} (that is a low level)")
    if not low.subgoal_every:
        raise BridgeplanError("the low level must plan between subgoals: train it with --subgoal-every J")
    step = low.subgoal_every * low.stride
    if step != high.stride:
        raise BridgeplanError(f"the levels do not fit: the low level's subgoals are {low.subgoal_every} x stride "
                              f"{low.stride} = {step} environment steps apart, the high level's states "
                              f"{high.stride} (they must be equal)")
    if span(low.horizon, low.stride) > span(high.horizon, high.stride):
        raise BridgeplanError(f"the low level spans {span(low.horizon, low.stride)} steps, longer than the high "
                              f"level's {span(high.horizon, high.stride)}")


@dataclass
class HierarchySource:
    """The decisions of a :class:`Hierarchy`, for a batch of ``n`` episodes.
    (Or over any high level with its interface: ``low``, ``spacing``, ``subgoals_per_plan``, ``progress_rule``,
    ``resolve_high_nfe``, ``coarse_plans``, ``subgoals``, ``high_entry``, ``line_floor``; e.g.
    :class:`GraphHierarchy`, the dataset graph's paths.)

    Returns the low level's plans (densified, physical states). With ``replan_high_every`` K, an episode's coarse
    plan is made again from its current state at its first decision K or more steps after the last one (its
    progress back to 0). Counts network calls per episode (``calls [n]``: ``nfe_high`` per coarse plan,
    ``nfe_low`` per low-level plan) and times every decision.
    """

    hierarchy: Hierarchy  # or another high level with its interface (above)
    nfe_high: int | None
    """Network calls per coarse plan (None: the high level's process's most)."""
    nfe_low: int | None
    """Network calls per low-level plan (None: the low level's process's most)."""
    generator: torch.Generator
    n: int
    replan_high_every: int | None = None
    coarse: np.ndarray | None = None
    """``[n, H_high, obs_dim]`` each episode's coarse plan (None before the first decision)."""
    first_coarse: np.ndarray | None = None
    """The coarse plans of the first decision (``coarse`` before any replan of the high level)."""
    first_goals: np.ndarray | None = None
    """The goals of the first decision."""
    coarse_at: np.ndarray | None = None
    """``[n]`` the step each episode's coarse plan was made at."""
    progress: np.ndarray | None = None
    """``[n]`` the coarse index each episode has reached."""
    calls: np.ndarray = field(init=False)
    high_seconds: float = 0.0
    low_seconds: float = 0.0
    low_plans: int = 0
    high_plans: int = 0

    def __post_init__(self):
        low = self.hierarchy.low.process
        self.nfe_high = self.hierarchy.resolve_high_nfe(self.nfe_high)
        self.nfe_low = low.max_nfe if self.nfe_low is None else self.nfe_low
        low.validate_nfe(self.nfe_low)
        self.calls = np.zeros(self.n, dtype=np.int64)

    @property
    def plan_seconds(self) -> float:
        return self.high_seconds + self.low_seconds

    @property
    def plans_sampled(self) -> int:
        return self.low_plans

    def reset(self) -> None:
        """Forget the coarse plans (a new episode); counters and timings are kept."""
        self.coarse = self.first_coarse = self.first_goals = self.coarse_at = self.progress = None

    def plan_coarse(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> None:
        """New coarse plans for ``episodes`` from their ``states``; their progress starts again at 0."""
        coarse, seconds = self.hierarchy.coarse_plans(states, goals, self.nfe_high, self.generator)
        if self.coarse is None:
            self.coarse, self.first_coarse, self.first_goals = coarse, coarse.copy(), np.array(goals, np.float64)
            self.progress = np.zeros(self.n, dtype=np.int64)
            self.coarse_at = np.zeros(self.n, dtype=np.int64)
        self.coarse[episodes], self.progress[episodes], self.coarse_at[episodes] = coarse, 0, t
        self.calls[episodes] += self.nfe_high
        self.high_seconds += seconds
        self.high_plans += len(episodes)

    def advance(self, states: np.ndarray, episodes: np.ndarray) -> np.ndarray:
        """Move each episode's progress along its coarse plan, by the hierarchy's ``progress_rule``, measured at the
        hierarchy's ``points`` of ``states`` and of the plan: ``nearest``, to the coarse state nearest among the next
        ``m + 1``; ``sequential``, one coarse state at a time while the next is no farther than the current (a plan
        that winds back near itself across a wall, as the data's paths do, is not skipped along)."""
        coarse, progress = self.coarse[episodes], self.progress[episodes].copy()
        positions = self.hierarchy.points(states)
        xy, last, rows = self.hierarchy.points(coarse), coarse.shape[1] - 1, np.arange(len(episodes))
        if self.hierarchy.progress_rule == "sequential":
            while True:
                after = np.minimum(progress + 1, last)
                move = (after > progress) & (np.linalg.norm(xy[rows, after] - positions, axis=1)
                                             <= np.linalg.norm(xy[rows, progress] - positions, axis=1))
                if not move.any():
                    break
                progress[move] += 1
        else:
            window = np.minimum(progress[:, None] + np.arange(self.hierarchy.subgoals_per_plan + 1)[None, :], last)
            near = np.take_along_axis(xy, window[..., None], axis=1)
            progress = window[rows, np.linalg.norm(near - positions[:, None], axis=2).argmin(axis=1)]
        self.progress[episodes] = progress
        return progress

    def __call__(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> np.ndarray:
        h = self.hierarchy
        if self.coarse is None:
            if len(episodes) != self.n:
                raise BridgeplanError("the first decision must be made for every episode")
            self.plan_coarse(states, goals, episodes, t)
        elif self.replan_high_every is not None:
            due = np.flatnonzero(t - self.coarse_at[episodes] >= self.replan_high_every)
            if len(due):
                self.plan_coarse(states[due], goals[due], episodes[due], t)
        progress = self.advance(states, episodes)
        plan = h.low.plan(states, None, self.nfe_low, self.generator,
                          subgoals=h.subgoals(self.coarse[episodes], progress))
        self.calls[episodes] += self.nfe_low
        self.low_seconds += plan.prior_seconds + plan.sample_seconds
        self.low_plans += len(episodes)
        return plan.states


def check_execution(execution: Execution, episode_steps: int) -> None:
    """What a hierarchy executes: a low level replanned every K steps (and/or on drift), one candidate, plans
    as sampled; bad settings raise BridgeplanError."""
    check_replanning(execution.replan_every, execution.tolerance, episode_steps)
    check_controller(execution.controller, execution.lookahead)
    if not execution.replans:
        raise BridgeplanError("a hierarchy replans its low level as the agent moves: give --replan-every K "
                              "(one high-level step, the high level's stride, is the natural K)")
    if execution.candidates != 1 or execution.warm or execution.arrival is not None:
        raise BridgeplanError("a hierarchy plans one candidate per decision, from its own prior, as sampled "
                              "(no --candidates, --prior warm or --arrival)")


def check_high_replanning(every: int | None, episode_steps: int) -> None:
    if every is not None and not 1 <= every <= episode_steps:
        raise BridgeplanError(f"--replan-high-every must be in 1..{episode_steps} (the episode length), got {every}")


def load_hierarchy(high_run: Path, low_run: Path, high_snapshot: int | None = None, low_snapshot: int | None = None,
                   device: str = "auto") -> tuple[Hierarchy, RunInfo, RunInfo]:
    """Two runs of one environment as a :class:`Hierarchy` (EMA weights of their latest checkpoints or of the
    snapshots)."""
    high, high_info = load_planner(Path(high_run), snapshot=high_snapshot, device=device)
    low, low_info = load_planner(Path(low_run), snapshot=low_snapshot, device=device)
    if high_info.config.maze != low_info.config.maze:
        raise BridgeplanError(f"the levels were trained on different environments ({high_info.config.maze} and "
                              f"{low_info.config.maze})")
    return Hierarchy(high, low), high_info, low_info


def level_dict(planner: Planner, info: RunInfo, nfe: int) -> dict:
    """One level's settings in a hierarchy's JSON."""
    return {"run": info.name, "step": info.step, "method": cfg.method_label(planner.process, planner.prior.name),
            "process": planner.process.name, "prior": planner.prior.name,
            "process_params": portable_process(planner.process.to_dict()), "nfe": nfe, "horizon": planner.horizon,
            "stride": planner.stride, "subgoal_every": planner.subgoal_every, "config": info.portable_config}


def coarse_diagnostics(dense: np.ndarray, goals: np.ndarray, free, layout) -> dict:
    """What limits the coarse plans ``dense [N, S, obs_dim]`` (densified, physical; measured with the environment's
    wall map ``free``, which no planner reads): ``in_walls``, the share of their positions inside walls or outside
    the maze, and ``arrival_step``, the mean step at which they first come within :data:`COARSE_ARRIVAL` of the goal
    (S - 1 when never); the first two None where the family has no wall map."""
    given = layout.given_columns  # the goal's columns (a position, or a manipulation task's objects)
    near = np.linalg.norm(dense[..., given] - layout.goal_states(goals)[:, None, given], axis=2) <= COARSE_ARRIVAL
    arrival = np.where(near.any(axis=1), near.argmax(axis=1), dense.shape[1] - 1)
    if free is None:
        return {"in_walls": None, "crossing_walls": None, "arrival_step": float(arrival.mean())}
    positions = layout.state_positions(dense)
    inside = ~free(positions.reshape(-1, 2)).reshape(positions.shape[:2])
    return {"in_walls": float(inside.mean()), "crossing_walls": float(inside.any(axis=1).mean()),
            "arrival_step": float(arrival.mean())}


@dataclass
class HierarchyDecisions:
    """A hierarchy's decisions (:class:`HierarchySource`) for :func:`bridgeplan.evaluate.evaluate`."""

    hierarchy: Hierarchy | GraphHierarchy
    nfe_high: int | None
    nfe_low: int | None
    replan_high_every: int | None = None

    @property
    def device(self) -> torch.device:
        return self.hierarchy.low.device

    def source(self, n: int, generator: torch.Generator) -> HierarchySource:
        return HierarchySource(self.hierarchy, self.nfe_high, self.nfe_low, generator, n, self.replan_high_every)


def evaluate_hierarchy(hierarchy: Hierarchy | GraphHierarchy, high_info: RunInfo | dict, low_info: RunInfo,
                       tasks: Tasks, nfe_high: int | None = None, nfe_low: int | None = None,
                       execution: Execution | None = None, replan_high_every: int | None = None,
                       progress: bool = False) -> EvalResult:
    """Score ``hierarchy`` on ``tasks`` (of its environment's family): the JSON of ``bridgeplan hierarchy eval`` (and
    of ``bridgeplan graph --low``). ``hierarchy``: two planners, or the dataset graph over a low level
    (:class:`GraphHierarchy`, whose ``high_info`` is the graph's settings).

    ``execution``: the low level's replanning and controller (default: every coarse step, the family's path controller);
    ``replan_high_every``: the high level plans again every that many steps (None: once per episode). Beside the
    hierarchy's score: ``high_alone``, the first coarse plans densified and executed open loop by the same
    controller (what the low level adds), ``coarse_plans`` (how they lie against the walls) and, for a planner as
    the high level, ``floor_line``, the straight line over its span so executed.
    """
    family = family_of(tasks.env)
    low = hierarchy.low
    execution = (execution or Execution(replan_every=hierarchy.spacing, controller=family.path_controller)).resolved(
        family, tasks.env)
    check_execution(execution, tasks.episode_steps)
    check_high_replanning(replan_high_every, tasks.episode_steps)
    decisions = HierarchyDecisions(hierarchy, nfe_high, nfe_low, replan_high_every)
    probe = decisions.source(1, torch.Generator(device=low.device))  # the NFE defaults, checked before any episode
    nfe_high, nfe_low = probe.nfe_high, probe.nfe_low
    graph = isinstance(hierarchy, GraphHierarchy)
    entries = {"kind": "graph" if graph else "hierarchy",
               "run": f"{hierarchy.high_entry(high_info, nfe_high)['run']} + {low_info.name}", "step": low_info.step,
               "method": f"{hierarchy.label(high_info)} -> {low_info.config.label()} H{low.horizon}k{low.stride}",
               "prior": low.prior.name, "nfe": nfe_low, "horizon": low.horizon, "stride": low.stride,
               "plan_span": span(low.horizon, low.stride)}
    seen = {}  # the high level's entry after the evaluation's episodes (the graph's queries: not the lone episode's)
    result, episodes = evaluate(decisions, family, tasks, execution, entries,
                                hierarchy.line_floor(family, tasks, execution),
                                after_run=lambda _: seen.update(high=hierarchy.high_entry(high_info, nfe_high)),
                                progress=progress)
    sources = episodes.executor.sources
    dense = densify(np.concatenate([s.first_coarse for s in sources]), hierarchy.spacing)
    goals = np.concatenate([s.first_goals for s in sources])
    alone = execute_plans(tasks, dense, Execution(controller=execution.controller, lookahead=execution.lookahead))
    result.execution["replan_high_every"] = replan_high_every
    result.extra.update({
        "high": seen["high"], "low": level_dict(low, low_info, nfe_low), "replan_high_every": replan_high_every,
        "high_alone": family.floor_score(tasks, alone),
        "coarse_plans": coarse_diagnostics(dense, goals, family.free(tasks.env), low.layout),
        "high_ms_per_plan": 1000.0 * sum(s.high_seconds for s in sources) / max(sum(s.high_plans for s in sources), 1),
        "low_ms_per_plan": 1000.0 * sum(s.low_seconds for s in sources) / max(sum(s.low_plans for s in sources), 1)})
    result.config = low_info.portable_config
    return result


def graph_hierarchy(low_run: Path, dataset: str | None = None, settings: dict | None = None,
                    low_snapshot: int | None = None, device: str = "auto", episode_steps: int | None = None,
                    env: str | None = None):
    """The dataset graph (over ``dataset``, default the low level's own training data) as the high level of a low
    level (:class:`GraphHierarchy`, the graph of :func:`bridgeplan.graph.for_stream` with ``settings`` over its
    family's); returns the hierarchy, the high level's JSON entry (the graph's settings, the data's identity, the
    build's seconds) and the low level's info; ``env``: the environment it must be of."""
    from bridgeplan.graph import for_stream

    low, low_info = load_planner(Path(low_run), snapshot=low_snapshot, device=device)
    if env is not None and low_info.config.maze != env:
        raise BridgeplanError(f"the low level was trained on {low_info.config.maze}, not {env}: the graph and the "
                              f"low level are of one environment")
    env = low_info.config.maze
    family = family_of(env)
    stream = family.load_stream(dataset or low_info.config.dataset, env)
    t0 = time.perf_counter()
    graph, settings = for_stream(stream, family, settings)
    hierarchy = GraphHierarchy(graph, low, episode_steps or family.longest_span(env))
    settings = {**settings, "build_seconds": time.perf_counter() - t0, "dataset_identity": stream.identity()}
    return hierarchy, settings, low_info


POLICY_AHEAD = 25
"""A policy low level's goal: the graph's path this many steps on (``bridgeplan graph --low`` a GCBC or GCIQL run).
Chosen on cube-single's validation tasks (6-10, 10 episodes each, GCIQL seed 0 at 20 k steps, the path searched again
every 50 steps; studies/manip-cube-single.toml)."""


def check_graph_low(low_run, policy_low: bool, nfe_low: int | None, replan_high_every: int | None,
                    policy_ahead: int | None) -> None:
    """The dataset graph's low-level options fit its low level: a planner's (``low_run`` not ``policy_low``), a
    policy's or none."""
    if (low_run is None or policy_low) and (nfe_low is not None or replan_high_every is not None):
        raise BridgeplanError("--nfe-low and --replan-high-every are a planner low level's: " + (
            "give --low RUN" if low_run is None else
            "a policy acts at every step toward the graph's path, searched again every --replan-every steps"))
    if policy_ahead is not None and not policy_low:
        raise BridgeplanError("--policy-ahead is a policy low level's: give --low a GCBC or GCIQL run")


@dataclass
class GraphAgent:
    """The dataset graph's decisions and, over a policy, the follower that executes them (:func:`graph_agent`)."""

    decisions: object
    """A :class:`bridgeplan.graph.GraphDecisions`: paths from the current states to the goals."""
    follower: Callable | None
    """``follower(n)``: the policy's :class:`~bridgeplan.envs.controllers.PolicyFollower` over ``n`` episodes; None:
    the execution's controller executes the paths."""
    settings: dict
    """The graph's settings (the family's, under those given)."""
    identity: dict
    """The data's identity."""
    build_seconds: float
    ahead: int | None
    """The policy's goal: the path's state this many steps on (None: no policy)."""


def graph_agent(env: str, dataset: str, length: int, settings: dict | None = None, policy=None, objects: bool = False,
                ahead: int | None = None, hand: bool = False) -> GraphAgent:
    """The dataset graph over ``dataset`` (of ``env``; :func:`bridgeplan.graph.for_stream`, ``objects``: one per
    object; ``hand``: --hand), its paths ``length`` states long, executed by ``policy`` (a GCBC or GCIQL run's,
    :func:`bridgeplan.gcbc.run_policy`; its goal the path's state ``ahead`` steps on, default :data:`POLICY_AHEAD`)
    or, without one, by the execution's controller: what ``bridgeplan graph`` evaluates and
    ``PlannerPolicy.from_graph`` acts by."""
    from bridgeplan.envs.controllers import PolicyFollower
    from bridgeplan.graph import GraphDecisions, for_stream

    family = family_of(env)
    if policy is not None and policy.dataset_identity and not Path(dataset).exists():
        raise BridgeplanError(f"no dataset {dataset}: the shipped policy's graph is over the data it was scored on, "
                              f"made by `bridgeplan data generate --maze {env}`")
    stream = family.load_stream(dataset, env)
    if policy is not None and policy.dataset_identity and Path(dataset) == Path(policy.dataset) and (
            stream.identity() != policy.dataset_identity):
        raise BridgeplanError(f"{dataset} is {stream.identity()}, not the data the shipped policy was scored over "
                              f"({policy.dataset_identity}): make it again with `bridgeplan data generate --maze "
                              f"{env} --force`, or give another dataset on purpose (--dataset)")
    t0 = time.perf_counter()
    graph, settings = for_stream(stream, family, settings, objects, hand)
    build_seconds = time.perf_counter() - t0
    if policy is None:
        return GraphAgent(GraphDecisions(graph, length), None, settings, stream.identity(), build_seconds, None)
    ahead = POLICY_AHEAD if ahead is None else ahead
    return GraphAgent(GraphDecisions(graph, length), lambda n: PolicyFollower(n, family.body(env), policy.act, ahead),
                      settings, stream.identity(), build_seconds, ahead)


def evaluate_graph(tasks: Tasks, dataset: str, settings: dict | None = None, execution: Execution | None = None,
                   low_run: Path | None = None, nfe_low: int | None = None, replan_high_every: int | None = None,
                   low_snapshot: int | None = None, device: str = "auto", progress: bool = False,
                   picture: Callable | None = None, objects: bool = False,
                   policy_ahead: int | None = None, hand: bool = False) -> EvalResult:
    """The dataset graph over ``dataset`` (of ``tasks``' environment; ``bridgeplan.graph``, built with ``settings``
    over its family's) on ``tasks``: the JSON of ``bridgeplan graph``, with the graph's settings, size and what its
    queries found (``graph``) and the data's identity (``config``).

    Alone, its paths are executed as plans (replanned from the current state every ``execution.replan_every`` steps
    if given). With ``low_run`` (a planner of that environment trained with ``--subgoal-every``), the graph is a
    hierarchy's high level (:class:`GraphHierarchy`, :func:`evaluate_hierarchy`): the low level plans through its
    path's next states every ``execution.replan_every`` steps (default: its subgoal spacing), the path searched
    again every ``replan_high_every`` steps if given. With ``low_run`` a GCBC or GCIQL run (``gcbc train``), its
    policy executes the graph's paths (:class:`~bridgeplan.envs.controllers.PolicyFollower`: its goal the path's state
    ``policy_ahead`` steps on, default :data:`POLICY_AHEAD`), the paths searched again every
    ``execution.replan_every`` steps as alone. ``picture(decisions, tasks, execution, follower)`` (the graph alone
    or over a policy) hears the graph's decisions after the evaluation (``bridgeplan graph --render``).
    ``objects``: the graph alone or over a policy, one per object or part (:func:`bridgeplan.graph.for_stream`;
    ``hand``: some parts' graphs over the hand's opening too)."""
    from bridgeplan.gcbc import is_gcbc_run, run_policy

    env, family = tasks.env, family_of(tasks.env)
    policy_low = low_run is not None and is_gcbc_run(low_run)
    check_graph_low(low_run, policy_low, nfe_low, replan_high_every, policy_ahead)
    policy = run_policy(low_run, low_snapshot, device, env) if policy_low else None
    if low_run is None or policy is not None:
        agent = graph_agent(env, dataset, tasks.episode_steps + 1, settings, policy, objects, policy_ahead, hand)
        graph, settings = agent.decisions.graph, agent.settings
        execution = (execution or Execution()).resolved(family, env)
        method = "dataset graph" + (f", {graph.kind}" if objects else "") + (
            f", {policy.config.agent.upper()} low level" if policy else "")
        entries = {"kind": "graph", "run": f"graph over {env}", "step": 0, "method": method, "nfe": 0,
                   "horizon": agent.decisions.length, "stride": 1, "plan_span": tasks.episode_steps}
        seen = {}
        result, _ = evaluate(agent.decisions, family, tasks, execution, entries,
                             after_run=lambda _: seen.update(graph=graph.summary()), progress=progress,
                             follower=agent.follower)
        result.extra["graph"] = {**settings, **seen["graph"], "build_seconds": agent.build_seconds}
        result.config = {"dataset": env, "dataset_identity": agent.identity,
                         "graph": {**settings, "objects": True, **({"hand": True} if hand else {})} if objects
                         else settings}
        if policy is not None:
            result.extra["low"] = {"run": Path(low_run).name, "agent": policy.config.agent, "step": policy.step,
                                   "ahead": agent.ahead}
            result.config["low"] = {**dataclasses.asdict(policy.config),
                                    "dataset": Path(policy.config.dataset).stem}  # named, no path of this machine
        if picture is not None:
            picture(agent.decisions, tasks, execution, agent.follower)
        return result
    hierarchy, high, low_info = graph_hierarchy(low_run, dataset, settings, low_snapshot, device, tasks.episode_steps,
                                                env)
    if execution is not None and execution.replan_every is None:  # the low level replans every subgoal step
        execution = dataclasses.replace(execution, replan_every=hierarchy.spacing)
    result = evaluate_hierarchy(hierarchy, high, low_info, tasks, None, nfe_low, execution, replan_high_every,
                                progress)
    graph = result.extra["high"]["graph"]
    result.extra["graph"] = {k: v for k, v in graph.items() if k != "dataset_identity"}
    settings = {k: graph[k] for k in ("keep", "radius", "neighbours", "reach")}
    result.config = {"dataset": env, "dataset_identity": graph["dataset_identity"], "graph": settings,
                     "low": low_info.portable_config}
    return result
