"""The controllers that execute plans, one set for every family: ``track``, ``pursuit`` and ``actions``
(:data:`CONTROLLERS`).

A plan is a batch of planned states ``[N, S, obs_dim]``, one per environment step (densified from its stride); its
actions are ignored. What differs between families is the body being steered, a :class:`Body`: how it reaches a
planned state in one step, and how it drives toward a waypoint. The rules are the same:

- ``track`` (Diffuser's): at step ``t`` of a plan the target is the plan's next state ``plan[t + 1]``, and after the
  plan's end its last position (at rest, where the state has a velocity). The plan's timing is executed as well as
  its path.
- ``pursuit``: the plan's path at the expert's pace. The waypoint is the first planned position at least
  ``lookahead`` from the body, among those not yet passed (progress along a plan never goes back: a stretch of the
  plan on the far side of a wall is not skipped to); the plan's last position once every other is passed. A body
  whose pursuit ``keeps_schedule`` also never takes a waypoint behind the tracking target's index: a plan that cuts
  a wall corner puts a waypoint behind the wall, and a waypoint chosen by distance alone would never change
  (OGBench's point, measured: every episode of a task stuck so).
- ``actions`` (Diffuser's own form, joint state-action plans): the plan's own action at the step it is at, so a
  planner's decisions carry their actions (``[N, S, transition_dim]``); from the plan's last state on, ``track``
  holds that state. Decisions of states alone (the dataset graph, a hierarchy's) cannot be executed so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.trajectory import Layout

CONTROLLERS = ("track", "pursuit", "actions")


@dataclass(frozen=True)
class Body:
    """How one family's agent is steered toward planned states (the action laws of its controllers)."""

    layout: Layout
    track: Callable[[np.ndarray, np.ndarray], np.ndarray]
    """``(states [N, obs_dim], targets [N, obs_dim]) -> actions``: toward each target in one step."""
    pursue: Callable[[np.ndarray, np.ndarray], np.ndarray]
    """``(states [N, obs_dim], waypoints [N, 2]) -> actions``: toward each waypoint at the expert's pace."""
    default_lookahead: float
    """Pursuit's lookahead unless one is given (the family's units)."""
    keeps_schedule: bool = False
    """Pursuit never takes a waypoint behind the tracking target's index (see the module)."""


def check_controller(kind: str, lookahead: float | None) -> None:
    check_choice("--controller", kind, CONTROLLERS)
    if lookahead is not None and not (math.isfinite(lookahead) and lookahead > 0):
        raise BridgeplanError(f"--lookahead must be a finite distance > 0 (in position), got {lookahead}")


def tracking_targets(plans: np.ndarray, steps_into_plan: np.ndarray, layout: Layout) -> np.ndarray:
    """``[N, obs_dim]``: ``plans[n, s_n + 1]`` for ``steps_into_plan [N]`` (steps since each plan was made), or past a
    plan's end its last position at rest."""
    plans = np.asarray(plans, np.float64)
    steps = np.asarray(steps_into_plan, dtype=np.int64)
    target = plans[np.arange(len(plans)), np.minimum(steps + 1, plans.shape[1] - 1)].copy()
    if layout.has_velocity:
        layout.state_velocities(target)[steps + 1 >= plans.shape[1]] = 0.0
    return target


def pursuit_waypoints(positions_planned: np.ndarray, positions: np.ndarray, passed: np.ndarray,
                      lookahead: float) -> np.ndarray:
    """``[N]`` each plan's waypoint index: the first index >= ``passed [N]`` whose planned position (of
    ``positions_planned [N, S, 2]``) is at least ``lookahead`` from ``positions [N, 2]``; the plan's last index when
    there is none."""
    far = np.linalg.norm(positions_planned - np.asarray(positions, np.float64)[:, None], axis=2) >= lookahead
    far &= np.arange(positions_planned.shape[1])[None, :] >= np.asarray(passed)[:, None]
    return np.where(far.any(axis=1), far.argmax(axis=1), positions_planned.shape[1] - 1)


