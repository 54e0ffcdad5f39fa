"""The planner: normalizer + prior + process + network -> plans for a batch of (start, goal)."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import torch

from bridgeplan.consistency import Correction, plan_residuals
from bridgeplan.errors import BridgeplanError
from bridgeplan.normalizer import Normalizer
from bridgeplan.priors import Prior
from bridgeplan.processes import Process
from bridgeplan.trajectory import Conditions, Layout, densify


@dataclass
class Plan:
    """Plans in physical units and what they cost."""

    states: np.ndarray
    """``[N, S, obs_dim]`` planned states (Maze2D: x, y, vx, vy) at every environment step:
    ``S = (H - 1) * stride + 1`` (the planned states, linearly interpolated between them at a stride)."""
    actions: np.ndarray
    """``[N, S, act_dim]`` planned actions (Maze2D's tracking controller ignores them, as Diffuser's did)."""
    prior_seconds: float
    """Wall time to sample the prior for the whole batch."""
    sample_seconds: float
    """Wall time of the sampler (the network calls, and the correction's work) for the whole batch."""
    sampled: torch.Tensor | None = None
    """The plans as sampled ``[N, H, D]``, normalized and not densified (``Planner.residuals`` measures them)."""


@dataclass
class Planner:
    model: torch.nn.Module
    process: Process
    prior: Prior
    normalizer: Normalizer
    horizon: int
    device: torch.device
    layout: Layout
    """The columns of the plans: the run's environment's (``TrainConfig.layout``)."""
    stride: int = 1
    """Environment steps between planned states (``TrainConfig.stride``)."""
    correction: Correction | None = None
    """A consistency correction of every x0 prediction (CDDB, ``consistency.py``); None: the process as trained."""
    subgoal_every: int = 0
    """A hierarchy's low level (``TrainConfig.subgoal_every``): it plans between subgoals, every this many planned
    states (:meth:`plan`'s ``subgoals``); 0: from a start to a goal."""

    def with_sampler(self, sampler: str, eta: float = 0.0) -> Planner:
        """The same network sampled another way (no reload): ``process.with_sampler``."""
        return dataclasses.replace(self, process=self.process.with_sampler(sampler, eta))

    def with_correction(self, correction: Correction | None) -> Planner:
        """The same network with every x0 prediction corrected (None: uncorrected); needs a process that samples
        through x0 predictions."""
        if correction is not None and not self.process.predicts_x0:
            raise BridgeplanError(f"--correction corrects x0 predictions, and {self.process.name} does not sample "
                                  f"through them")
        return dataclasses.replace(self, correction=correction)

    def with_prior(self, prior: Prior) -> Planner:
        return dataclasses.replace(self, prior=prior)

    @property
    def subgoals_per_plan(self) -> int:
        """Subgoals a low level's plan is conditioned on (the last one at H - 1); 0 for a planner to a goal."""
        return (self.horizon - 1) // self.subgoal_every if self.subgoal_every else 0

    def conditions(self, starts: np.ndarray, goals: np.ndarray | None, arrival: np.ndarray | None = None,
                   subgoals: np.ndarray | None = None) -> Conditions:
        """Normalized conditions: the start state at t=0, the goal at rest (zero velocity, if the state has one;
        where the layout names goal columns, a goal observation's columns alone: ``Layout.goal_states``) at t=H-1
        and, for a plan with an ``arrival`` index ``a < H - 1`` (``[N]``, planned states), at every
        t >= a as well (held). A low level takes ``subgoals`` ``[N, m, obs_dim]`` (whole states) at
        ``j, 2j, ..., H - 1`` instead of a goal."""
        state_dims = self.layout.state_columns

        def norm(s: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(self.normalizer.normalize(s, state_dims), dtype=torch.float32,
                                   device=self.device)

        if (subgoals is not None) != bool(self.subgoal_every):
            raise BridgeplanError("this planner is a hierarchy's low level: it plans between a high level's "
                                  "subgoals (bridgeplan hierarchy eval)" if self.subgoal_every else
                                  "subgoals are for a hierarchy's low level (a run trained with --subgoal-every)")
        if subgoals is not None:
            subgoals = np.asarray(subgoals, dtype=np.float64)
            want = (len(starts), self.subgoals_per_plan, self.layout.obs_dim)
            if subgoals.shape != want or arrival is not None:
                raise BridgeplanError(f"a low level plans to {list(want)} subgoals (no arrival hold), got "
                                      f"{list(subgoals.shape)}")
            every = self.subgoal_every
            return {0: norm(starts), **{every * (i + 1): norm(subgoals[:, i]) for i in range(want[1])}}
        goal = norm(self.layout.goal_states(goals))
        conditions = {0: norm(starts), self.horizon - 1: goal}
        if arrival is not None:
            arrival = torch.as_tensor(np.asarray(arrival), device=self.device)[:, None]
            for t in range(max(int(arrival.min()), 1), self.horizon - 1):
                conditions[t] = torch.where(arrival <= t, goal, torch.nan)
        return conditions

    def unnormalize(self, x: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
        traj = self.normalizer.unnormalize(x.double().cpu().numpy())
        return self.layout.states(traj), self.layout.actions(traj)

    @torch.inference_mode()
    def plan(self, starts: np.ndarray, goals: np.ndarray | None, nfe: int, generator: torch.Generator,
             prior_only: bool = False, arrival: np.ndarray | None = None,
             subgoals: np.ndarray | None = None) -> Plan:
        """Plan from ``starts`` ``[N, obs_dim]`` to goal positions ``goals`` ``[N, 2]`` (goal observations
        ``[N, obs_dim]`` where the layout names goal columns) with ``nfe`` network calls.

        ``prior_only`` returns the prior sample itself (the floor every model must beat). ``arrival`` ``[N]``
        (planned states): hold the goal from there on (:meth:`conditions`). A low level plans through
        ``subgoals`` instead of to ``goals`` (None).
        """
        conditions = self.conditions(starts, goals, arrival, subgoals)
        t0 = _now(self.device)
        x = self.prior.sample(conditions, self.horizon, len(starts), generator=generator)
        t1 = _now(self.device)
        if not prior_only:
            extra = ({} if self.correction is None
                     else {"correct": self.correction.wrap(conditions, self.normalizer, self.layout, self.stride)})
            x = self.process.sample(self.model, x, conditions, nfe, generator=generator, **extra)
        t2 = _now(self.device)
        states, actions = self.unnormalize(x)
        return Plan(densify(states, self.stride), densify(actions, self.stride), t1 - t0, t2 - t1, x)

    def residuals(self, plan: Plan) -> dict[str, np.ndarray]:
        """``kinematics_rms``, ``dynamics_rms`` ``[N]`` (m/s) of ``plan`` as sampled (``consistency.plan_residuals``;
        computed on request, off the planning path)."""
        return plan_residuals(plan.sampled, self.normalizer, self.layout, self.stride)


def _now(device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()
