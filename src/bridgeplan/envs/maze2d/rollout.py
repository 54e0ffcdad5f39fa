"""Batched episodes: a policy, or a batch of plans through a controller (:mod:`~bridgeplan.envs.maze2d.controllers`),
in lockstep.

Evaluation is a continuing task: the goal stays for the whole episode and every step within 0.45
of it earns reward 1, so reaching the goal fast and staying there earns more.

Plans are executed open loop (:func:`execute_plans`: one plan per episode, tracked to the end) or closed
loop (:func:`execute_closed_loop`, :class:`ClosedLoopController`: plan again from the current state every
K steps and/or when the state has drifted from the plan; the controller executes the newest plan).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from bridgeplan.envs.maze2d.controllers import Follower
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, Maze
from bridgeplan.envs.maze2d.sim import BatchedPointMaze
from bridgeplan.errors import BridgeplanError
from bridgeplan.trajectory import MAZE2D

Policy = Callable[[int, np.ndarray], np.ndarray]
"""``policy(step_index, obs [N, 4]) -> actions [N, 2]``."""


@dataclass
class RolloutResult:
    returns: np.ndarray
    """``[N]`` sum of the sparse rewards over the episode."""
    success: np.ndarray
    """``[N]`` bool: the point mass was within 0.45 of the goal at some step."""
    states: np.ndarray
    """``[N, steps + 1, 4]`` observed states, the initial one first."""
    actions: np.ndarray
    """``[N, steps, 2]`` the actions applied (clipped to [-1, 1])."""


def rollout(maze: Maze, policy: Policy, starts_xy, goals_xy, steps: int | None = None) -> RolloutResult:
    """Run ``policy`` from ``starts_xy [N, 2]`` toward ``goals_xy [N, 2]`` for ``steps`` (default: the
    maze's episode length), all episodes in lockstep."""
    steps = maze.episode_steps if steps is None else int(steps)
    if steps <= 0:
        raise BridgeplanError(f"episode steps must be positive, got {steps}")
    sim = BatchedPointMaze(maze, len(np.asarray(starts_xy)))
    obs = sim.reset(starts_xy, goals_xy)
    n = len(obs)
    states = np.empty((n, steps + 1, MAZE2D.obs_dim))
    actions = np.empty((n, steps, MAZE2D.act_dim))
    states[:, 0] = obs
    returns = np.zeros(n)
    for t in range(steps):
        act = np.clip(np.asarray(policy(t, obs), dtype=np.float64), -1.0, 1.0)
        actions[:, t] = act
        obs, reward = sim.step(act)
        states[:, t + 1] = obs
        returns += reward
    dist = np.linalg.norm(MAZE2D.state_positions(states[:, 1:]) - sim.goals[:, None], axis=2)
    return RolloutResult(returns, (dist <= GOAL_RADIUS).any(axis=1), states, actions)


def execute_plans(maze: Maze, starts_xy, goals_xy, plans, steps: int | None = None,
                  follower: Follower | None = None) -> RolloutResult:
    """Execute planned states ``plans [N, H, 4]`` open loop for ``steps`` (default: the maze's episode length)
    with ``follower`` (:mod:`bridgeplan.envs.maze2d.controllers`; default Diffuser's tracking controller)."""
    plans = np.asarray(plans, dtype=np.float64)
    if plans.ndim != 3 or plans.shape[2] != MAZE2D.obs_dim or len(plans) != len(np.asarray(starts_xy)):
        raise BridgeplanError(f"plans must have shape [N, H, {MAZE2D.obs_dim}] with N = {len(np.asarray(starts_xy))} "
                              f"episodes, got {list(plans.shape)}")
    follower = follower or Follower(len(plans))
    return rollout(maze, lambda t, obs: follower.actions(obs, plans, np.full(len(plans), t)), starts_xy, goals_xy,
                   steps)


PlanFn = Callable[[np.ndarray, np.ndarray, np.ndarray, int], np.ndarray]
"""``plan_fn(states [n, 4], goals [n, 2], episodes [n], t) -> planned states [n, H, 4]``: new plans for the
episodes ``episodes`` (indices into the batch) from their current ``states`` at step ``t``."""


def check_replanning(replan_every: int | None, tolerance: float | None, episode_steps: int) -> None:
    """``replan_every`` in 1..episode_steps (or None: no periodic replanning), ``tolerance`` >= 0 (or None)."""
    if replan_every is not None and not 1 <= replan_every <= episode_steps:
        raise BridgeplanError(f"--replan-every must be in 1..{episode_steps} (the episode length), "
                              f"got {replan_every}")
    if tolerance is not None and not tolerance >= 0:
        raise BridgeplanError(f"--replan-tolerance must be >= 0 (a distance in position), got {tolerance}")


class ClosedLoopController:
    """Receding-horizon execution for a batch of ``n`` episodes: plans with ``plan_fn`` at step 0, then again
    for every episode whose plan is ``replan_every`` steps old or whose position is more than ``tolerance``
    from its plan (:meth:`Follower.drift`); executes the newest plan with ``follower`` (default Diffuser's
    tracking controller, indexed relative to the step that plan was made at; past the plan's end it holds
    the last position).

    All episodes due at a step are planned in one ``plan_fn`` call; episodes that are not due keep their plan.
    With a fixed ``replan_every`` and no tolerance every episode is due at the same steps (0, K, 2K, ...),
    so each episode makes exactly ``ceil(steps / K)`` plans; with a tolerance, only the drifted episodes
    replan (and their K-step clock restarts). Neither set: one plan per episode, exactly
    :func:`execute_plans` (open loop). ``plans_made [n]`` counts plans per episode, ``calls`` the
    ``plan_fn`` calls and ``call_steps`` the steps they were made at.
    """

    def __init__(self, plan_fn: PlanFn, n: int, replan_every: int | None = None, tolerance: float | None = None,
                 follower: Follower | None = None):
        self.plan_fn, self.n = plan_fn, int(n)
        self.replan_every, self.tolerance = replan_every, tolerance
        self.follower = follower or Follower(self.n)
        self.reset()

    def reset(self) -> None:
        self.plans: np.ndarray | None = None
        self.made_at = np.zeros(self.n, dtype=np.int64)
        self.plans_made = np.zeros(self.n, dtype=np.int64)
        self.call_steps: list[int] = []

    @property
    def calls(self) -> int:
        return len(self.call_steps)

    def due(self, t: int, states: np.ndarray) -> np.ndarray:
        """``[n]`` bool: the episodes that plan at step ``t``."""
        if self.plans is None:
            return np.ones(self.n, dtype=bool)
        age = t - self.made_at
        due = np.zeros(self.n, dtype=bool)
        if self.replan_every is not None:
            due |= age >= self.replan_every
        if self.tolerance is not None:
            due |= self.follower.drift(states, self.plans, age) > self.tolerance
        return due

    def act(self, t: int, states: np.ndarray, goals: np.ndarray, due: np.ndarray | None = None) -> np.ndarray:
        """Actions ``[n, 2]`` at step ``t`` for observed ``states [n, 4]`` and ``goals [n, 2]``, planning first
        for the episodes :meth:`due` (or ``due``, when given) at ``t``."""
        states = np.asarray(states, dtype=np.float64)
        due = self.due(t, states) if due is None else np.asarray(due, dtype=bool)
        if due.any():
            idx = np.flatnonzero(due)
            new = np.asarray(self.plan_fn(states[idx], np.asarray(goals, np.float64)[idx], idx, t), np.float64)
            if self.plans is None:
                if len(idx) != self.n:
                    raise BridgeplanError("the first plan must be made for every episode")
                self.plans = new.copy()
            else:
                self.plans[idx] = new
            self.made_at[idx] = t
            self.plans_made[idx] += 1
            self.call_steps.append(t)
            self.follower.new_plans(idx)
        return self.follower.actions(states, self.plans, t - self.made_at)


@dataclass
class ClosedLoopResult(RolloutResult):
    plans_made: np.ndarray | None = None
    """``[N]`` plans made per episode (the first one included)."""
    call_steps: list[int] | None = None
    """The steps at which ``plan_fn`` was called (once per step at most, for all the episodes due)."""


def execute_closed_loop(maze: Maze, starts_xy, goals_xy, plan_fn: PlanFn, replan_every: int | None = None,
                        tolerance: float | None = None, steps: int | None = None,
                        follower: Follower | None = None) -> ClosedLoopResult:
    """Run :class:`ClosedLoopController` over ``plan_fn`` for ``steps`` (default: the maze's episode length),
    all episodes in lockstep, executing plans with ``follower`` (default: tracking)."""
    steps_ = maze.episode_steps if steps is None else int(steps)
    check_replanning(replan_every, tolerance, steps_)
    goals = np.asarray(goals_xy, dtype=np.float64)
    controller = ClosedLoopController(plan_fn, len(goals), replan_every, tolerance, follower)
    result = rollout(maze, lambda t, obs: controller.act(t, obs, goals), starts_xy, goals_xy, steps_)
    return ClosedLoopResult(result.returns, result.success, result.states, result.actions,
                            controller.plans_made.copy(), list(controller.call_steps))