class Follower:
    """A batch of ``n`` controllers of one kind (:data:`CONTROLLERS`) steering ``body``, each executing the newest
    plan of its episode: :meth:`new_plans` when episodes get a plan; :meth:`actions` at every step, with ``age [n]``
    the steps since each plan was made; :meth:`drift`, how far each episode is from its plan (``track``: from where
    the plan put it now; ``pursuit``: from the nearest point of the plan's path). ``network_calls``: the network calls
    each episode's controller makes at a step (a family's none; a policy's one)."""

    network_calls = 0

    def __init__(self, n: int, body: Body, kind: str = "track", lookahead: float | None = None):
        check_controller(kind, lookahead)
        self.body, self.kind = body, kind
        self.lookahead = float(body.default_lookahead if lookahead is None else lookahead)
        self.passed = np.zeros(int(n), dtype=np.int64)

    def new_plans(self, episodes: np.ndarray) -> None:
        self.passed[episodes] = 0

    def described(self) -> dict:
        """What its rows' ``execution`` says other than the execution's own entries (a family's controllers: none,
        the execution names them)."""
        return {}

    def actions(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        states, layout = np.asarray(states, np.float64), self.body.layout
        if self.kind == "actions":
            return self._planned_actions(states, plans, np.asarray(age))
        if self.kind == "track":
            return self.body.track(states, tracking_targets(plans, age, layout))
        planned = layout.state_positions(np.asarray(plans, np.float64))
        passed = self.passed
        if self.body.keeps_schedule:
            passed = np.maximum(passed, np.minimum(np.asarray(age) + 1, planned.shape[1] - 1))
        self.passed = pursuit_waypoints(planned, layout.state_positions(states), passed, self.lookahead)
        return self.body.pursue(states, planned[np.arange(len(states)), self.passed])

    def _planned_actions(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        layout = self.body.layout
        plans = np.asarray(plans, np.float64)
        if plans.shape[-1] != layout.transition_dim:
            raise BridgeplanError("--controller actions executes a planner's own planned actions; these decisions plan "
                                  "states alone (use track or pursuit)")
        last = plans.shape[1] - 1
        rows = np.arange(len(plans))
        actions = layout.actions(plans)[rows, np.minimum(age, last)].copy()
        done = age >= last  # the last state's action leads nowhere in the plan: hold that state
        if done.any():
            actions[done] = self.body.track(states[done], tracking_targets(layout.states(plans[done]), age[done],
                                                                           layout))
        return actions

    def drift(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        layout = self.body.layout
        if self.kind == "actions":  # joint plans: their states
            plans = layout.states(np.asarray(plans, np.float64))
        positions = layout.state_positions(np.asarray(states, np.float64))
        planned = layout.state_positions(np.asarray(plans, np.float64))
        if self.kind == "track":
            expected = planned[np.arange(len(planned)), np.minimum(age, planned.shape[1] - 1)]
            return np.linalg.norm(positions - expected, axis=1)
        return np.linalg.norm(planned - positions[:, None], axis=2).min(axis=1)


class PolicyFollower(Follower):
    """Plans executed by a trained goal-conditioned policy instead of the family's body: at step ``t`` of a plan the
    policy's goal is the plan's state ``ahead`` steps on (its last past its end) and ``act(states, goals)`` its action.
    A hierarchy whose low level is a policy (HIQL's form), its subgoals the plan's states: a GCBC or GCIQL policy
    reaches a state a few steps away far more surely than a task's goal (``bridgeplan graph --low`` a GCBC run).
    Drift is ``track``'s."""

    network_calls = 1

    def __init__(self, n: int, body: Body, act: Callable[[np.ndarray, np.ndarray], np.ndarray], ahead: int):
        super().__init__(n, body, "track")
        if ahead < 1:
            raise BridgeplanError(f"a policy's goal must be at least 1 step ahead on the plan, got {ahead}")
        self.act, self.ahead = act, int(ahead)

    def described(self) -> dict:
        return {"controller": "policy", "lookahead": None}

    def actions(self, states: np.ndarray, plans: np.ndarray, age: np.ndarray) -> np.ndarray:
        plans, layout = np.asarray(plans, np.float64), self.body.layout
        if plans.shape[-1] == layout.transition_dim:  # joint plans: their states
            plans = layout.states(plans)
        index = np.minimum(np.asarray(age) + self.ahead, plans.shape[1] - 1)
        return self.act(np.asarray(states, np.float64), plans[np.arange(len(plans)), index])
