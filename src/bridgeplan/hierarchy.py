"""Hierarchical planning: a coarse plan over the whole episode, refined stretch by stretch by a low level.

The high level is an ordinary planner whose states lie far apart (a long ``stride``, Hierarchical Diffuser's
jump): one plan spans the episode, from the start to the goal. The low level is a planner trained with
``subgoal_every = j`` (``TrainConfig``): its every j-th planned state is a condition, so it plans from the
current state through the next ``m = (H - 1) / j`` states of the coarse plan; its prior is either noise
(DDPM inpainting the subgoals, as Hierarchical Diffuser does) or the coarse plan itself, densified
(``coarse``: the line through the subgoals, which a bridge or flow refines). The levels fit when a low-level
subgoal step is one high-level step: ``low.subgoal_every * low.stride == high.stride``.

Executed closed loop (:class:`HierarchySource` is the ``plan_fn`` of ``maze.rollout.ClosedLoopController``):
the high level plans at an episode's first step (and again from the current state every ``replan_high_every``
steps, if given: on large that is what pays, docs/results/hierarchy.md), and its plan holds the goal from its
first arrival on (a plan conditioned to end at the goal fills its whole span, however short the way: a high
level trained with holds, ``hold_share``, may arrive early instead); every decision, the low level plans from
the current state through the coarse states that follow the one nearest the agent (searched forward from the
last, so progress never runs back), the goal at rest repeating once the coarse plan runs out.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch

from bridgeplan import config as cfg
from bridgeplan.envs import maze2d
from bridgeplan.envs.maze2d.controllers import check_controller
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS
from bridgeplan.envs.maze2d.rollout import check_replanning, execute_closed_loop, execute_plans
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import Tasks, batch1_latency, environment_of, prior_only, score_returns
from bridgeplan.graph import DatasetGraph, fixed_length
from bridgeplan.planner import Planner
from bridgeplan.replan import Execution, percentiles_ms, truncate_at_arrival
from bridgeplan.runs import RunInfo, load_planner, require_family
from bridgeplan.trajectory import densify, span


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
        traj, _ = truncate_at_arrival(traj, goals, self.high.layout)
        return self.high.layout.states(traj), plan.prior_seconds + plan.sample_seconds

    def subgoals(self, coarse: np.ndarray, progress: np.ndarray) -> np.ndarray:
        return next_subgoals(coarse, progress, self.subgoals_per_plan)

    def high_entry(self, info: RunInfo, nfe: int) -> dict:
        """The high level's entry in the hierarchy's JSON."""
        return level_dict(self.high, info, nfe)

    def line_floor(self, tasks: Tasks, execution: Execution) -> dict:
        """``floor_line``: the straight line over the high level's span, executed as the hierarchy is."""
        return {"floor_line": prior_only(self.high, tasks, "line", Execution(controller=execution.controller,
                                                                             lookahead=execution.lookahead))}


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

    def line_floor(self, tasks, execution) -> dict:
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
    """The ``plan_fn`` of the closed-loop controller over a :class:`Hierarchy`, for a batch of ``n`` episodes.
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
    coarse_at: np.ndarray | None = None
    """``[n]`` the step each episode's coarse plan was made at."""
    progress: np.ndarray | None = None
    """``[n]`` the coarse index each episode has reached."""
    calls: np.ndarray = field(init=False)
    decision_seconds: list[float] = field(default_factory=list)
    decision_batch: list[int] = field(default_factory=list)
    high_seconds: float = 0.0
    low_seconds: float = 0.0
    low_plans: int = 0

    def __post_init__(self):
        low = self.hierarchy.low.process
        self.nfe_high = self.hierarchy.resolve_high_nfe(self.nfe_high)
        self.nfe_low = low.max_nfe if self.nfe_low is None else self.nfe_low
        low.validate_nfe(self.nfe_low)
        self.calls = np.zeros(self.n, dtype=np.int64)

    def reset(self) -> None:
        """Forget the coarse plans (a new episode); counters and timings are kept."""
        self.coarse = self.first_coarse = self.coarse_at = self.progress = None

    def plan_coarse(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> None:
        """New coarse plans for ``episodes`` from their ``states``; their progress starts again at 0."""
        coarse, seconds = self.hierarchy.coarse_plans(states, goals, self.nfe_high, self.generator)
        if self.coarse is None:
            self.coarse, self.first_coarse = coarse, coarse.copy()
            self.progress = np.zeros(self.n, dtype=np.int64)
            self.coarse_at = np.zeros(self.n, dtype=np.int64)
        self.coarse[episodes], self.progress[episodes], self.coarse_at[episodes] = coarse, 0, t
        self.calls[episodes] += self.nfe_high
        self.high_seconds += seconds

    def advance(self, positions: np.ndarray, episodes: np.ndarray) -> np.ndarray:
        """Move each episode's progress along its coarse plan, by the hierarchy's ``progress_rule``: ``nearest``,
        to the coarse state nearest its position among the next ``m + 1``; ``sequential``, one coarse state at a
        time while the next is no farther than the current (a plan that winds back near itself across a wall,
        as the data's paths do, is not skipped along)."""
        coarse, progress = self.coarse[episodes], self.progress[episodes].copy()
        layout = self.hierarchy.low.layout  # the levels' layouts are one (check_levels)
        xy, last, rows = layout.state_positions(coarse), coarse.shape[1] - 1, np.arange(len(episodes))
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
        t0 = time.perf_counter()
        h = self.hierarchy
        if self.coarse is None:
            if len(episodes) != self.n:
                raise BridgeplanError("the first decision must be made for every episode")
            self.plan_coarse(states, goals, episodes, t)
        elif self.replan_high_every is not None:
            due = np.flatnonzero(t - self.coarse_at[episodes] >= self.replan_high_every)
            if len(due):
                self.plan_coarse(states[due], goals[due], episodes[due], t)
        progress = self.advance(h.low.layout.state_positions(states), episodes)
        plan = h.low.plan(states, None, self.nfe_low, self.generator,
                          subgoals=h.subgoals(self.coarse[episodes], progress))
        self.calls[episodes] += self.nfe_low
        self.low_seconds += plan.prior_seconds + plan.sample_seconds
        self.low_plans += len(episodes)
        self.decision_seconds.append(time.perf_counter() - t0)
        self.decision_batch.append(len(episodes))
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
    """Two Maze2D runs as a :class:`Hierarchy` (EMA weights of their latest checkpoints or of the snapshots)."""
    high, high_info = load_planner(Path(high_run), snapshot=high_snapshot, device=device)
    low, low_info = load_planner(Path(low_run), snapshot=low_snapshot, device=device)
    for info in (high_info, low_info):
        require_family(info, maze2d.FAMILY)
    if high_info.config.maze != low_info.config.maze:
        raise BridgeplanError(f"the levels were trained in different mazes ({high_info.config.maze} and "
                              f"{low_info.config.maze})")
    return Hierarchy(high, low), high_info, low_info


def level_dict(planner: Planner, info: RunInfo, nfe: int) -> dict:
    """One level's settings in a hierarchy's JSON."""
    return {"run": info.name, "step": info.step, "method": cfg.method_label(planner.process, planner.prior.name),
            "process": planner.process.name, "prior": planner.prior.name, "process_params": planner.process.to_dict(),
            "nfe": nfe, "horizon": planner.horizon, "stride": planner.stride,
            "subgoal_every": planner.subgoal_every, "config": info.portable_config}


def coarse_diagnostics(dense: np.ndarray, goals: np.ndarray, maze, layout) -> dict:
    """What limits the coarse plans ``dense [N, S, obs_dim]`` (densified, physical; measured with the maze's map,
    which no planner reads): ``in_walls``, the share of their positions inside walls or outside the maze, and
    ``arrival_step``, the mean step at which they first come within 0.45 of the goal (S - 1 when never)."""
    positions = layout.state_positions(dense)
    inside = ~maze.is_free_xy(positions.reshape(-1, 2)).reshape(positions.shape[:2])
    near = np.linalg.norm(positions - goals[:, None], axis=2) <= GOAL_RADIUS
    arrival = np.where(near.any(axis=1), near.argmax(axis=1), dense.shape[1] - 1)
    return {"in_walls": float(inside.mean()), "crossing_walls": float(inside.any(axis=1).mean()),
            "arrival_step": float(arrival.mean())}


def load_graph_hierarchy(low_run: Path, settings: dict | None = None, low_snapshot: int | None = None,
                         device: str = "auto"):
    """The dataset graph over a Maze2D low level's own training data as its high level
    (:class:`GraphHierarchy`, ``graph.for_stream``'s Maze2D settings under ``settings``); returns the hierarchy,
    the high level's JSON entry (the graph's settings and size, the data's identity) and the low level's info."""
    from bridgeplan.envs.maze2d.datasets import load_stream
    from bridgeplan.envs.maze2d.grids import get_maze
    from bridgeplan.graph import MAZE2D_DEFAULTS, for_stream

    low, low_info = load_planner(Path(low_run), snapshot=low_snapshot, device=device)
    require_family(low_info, maze2d.FAMILY)
    settings = {**MAZE2D_DEFAULTS, **(settings or {})}
    stream = load_stream(low_info.config.dataset)
    t0 = time.perf_counter()
    hierarchy = GraphHierarchy(for_stream(stream, settings), low, get_maze(low_info.config.maze).episode_steps)
    settings["build_seconds"] = time.perf_counter() - t0
    settings["dataset_identity"] = stream.identity()
    return hierarchy, settings, low_info


def evaluate_hierarchy(hierarchy: Hierarchy, high_info: RunInfo | dict, low_info: RunInfo, tasks: Tasks,
                       nfe_high: int | None = None, nfe_low: int | None = None,
                       execution: Execution | None = None, replan_high_every: int | None = None) -> dict:
    """Score ``hierarchy`` on ``tasks``; returns the JSON that ``bridgeplan hierarchy eval`` (and ``graph-eval``)
    writes. ``hierarchy``: two planners, or the dataset graph over a low level (:class:`GraphHierarchy`, whose
    ``high_info`` is its settings, :func:`load_graph_hierarchy`).

    ``replan_high_every``: the high level plans again every that many steps (None: once per episode). Beside the
    hierarchy's score: ``high_alone``, the first coarse plans densified and executed open loop by the
    same controller (what the low level adds), and, for a planner as the high level, ``floor_line``, the straight
    line over its span so executed. Decisions are timed in the evaluation's batches and, at batch 1, over the first
    episode run again alone after one untimed decision.
    """
    low = hierarchy.low
    maze, n = tasks.maze, tasks.episodes
    execution = execution or Execution(replan_every=hierarchy.spacing, controller="pursuit")
    check_execution(execution, maze.episode_steps)
    starts, goals = tasks.starts_xy, tasks.goals_xy
    check_high_replanning(replan_high_every, maze.episode_steps)
    source = HierarchySource(hierarchy, nfe_high, nfe_low, tasks.generator(low.device), n, replan_high_every)
    nfe_high, nfe_low = source.nfe_high, source.nfe_low
    result = execute_closed_loop(maze, starts, goals, source, execution.replan_every, execution.tolerance,
                                 follower=execution.follower(n))
    dense = densify(source.first_coarse, hierarchy.spacing)
    alone = execute_plans(maze, starts, goals, dense, follower=execution.follower(n))
    high = hierarchy.high_entry(high_info, nfe_high)  # the graph's: its queries so far, not the lone episode's
    single = HierarchySource(hierarchy, nfe_high, nfe_low, torch.Generator(device=low.device)
                             .manual_seed(tasks.seed + 1), 1, replan_high_every)
    per_batch = percentiles_ms(source.decision_seconds)
    per_batch["mean_batch"] = float(np.mean(source.decision_batch))
    return {
        "kind": "hierarchy", "maze": maze.name, "episodes": n, "seed": tasks.seed, "multi_task": tasks.multi_task,
        "episode_steps": maze.episode_steps,
        "high": high, "low": level_dict(low, low_info, nfe_low),
        **score_returns(maze.name, result.returns, result.success),
        "high_alone": score_returns(maze.name, alone.returns, alone.success),
        "coarse_plans": coarse_diagnostics(dense, goals, maze, low.layout), **hierarchy.line_floor(tasks, execution),
        "execution": {**execution.to_dict(low.prior.name), "replan_high_every": replan_high_every},
        "plans_per_episode": {"mean": float(result.plans_made.mean()), "min": int(result.plans_made.min()),
                              "max": int(result.plans_made.max())},
        "calls_per_episode": float(source.calls.mean()),
        "high_ms_per_plan": 1000.0 * source.high_seconds / n,
        "low_ms_per_plan": 1000.0 * source.low_seconds / max(source.low_plans, 1),
        "decision_ms_batch1": batch1_latency(single, tasks, execution), "decision_ms_per_batch": per_batch,
        "environment": environment_of(low),
    }
