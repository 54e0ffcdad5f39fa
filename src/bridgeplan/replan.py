"""How plans are made and chosen when executing: replanning, warm starts, arrival time, candidates.

:class:`Execution` holds the settings (the ``eval``/``render`` flags); :class:`PlanExecutor` runs a family's
episodes on decisions (an agent of :meth:`bridgeplan.envs.family.Family.run`: it plans again when an episode is due,
and its controllers execute the newest plans); :class:`PlanSource` turns a :class:`~bridgeplan.planner.Planner`
into those decisions. Each call is one decision for every due episode, made in one batch:

1. **Prior.** The run's own prior for the first plan; with ``warm``, replans start from
   :class:`~bridgeplan.priors.WarmPrior` (the episode's previous plan, shifted by the elapsed steps).
2. **Candidates.** ``candidates`` (M) plans per episode, sampled in the same batch (N x M plans).
3. **Arrival.** ``arrival="truncate"``: each plan is cut at its first state within the family's goal radius
   (Maze2D: 0.45) of the goal, and holds the goal (zero velocity) from there on; ``"end"``: the plan as sampled, which
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

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from bridgeplan.envs.controllers import Follower, check_controller
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.priors import WarmPrior
from bridgeplan.trajectory import Layout

SELECTIONS = ("arrival", "agreement", "walls")
ARRIVALS = ("end", "truncate", "keep")


def check_replanning(replan_every: int | None, tolerance: float | None, episode_steps: int,
                     after_step: int | None = None, object_tolerance: float | None = None) -> None:
    """``replan_every`` in 1..episode_steps (or None: no periodic replanning), ``tolerance`` and
    ``object_tolerance`` >= 0 (or None), ``after_step`` in 0..episode_steps (or None)."""
    if replan_every is not None and not 1 <= replan_every <= episode_steps:
        raise BridgeplanError(f"--replan-every must be in 1..{episode_steps} (the episode length), "
                              f"got {replan_every}")
    if tolerance is not None and not tolerance >= 0:
        raise BridgeplanError(f"--replan-tolerance must be >= 0 (a distance in position), got {tolerance}")
    if object_tolerance is not None and not object_tolerance >= 0:
        raise BridgeplanError(f"--replan-object-tolerance must be >= 0 (a distance in the objects' columns), got "
                              f"{object_tolerance}")
    if after_step is not None and not 0 <= after_step <= episode_steps:
        raise BridgeplanError(f"--replan-after-step must be in 0..{episode_steps} (the episode length), "
                              f"got {after_step}")


@dataclass(frozen=True)
class Execution:
    """How plans are executed (its fields' docs are the CLI's help, ``bridgeplan.option_groups``). The defaults are
    open loop as ever: one plan per episode, tracked to the end."""

    replan_every: int | None = None
    """Plan again from the current state every K environment steps (1..episode length)."""
    tolerance: float | None = None
    """Also plan again, for the episodes concerned only, when the position is more than D from where the plan put it
    (default: off)."""
    after_step: int | None = None
    """Also plan again S steps after where the plan's first step ends, for paths made of steps (``graph --objects``
    on cube and scene: one part at a time): a step whose part slipped is taken again at once, not at the next
    --replan-every (S: the arm lags its plan; default: off)."""
    object_tolerance: float | None = None
    """Also plan again when an object is more than D from where the plan has it within 10 steps of now, for paths that
    say where every object should be (``graph --objects`` on cube and scene datasets; D in the state's units, 10 per
    metre there): a dropped or pushed cube is taken again at once (default: off)."""
    candidates: int = 1
    """Plans sampled per decision, in one batch; ``select`` picks one."""
    select: str = "arrival"
    """``arrival`` (earliest within the goal radius), ``agreement`` (the candidate closest to the others) or ``walls``
    (fewest planned positions in walls: uses the maze's wall map)."""
    warm: bool = False
    """Replans start from the previous plan (:class:`~bridgeplan.priors.WarmPrior`) instead of the run's prior; needs
    a process with a prior and replanning."""
    arrival: str | None = None
    """``end`` (the plan as sampled, arriving at t=H-1), ``truncate`` (cut at its first state within the goal radius,
    then hold the goal) or ``keep`` (truncate, and replans hold the goal from the step the previous plan arrived at);
    default: the family's (Maze2D truncate, OGBench end: its episodes end at the goal) when replanning or with
    candidates, else end."""
    controller: str = "track"
    """``track`` (Diffuser's: the planned states in time), ``pursuit`` (the plan's path at the expert's pace: toward
    the first planned position ``lookahead`` away) or ``actions`` (a planner's own planned actions, Diffuser's joint
    state-action plans); where no default is shown, the environment family's (pursuit; OGBench manipulation: track)."""
    lookahead: float | None = None
    """Pursuit: distance to the planned position driven toward (default: the family's, Maze2D 1.0, OGBench 2.0)."""
    arrival_default: str = "truncate"
    """The arrival rule of replans and candidates when ``arrival`` is None: the family's
    (``Family.default_arrival``, set by :meth:`resolved`); not part of the settings' name."""

    def resolved(self, family, env: str) -> Execution:
        """These settings in ``env`` of ``family``: its pursuit lookahead unless one is given, its arrival rule."""
        lookahead = family.body(env).default_lookahead if self.lookahead is None else self.lookahead
        return dataclasses.replace(self, lookahead=float(lookahead), arrival_default=family.default_arrival)

    @property
    def replans(self) -> bool:
        return (self.replan_every is not None or self.tolerance is not None or self.after_step is not None
                or self.object_tolerance is not None)

    @property
    def arrival_rule(self) -> str:
        if self.arrival is not None:
            return self.arrival
        return self.arrival_default if self.replans or self.candidates > 1 else "end"

    @property
    def plans_once(self) -> bool:
        """True when each episode is executed from one plan, as sampled (by either controller)."""
        return not self.replans and self.candidates == 1 and self.arrival_rule == "end"

    def validate(self, process, episode_steps: int) -> None:
        """Bad settings raise BridgeplanError (the CLI's one-line ``error:``)."""
        check_replanning(self.replan_every, self.tolerance, episode_steps, self.after_step, self.object_tolerance)
        check_controller(self.controller, self.lookahead)
        if self.candidates < 1:
            raise BridgeplanError(f"--candidates must be >= 1, got {self.candidates}")
        check_choice("--select", self.select, SELECTIONS)
        if self.arrival is not None and self.arrival not in ARRIVALS:
            raise BridgeplanError(f"unknown --arrival {self.arrival!r}: choose from {', '.join(ARRIVALS)}")
        if self.arrival == "keep" and not self.replans:
            raise BridgeplanError("--arrival keep holds replans to the first plan's arrival step: give "
                                  "--replan-every K or --replan-tolerance D")
        if self.warm and process is not None and not process.uses_prior:
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
                "lookahead": self.lookahead if self.controller == "pursuit" else None,
                **({"replan_after_step": self.after_step} if self.after_step is not None else {}),
                **({"replan_object_tolerance": self.object_tolerance} if self.object_tolerance is not None else {})}

    @classmethod
    def from_dict(cls, d: dict | None) -> Execution:
        """The execution an evaluation JSON's ``execution`` field (:meth:`to_dict`) records; None or absent (older
        JSONs): open loop, tracked."""
        if not d:
            return cls()
        replans = any(d.get(k) is not None for k in ("replan_every", "replan_tolerance", "replan_after_step",
                                                      "replan_object_tolerance"))
        candidates = int(d.get("candidates") or 1)
        default_arrival = "truncate" if replans or candidates > 1 else "end"
        controller = d.get("controller") or "track"
        kwargs = dict(replan_every=d.get("replan_every"), tolerance=d.get("replan_tolerance"), candidates=candidates,
                      warm=d.get("replan_prior") == "warm",
                      arrival=None if d.get("arrival", default_arrival) == default_arrival else d["arrival"],
                      controller=controller, after_step=d.get("replan_after_step"),
                      object_tolerance=d.get("replan_object_tolerance"))
        if d.get("select"):
            kwargs["select"] = d["select"]
        if controller != "track":  # a JSON without it was pursued at Maze2D's lookahead then, 1
            kwargs["lookahead"] = float(d["lookahead"]) if d.get("lookahead") is not None else 1.0
        return cls(**kwargs)

    def tag(self) -> str:
        """A file-name suffix for these settings ('' for the default)."""
        parts = []
        if self.replan_every is not None:
            parts.append(f"replan{self.replan_every}")
        if self.tolerance is not None:
            parts.append(f"tol{self.tolerance:g}")
        if self.after_step is not None:
            parts.append(f"afterstep{self.after_step}")
        if self.object_tolerance is not None:
            parts.append(f"objtol{self.object_tolerance:g}")
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
                        radius: float) -> tuple[np.ndarray, np.ndarray]:
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


