"""How plans are made and chosen when executing: replanning, warm starts, arrival time, candidates.

:class:`Execution` holds the settings (the ``eval``/``render`` flags); :class:`PlanSource` turns a
:class:`~bridgeplan.planner.Planner` into the ``plan_fn`` that ``maze.rollout.ClosedLoopController`` calls
whenever episodes are due to plan. Each call is one decision for every due episode, made in one batch:

1. **Prior.** The run's own prior for the first plan; with ``warm``, replans start from
   :class:`~bridgeplan.priors.WarmPrior` (the episode's previous plan, shifted by the elapsed steps).
2. **Candidates.** ``candidates`` (M) plans per episode, sampled in the same batch (N x M plans).
3. **Arrival.** ``arrival="truncate"``: each plan is cut at its first state within ``GOAL_RADIUS`` (0.45)
   of the goal, and holds the goal (zero velocity) from there on; ``"end"``: the plan as sampled, which
   arrives at ``t = H - 1`` (the goal is inpainted there); ``"keep"``: truncated as well, and a replan is
   conditioned to arrive by the step at which the episode's first plan came within 0.45 of the goal (the
   goal inpainted, held, from the planned index of that step on).
4. **Selection** of one candidate per episode (:data:`SELECTIONS`): ``arrival`` (earliest arrival within
   0.45 of the goal), ``agreement`` (the medoid: closest in position, on average, to the other candidates)
   or ``walls`` (fewest planned positions inside a wall, then earliest arrival; it reads the maze's wall
   map, which the model never sees: a separate, labelled variant).

Why truncation for the arrival time: evaluation windows are cut from a continuous stream in which the
expert, once at a goal, heads for the next one at the same speed; no window waits at a goal. Conditioned on
the goal at ``t = H - 1``, a plan whose start is closer than ``H - 1`` steps of expert motion from the goal
has to spend the surplus somehow, and the data teaches it to do so by moving (detours, loops, passing
through the goal and coming back), not by waiting. Inpainting a hold of the goal over ``k..H-1`` would put
the network on inputs it never saw in training (a stationary tail); reading the first passage within 0.45
of the goal off the model's own sample asks nothing of it that the data did not show, and costs nothing.
Truncated plans then hold the goal, so replanning from them (``warm``) also starts from a plan that stays.

What truncation cannot fix, measured with a stand-in planner (no trained run was at hand): plans that are the
expert's own path slowed down to arrive exactly at ``t = H - 1`` (H = 128, umaze, 40 episodes, seed 0) score
88.8 +- 1.5 open loop (the issue's plateau) but -7.0 +- 1.3 replanned every 8 steps and 7.1 +- 4.9 every 32,
with either arrival rule: each replan stretches what is left of the path over another H - 1 steps, so the
point mass slows down and never arrives. Replanning pays only for a model whose samples reach the goal
early (detours through it, or candidates that do); for one that slows down, arrival has to be imposed:
``keep`` holds the goal from the step the first plan arrived at, so what is left of the path is never
stretched. The step is fixed per episode: taking each replan's own (truncated) arrival instead compounds
the 0.45 lead into ever earlier deadlines, until no plan can keep them. It puts the network on a held tail
it never saw in training; planning over a shorter horizon instead (the U-Net is convolutional) was worse in
a trial, because a plan too short for the path cuts through walls. Results: docs/results/controllers.md and findings.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from bridgeplan.envs.maze2d.controllers import DEFAULT_LOOKAHEAD, Follower, check_controller
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, Maze
from bridgeplan.envs.maze2d.rollout import check_replanning
from bridgeplan.errors import BridgeplanError
from bridgeplan.priors import WarmPrior
from bridgeplan.trajectory import Layout

SELECTIONS = ("arrival", "agreement", "walls")
ARRIVALS = ("end", "truncate", "keep")


@dataclass(frozen=True)
class Execution:
    """How plans are executed. The defaults are open loop as ever: one plan per episode, tracked to the end.

    ``replan_every`` (K): plan again from the current state every K steps (1..episode length).
    ``tolerance`` (D): also plan again when the position is more than D from where the plan put it now.
    ``candidates`` (M): plans sampled per decision; ``select`` picks one (:data:`SELECTIONS`).
    ``warm``: replans start from the previous plan (:class:`~bridgeplan.priors.WarmPrior`) instead of the
    run's prior; needs a process with a prior and replanning. ``arrival``: ``end``, ``truncate`` or ``keep``
    (see the module); None: ``truncate`` when replanning or sampling candidates, else ``end``.
    ``controller``: ``track`` (Diffuser's) or ``pursuit`` (the plan's path at the expert's pace, toward the
    first planned position ``lookahead`` away; :mod:`bridgeplan.envs.maze2d.controllers`).
    """

    replan_every: int | None = None
    tolerance: float | None = None
    candidates: int = 1
    select: str = "arrival"
    warm: bool = False
    arrival: str | None = None
    controller: str = "track"
    lookahead: float = DEFAULT_LOOKAHEAD

    @property
    def replans(self) -> bool:
        return self.replan_every is not None or self.tolerance is not None

    @property
    def arrival_rule(self) -> str:
        if self.arrival is not None:
            return self.arrival
        return "truncate" if self.replans or self.candidates > 1 else "end"

    def follower(self, n: int) -> Follower:
        """The controllers that execute the plans of ``n`` episodes."""
        return Follower(n, self.controller, self.lookahead)

    @property
    def plans_once(self) -> bool:
        """True when each episode is executed from one plan, as sampled (by either controller)."""
        return not self.replans and self.candidates == 1 and self.arrival_rule == "end"

    def validate(self, process, episode_steps: int) -> None:
        """Bad settings raise BridgeplanError (the CLI's one-line ``error:``)."""
        check_replanning(self.replan_every, self.tolerance, episode_steps)
        check_controller(self.controller, self.lookahead)
        if self.candidates < 1:
            raise BridgeplanError(f"--candidates must be >= 1, got {self.candidates}")
        if self.select not in SELECTIONS:
            raise BridgeplanError(f"unknown --select {self.select!r}: choose from {', '.join(SELECTIONS)}")
        if self.arrival is not None and self.arrival not in ARRIVALS:
            raise BridgeplanError(f"unknown --arrival {self.arrival!r}: choose from {', '.join(ARRIVALS)}")
        if self.arrival == "keep" and not self.replans:
            raise BridgeplanError("--arrival keep holds replans to the first plan's arrival step: give "
                                  "--replan-every K or --replan-tolerance D")
        if self.warm and not process.uses_prior:
            raise BridgeplanError(f"--prior warm needs a process that starts from a prior; {process.display_name} "
                                  f"starts from Gaussian noise")
        if self.warm and not self.replans:
            raise BridgeplanError("--prior warm is only valid on replans (a first plan has no previous plan): "
                                  "give --replan-every K or --replan-tolerance D")

    def to_dict(self, run_prior: str) -> dict:
        return {"mode": "closed_loop" if self.replans else "open_loop", "replan_every": self.replan_every,
                "replan_tolerance": self.tolerance, "candidates": self.candidates,
                "select": self.select if self.candidates > 1 else None, "arrival": self.arrival_rule,
                "first_prior": run_prior, "replan_prior": ("warm" if self.warm else run_prior) if self.replans
                else None, "controller": self.controller,
                "lookahead": self.lookahead if self.controller == "pursuit" else None}

    def tag(self) -> str:
        """A file-name suffix for these settings ('' for the default)."""
        parts = []
        if self.replan_every is not None:
            parts.append(f"replan{self.replan_every}")
        if self.tolerance is not None:
            parts.append(f"tol{self.tolerance:g}")
        if self.candidates > 1:
            parts.append(f"cand{self.candidates}-{self.select}")
        if self.warm:
            parts.append("warm")
        if self.arrival is not None:
            parts.append(f"arrival-{self.arrival}")
        if self.controller != "track":
            parts.append(f"{self.controller}{self.lookahead:g}")
        return "-".join(parts)


def truncate_at_arrival(traj: np.ndarray, goals: np.ndarray, layout: Layout,
                        radius: float = GOAL_RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """Cut each plan ``traj [N, H, D]`` (physical, in ``layout``) at its first state within ``radius`` of its
    goal ``goals [N, 2]`` and hold the goal from the next step on (zero velocity, zero action).

    Returns ``(truncated copy, arrival [N])``: the index of that first state (``H - 1`` when none is closer
    before the end; the goal is inpainted there, so every plan arrives by then).
    """
    traj = np.array(traj, dtype=np.float64)
    horizon = traj.shape[1]
    arrival = arrival_index(traj, goals, layout, radius)
    after = np.arange(horizon)[None, :] > arrival[:, None]
    hold = np.zeros_like(traj)
    layout.positions(hold)[...] = np.asarray(goals, np.float64)[:, None]
    traj[after] = hold[after]
    return traj, arrival


def arrival_index(traj: np.ndarray, goals: np.ndarray, layout: Layout, radius: float = GOAL_RADIUS) -> np.ndarray:
    """``[N]`` the first index at which plan ``traj [N, H, D]`` (in ``layout``) is within ``radius`` of its goal
    (else H-1)."""
    traj = np.asarray(traj, dtype=np.float64)
    dist = np.linalg.norm(layout.positions(traj) - np.asarray(goals, np.float64)[:, None], axis=2)
    inside = dist <= radius
    return np.where(inside.any(axis=1), inside.argmax(axis=1), traj.shape[1] - 1)


def select_candidates(traj: np.ndarray, goals: np.ndarray, how: str, layout: Layout,
                      maze: Maze | None = None) -> np.ndarray:
    """The index ``[N]`` of the chosen candidate among ``traj [N, M, H, D]`` (in ``layout``; goals ``[N, 2]``).

    ``arrival``: the earliest first state within 0.45 of the goal (ties: the first candidate).
    ``agreement``: the candidate with the smallest mean position distance to the other candidates
    (the medoid; ties: the first). ``walls``: the fewest planned positions inside walls or outside the maze
    (``maze`` needed), ties broken by earliest arrival. All use only the plans, the goal and, for ``walls``,
    the wall map.
    """
    traj = np.asarray(traj, dtype=np.float64)
    n, m, horizon, _ = traj.shape
    if m == 1:
        return np.zeros(n, dtype=np.int64)
    arrival = arrival_index(traj.reshape(n * m, horizon, -1), np.repeat(goals, m, axis=0), layout).reshape(n, m)
    if how == "arrival":
        return arrival.argmin(axis=1)
    pos = layout.positions(traj)
    if how == "agreement":
        dist = np.linalg.norm(pos[:, :, None] - pos[:, None, :], axis=-1).mean(axis=-1)  # [n, m, m]
        return dist.sum(axis=2).argmin(axis=1)
    if how == "walls":
        if maze is None:
            raise BridgeplanError("--select walls needs the maze")
        in_walls = (~maze.is_free_xy(pos)).sum(axis=2)  # [n, m]
        return _lexmin(in_walls, arrival)
    raise BridgeplanError(f"unknown --select {how!r}: choose from {', '.join(SELECTIONS)}")


def _lexmin(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Per row, the column with the smallest ``first``, ties broken by the smallest ``second`` then column."""
    key = first.astype(np.int64) * (int(second.max()) + 1) + second.astype(np.int64)
    return key.argmin(axis=1)


@dataclass
class PlanSource:
    """The ``plan_fn`` of the closed-loop controller over a planner (see the module): warm start, candidates,
    arrival and selection, for a batch of ``n`` episodes; counts the decisions and times them.

    ``decision_seconds`` holds the wall time of every call (prior, network, truncation and selection of all
    the episodes due at that step) and ``decision_batch`` how many episodes it decided for.
    """

    planner: object
    execution: Execution
    nfe: int
    generator: torch.Generator
    n: int
    maze: Maze | None = None
    batch_size: int | None = None
    previous: np.ndarray | None = None
    previous_at: np.ndarray | None = None
    deadline: np.ndarray | None = None
    """``[n]`` the step at which each episode's first plan came within 0.45 of the goal (``keep``)."""
    decision_seconds: list[float] = field(default_factory=list)
    decision_batch: list[int] = field(default_factory=list)
    prior_seconds: float = 0.0
    sample_seconds: float = 0.0
    plans_sampled: int = 0

    def reset(self) -> None:
        """Forget the previous plans (a new episode); counters and timings are kept."""
        self.previous = None
        self.previous_at = None
        self.deadline = None

    def __call__(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> np.ndarray:
        t0 = time.perf_counter()
        ex, m = self.execution, self.execution.candidates
        planner = self.planner
        replan = self.previous is not None
        warm = ex.warm and replan
        if replan:
            prev = np.repeat(self.previous[episodes], m, axis=0)
            elapsed = np.repeat(t - self.previous_at[episodes], m)
        starts, goals_m = np.repeat(states, m, axis=0), np.repeat(goals, m, axis=0)
        arrival = None
        if ex.arrival_rule == "keep" and replan:  # hold the goal from the first plan's arrival step on
            left = np.maximum(np.repeat(self.deadline[episodes], m) - t, 0)
            arrival = np.clip(-(-left // planner.stride), 1, planner.horizon - 1)
        total = len(starts)
        batch = min(self.batch_size or total, total)
        parts = []
        for lo in range(0, total, batch):
            sub = planner
            if warm:  # the warm prior over this chunk's previous plans
                sub = planner.with_prior(WarmPrior(planner.normalizer, planner.layout, prev[lo:lo + batch],
                                                   elapsed[lo:lo + batch], planner.stride))
            plan = sub.plan(starts[lo:lo + batch], goals_m[lo:lo + batch], self.nfe, self.generator,
                            arrival=None if arrival is None else arrival[lo:lo + batch])
            parts.append(np.concatenate([plan.actions, plan.states], axis=2))
            self.prior_seconds += plan.prior_seconds
            self.sample_seconds += plan.sample_seconds
        traj = np.concatenate(parts)
        self.plans_sampled += total
        if ex.arrival_rule in ("truncate", "keep"):
            traj, _ = truncate_at_arrival(traj, goals_m, planner.layout)
        horizon = traj.shape[1]
        traj = traj.reshape(len(states), m, horizon, -1)
        pick = select_candidates(traj, goals, ex.select, planner.layout, self.maze)
        chosen = traj[np.arange(len(states)), pick]
        if self.previous is None:
            self.previous = np.zeros((self.n, horizon, chosen.shape[2]))
            self.previous_at = np.zeros(self.n, dtype=np.int64)
            self.deadline = t + arrival_index(chosen, goals, planner.layout)
        self.previous[episodes] = chosen
        self.previous_at[episodes] = t
        self.decision_seconds.append(time.perf_counter() - t0)
        self.decision_batch.append(len(states))
        return planner.layout.states(chosen)


def percentiles_ms(seconds: list[float]) -> dict:
    """``{p50, p95, mean, count}`` in milliseconds."""
    ms = 1000.0 * np.asarray(seconds, dtype=np.float64)
    if len(ms) == 0:
        return {"p50": None, "p95": None, "mean": None, "count": 0}
    return {"p50": float(np.percentile(ms, 50)), "p95": float(np.percentile(ms, 95)), "mean": float(ms.mean()),
            "count": int(len(ms))}