def arrival_index(traj: np.ndarray, goals: np.ndarray, layout: Layout, radius: float) -> np.ndarray:
    """``[N]`` the first index at which plan ``traj [N, H, D]`` (in ``layout``) is within ``radius`` of its goal
    (else H-1)."""
    traj = np.asarray(traj, dtype=np.float64)
    dist = np.linalg.norm(layout.positions(traj) - np.asarray(goals, np.float64)[:, None], axis=2)
    inside = dist <= radius
    return np.where(inside.any(axis=1), inside.argmax(axis=1), traj.shape[1] - 1)


def select_candidates(traj: np.ndarray, goals: np.ndarray, how: str, layout: Layout, radius: float,
                      free: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """The index ``[N]`` of the chosen candidate among ``traj [N, M, H, D]`` (in ``layout``; goals ``[N, 2]``).

    ``arrival``: the earliest first state within ``radius`` of the goal (ties: the first candidate).
    ``agreement``: the candidate with the smallest mean position distance to the other candidates
    (the medoid; ties: the first). ``walls``: the fewest planned positions inside walls or outside the maze
    (``free``, the family's wall map, needed), ties broken by earliest arrival. All use only the plans, the goal
    and, for ``walls``, the wall map.
    """
    traj = np.asarray(traj, dtype=np.float64)
    n, m, horizon, _ = traj.shape
    if m == 1:
        return np.zeros(n, dtype=np.int64)
    arrival = arrival_index(traj.reshape(n * m, horizon, -1), np.repeat(goals, m, axis=0), layout,
                            radius).reshape(n, m)
    if how == "arrival":
        return arrival.argmin(axis=1)
    pos = layout.positions(traj)
    if how == "agreement":
        dist = np.linalg.norm(pos[:, :, None] - pos[:, None, :], axis=-1).mean(axis=-1)  # [n, m, m]
        return dist.sum(axis=2).argmin(axis=1)
    if how == "walls":
        if free is None:
            raise BridgeplanError("--select walls needs the environment's wall map, and its family has none")
        in_walls = (~free(pos)).sum(axis=2)  # [n, m]
        return _lexmin(in_walls, arrival)
    raise BridgeplanError(f"unknown --select {how!r}: choose from {', '.join(SELECTIONS)}")


def _lexmin(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Per row, the column with the smallest ``first``, ties broken by the smallest ``second`` then column."""
    key = first.astype(np.int64) * (int(second.max()) + 1) + second.astype(np.int64)
    return key.argmin(axis=1)


@dataclass
class PlanSource:
    """A planner's decisions (see the module): warm start, candidates, arrival and selection, for a batch of ``n``
    episodes; counts the plans and their network calls and times them.

    ``radius`` and ``free`` are the family's goal radius and wall map (arrival and ``walls`` selection);
    ``prior_only`` plans from the prior's sample alone (a floor); ``measure_residuals``: collect each plan's
    ``Planner.residuals`` in :attr:`residuals`.
    """

    planner: object
    execution: Execution
    nfe: int
    generator: torch.Generator
    n: int
    radius: float | None = None
    free: Callable[[np.ndarray], np.ndarray] | None = None
    batch_size: int | None = None
    prior_only: bool = False
    measure_residuals: bool = False
    residuals: dict[str, list] = field(default_factory=dict)
    previous: np.ndarray | None = None
    previous_at: np.ndarray | None = None
    deadline: np.ndarray | None = None
    """``[n]`` the step at which each episode's first plan came within the goal radius (``keep``)."""
    calls: np.ndarray = field(init=False)
    """``[n]`` network calls made for each episode (NFE per decision; a decision's candidates share a batch)."""
    plan_seconds: float = 0.0
    prior_seconds: float = 0.0
    plans_sampled: int = 0

    def __post_init__(self):
        self.calls = np.zeros(self.n, dtype=np.int64)
        if self.execution.arrival_rule != "end" and self.radius is None:
            raise BridgeplanError(f"--arrival {self.execution.arrival_rule} cuts plans at the goal, and this "
                                  f"environment's family has no goal radius")

    def reset(self) -> None:
        """Forget the previous plans (a new episode); counters and timings are kept."""
        self.previous = None
        self.previous_at = None
        self.deadline = None

    def __call__(self, states: np.ndarray, goals: np.ndarray, episodes: np.ndarray, t: int) -> np.ndarray:
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
                            prior_only=self.prior_only, arrival=None if arrival is None else arrival[lo:lo + batch])
            parts.append(np.concatenate([plan.actions, plan.states], axis=2))
            self.prior_seconds += plan.prior_seconds
            self.plan_seconds += plan.prior_seconds + plan.sample_seconds
            if self.measure_residuals:
                for key, values in planner.residuals(plan).items():
                    self.residuals.setdefault(key, []).append(values)
        traj = np.concatenate(parts)
        self.plans_sampled += total
        self.calls[episodes] += self.nfe
        if ex.arrival_rule in ("truncate", "keep"):
            traj, _ = truncate_at_arrival(traj, goals_m, planner.layout, self.radius)
        horizon = traj.shape[1]
        traj = traj.reshape(len(states), m, horizon, -1)
        pick = select_candidates(traj, goals, ex.select, planner.layout, self.radius or 0.0, self.free)
        chosen = traj[np.arange(len(states)), pick]
        if self.previous is None:
            self.previous = np.zeros((self.n, horizon, chosen.shape[2]))
            self.previous_at = np.zeros(self.n, dtype=np.int64)
            if ex.arrival_rule == "keep":
                self.deadline = t + arrival_index(chosen, goals, planner.layout, self.radius)
        self.previous[episodes] = chosen
        self.previous_at[episodes] = t
        return chosen if ex.controller == "actions" else planner.layout.states(chosen)  # the actions: Diffuser's


DecisionSource = Callable[[np.ndarray, np.ndarray, np.ndarray, int], np.ndarray]
"""``(states [n, obs_dim], goals [n, goal_dim], episodes [n], t) -> planned states [n, S, obs_dim]``: new plans for
the batch's episodes ``episodes`` from their current states at step ``t`` (:class:`PlanSource`, a hierarchy's
``HierarchySource``, the dataset graph's ``GraphSource``); one with ``reset()`` forgets an episode's plans."""


class PlanExecutor:
    """Decisions executed by controllers: the :class:`~bridgeplan.envs.family.Agent` every evaluation runs.

    For each batch of ``n`` episodes (:meth:`begin`) it makes a fresh decision source ``decisions(n)`` and controllers
    ``follower(n)``; at an episode's first step it plans for every episode, then again for the episodes whose plan is
    ``replan_every`` steps old, whose position is more than ``tolerance`` from its plan (``Follower.drift``) or whose
    plan's first step ended ``after_step`` steps ago (a source's ``step_ends``: paths made of steps) or whose objects
    are more than ``object_tolerance`` from their plan (a source's ``drift``: paths of objects), all of them in
    one call, ended episodes never. The controllers execute the newest plan of each episode, indexed from the
    step it was made at (past its end they hold its last position).

    ``warm_up(states, goals, episodes, t)``, when given, is called once before the very first decision, untimed
    (a compile, or a decision that is thrown away). Counted: the plans made per episode (:attr:`plans_made`, in episode
    order over the batches), the controllers' network calls per episode (a policy's, :attr:`follower_calls`), every
    decision's wall time and how many episodes it planned for, every step's.
    """

    def __init__(self, decisions: Callable[[int], DecisionSource], follower: Callable[[int], Follower],
                 replan_every: int | None = None, tolerance: float | None = None,
                 warm_up: Callable | None = None, after_step: int | None = None,
                 object_tolerance: float | None = None):
        self.decisions, self.make_follower = decisions, follower
        self.replan_every, self.tolerance, self.warm_up = replan_every, tolerance, warm_up
        self.after_step, self.object_tolerance = after_step, object_tolerance
        self.sources: list = []
        self.made: list[np.ndarray] = []
        self.follower_calls: list[np.ndarray] = []
        self.decision_seconds: list[float] = []
        self.decision_batch: list[int] = []
        self.step_seconds: list[float] = []
        self.warm_up_seconds = 0.0
        self.n = 0

    @classmethod
    def executing(cls, execution: Execution, decisions: Callable[[int], DecisionSource],
                  follower: Callable[[int], Follower], warm_up: Callable | None = None) -> PlanExecutor:
        """The executor that replans as ``execution`` says (every K steps, past a drift, where a step ends, past an
        object's drift)."""
        return cls(decisions, follower, execution.replan_every, execution.tolerance, warm_up, execution.after_step,
                   execution.object_tolerance)

    @property
    def plans_made(self) -> np.ndarray:
        """``[episodes]`` plans made for each episode so far (the first one included)."""
        return np.concatenate(self.made) if self.made else np.zeros(0, dtype=np.int64)

    def replan(self, rows: np.ndarray) -> None:
        """Rows ``rows`` plan at the next step, whatever their plans' age (their goal changed)."""
        self.forced[rows] = True

    def begin(self, n: int) -> None:
        self.n = int(n)
        self.forced = np.zeros(self.n, dtype=bool)
        self.source = self.decisions(self.n)
        if self.after_step is not None and getattr(self.source, "step_ends", None) is None:
            raise BridgeplanError("--replan-after-step plans again where a path's first step ends: only paths made "
                                  "of steps have one (graph --objects on cube or scene datasets)")
        if self.object_tolerance is not None and not getattr(self.source, "drifts", False):
            raise BridgeplanError("--replan-object-tolerance plans again where an object left its plan: only paths "
                                  "that say where every object should be do (graph --objects on cube datasets)")
        self.sources.append(self.source)
        self.follower = self.make_follower(self.n)
        self.plans: np.ndarray | None = None
        self.made_at = np.zeros(self.n, dtype=np.int64)
        self.made.append(np.zeros(self.n, dtype=np.int64))
        self.follower_calls.append(np.zeros(self.n, dtype=np.int64))
        self.active = np.ones(self.n, dtype=bool)
        self.t = 0

    def end(self, rows: np.ndarray) -> None:
        self.active[rows] = False

    def due(self, states: np.ndarray) -> np.ndarray:
        """``[n]`` bool: the episodes that plan at this step."""
        if self.plans is None:
            return np.ones(self.n, dtype=bool)
        age = self.t - self.made_at
        due = np.zeros(self.n, dtype=bool)
        if self.replan_every is not None:
            due |= age >= self.replan_every
        if self.tolerance is not None:
            due |= self.follower.drift(states, self.plans, age) > self.tolerance
        if self.after_step is not None:
            due |= age >= self.source.step_ends + self.after_step
        if self.object_tolerance is not None:
            due |= self.source.drift(states, self.plans, age) > self.object_tolerance
        return (due | self.forced) & self.active

    def act(self, states: np.ndarray, goals: np.ndarray) -> np.ndarray:
        t0 = time.perf_counter()
        states, goals = np.asarray(states, np.float64), np.asarray(goals, np.float64)
        if len(states) != self.n:
            raise BridgeplanError(f"the agent was called on {len(states)} episodes, its batch has {self.n} (begin was "
                                  f"not called)")
        due = self.due(states)
        if due.any():
            idx = np.flatnonzero(due)
            if self.warm_up is not None:
                w0 = time.perf_counter()
                self.warm_up(states[idx], goals[idx], idx, self.t)
                self.warm_up_seconds = time.perf_counter() - w0
                self.warm_up = None
                t0 = time.perf_counter()
            d0 = time.perf_counter()
            new = np.asarray(self.source(states[idx], goals[idx], idx, self.t), np.float64)
            self.decision_seconds.append(time.perf_counter() - d0)
            self.decision_batch.append(len(idx))
            if self.plans is None:
                if len(idx) != self.n:
                    raise BridgeplanError("the first plan must be made for every episode")
                self.plans = new.copy()
            else:  # a plan's length is fixed, so replans fit the same array
                self.plans[idx] = new
            self.made_at[idx] = self.t
            self.made[-1][idx] += 1
            self.forced[idx] = False
            self.follower.new_plans(idx)
        actions = self.follower.actions(states, self.plans, self.t - self.made_at)
        self.follower_calls[-1] += self.follower.network_calls * self.active
        self.t += 1
        self.step_seconds.append(time.perf_counter() - t0)
        return actions


def percentiles_ms(seconds: list[float]) -> dict:
    """``{p50, p95, mean, count}`` in milliseconds."""
    ms = 1000.0 * np.asarray(seconds, dtype=np.float64)
    if len(ms) == 0:
        return {"p50": None, "p95": None, "mean": None, "count": 0}
    return {"p50": float(np.percentile(ms, 50)), "p95": float(np.percentile(ms, 95)), "mean": float(ms.mean()),
            "count": int(len(ms))}
