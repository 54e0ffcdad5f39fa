"""Consistency corrections of the x0 predictions (CDDB, Chung et al., NeurIPS 2023) and the residuals they reduce.

A sampler calls ``predict_x0(x_n, n)`` (an :data:`~bridgeplan.processes.samplers.X0Predictor`) once per network
call; :func:`corrected` turns it into a predictor whose every x0 prediction is moved down the gradient of a
residual ``R`` (``[B]``, one value per plan, in physical units; the plans of a batch are corrected independently):

- form ``x0`` (CDDB): ``x0_hat <- clip(x0_hat - grad_{x0_hat} sum_r alpha_r R_r(x0_hat))``, the gradient taken
  in x0 space (normalized units, through the normalizer); no extra network call.
- form ``deep`` (CDDB-deep, DPS-like): ``x0_hat <- clip(x0_hat(x_n) - grad_{x_n} sum_r alpha_r R_r(x0_hat(x_n)))``,
  the gradient of the residual of the prediction taken w.r.t. the network's input x_n, through the network (one
  backward pass per call), and applied to x0_hat. Every sampler here steps ``x_m = a x0_hat + b x_n (+ noise)``,
  so this moves x_m by ``-a alpha grad_{x_n} R``: DPS's update of x_m, its step scaled by the posterior's weight
  ``a`` on x0_hat (CDDB-deep puts it on x_m directly; the wrapper keeps the samplers untouched).

Both act on every prediction, the last one (the plan) included; ``clip`` keeps the predictor's [-1, 1] contract
(and the deep gradient passes through ``predict_x0``'s own clip, zero where it clips).

Residuals (``R = 1/2 sum e^2`` over the error ``e`` below, per plan, physical units from the run's normalizer; the
columns from the run's :class:`~bridgeplan.trajectory.Layout`):

- ``conditions``: the start/goal (and held arrival) states the plan is conditioned on, minus the prediction's
  states at those indices (m and m/s), *before* the sampler overwrites them: every sampler overwrites the
  conditioned entries of x_n after each step and of the final plan, so on a sample this residual is 0, but the
  network's prediction there is what CDDB measures. Only the deep form can act on it (the x0 form would move
  only the conditioned entries of x0_hat, which are then overwritten: it is refused).
- ``kinematics``: positions integrate velocities, actions ignored (the tracking controller ignores them): per
  transition of rows ``i -> i + 1`` (``k = stride`` environment steps of ``h`` seconds apart)
  ``e = (p_{i+1} - p_i) / (k h) - vbar_i`` in m/s, ``vbar_i`` the mean velocity over the k steps with the
  velocity linear between rows (as ``trajectory.densify`` hands the plan to the controller):
  ``((k - 1) v_i + (k + 1) v_{i+1}) / (2 k)``; at stride 1, ``v_{i+1}`` (MuJoCo's semi-implicit Euler). For a
  :class:`KinematicPoint` (no velocity: each step moves the position by ``gain * action``) the actions take the
  velocities' place: ``e = (p_{i+1} - p_i) / (k gain) - abar_i`` in action units, ``abar_i`` the mean action over
  the k steps, ``((k + 1) a_i + (k - 1) a_{i+1}) / (2 k)`` (step j moves by row i's action interpolated at j / k).
- ``dynamics``: the whole transition of PointMaze v3's point mass (:data:`POINT_MASS`): from row i's state and
  action, ``k`` steps of ``v <- (m clip(v, -5, 5) + h gear clip(a, -1, 1)) / (m + h damping)``, ``p <- p + h v``
  (MuJoCo's Euler integrator, damping implicit) give the predicted next state; ``e`` is row i+1's state minus it,
  the position part divided by ``k h`` (so both parts are m/s). Exact at stride 1 in free space (walls push);
  at stride k > 1 it holds row i's action for the k steps (zero-order hold): the data do not (their actions change
  every step, with noise), so there a data-like plan has a residual of its own; ``kinematics`` has no actions.
  It needs the velocity columns: a layout without them is refused.

**Step sizes.** alpha is in R's units (m/s squared) against normalized x0: the position parts, divided by k h, make
R stiff there, and one gradient step on them is stable only for ``alpha < (k h)^2 / (2 s_p^2)`` or so (``s_p`` the
normalizer's half-range of a position column): about 1e-4 at stride 2 on umaze's ranges, 4e-4 at stride 8 on
medium's; the velocity parts alone allow about 100 times more. Choose alpha on validation episodes.

:class:`Correction` is the sampling option (``Planner.with_correction``; ``bridgeplan eval --correction``); its
cost is one extra backward pass per network call with the deep form, counted as two forward passes
(:meth:`Correction.network_call_equivalents`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.normalizer import Normalizer
from bridgeplan.processes.samplers import X0Predictor
from bridgeplan.trajectory import Conditions, Layout

RESIDUALS = ("conditions", "kinematics", "dynamics")
FORMS = ("x0", "deep")
BACKWARD_COST = 2
"""Forward passes one backward pass through the network is counted as (its FLOPs: the usual 2x)."""


@dataclass(frozen=True)
class PointMass:
    """PointMaze v3's point mass as gymnasium-robotics builds it (``assets/point/point.xml``, PointEnv)."""

    timestep: float = 0.01
    gear: float = 100.0
    damping: float = 1.0
    mass: float = 4 / 3 * math.pi * 0.1 ** 3 * 1000.0
    """A sphere of radius 0.1 and density 1000 (MuJoCo's inertia from geom)."""
    frame_skip: int = 1
    max_speed: float = 5.0
    """PointEnv clips each velocity component to this before every step (``maze.sim.MAX_SPEED``)."""

    def step(self, pos: torch.Tensor, vel: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One environment step: velocity clipped, then ``frame_skip`` MuJoCo Euler steps (implicit damping)."""
        vel = vel.clamp(-self.max_speed, self.max_speed)
        force = self.gear * action.clamp(-1.0, 1.0)
        for _ in range(self.frame_skip):
            h = self.timestep
            vel = (self.mass * vel + h * force) / (self.mass + h * self.damping)
            pos = pos + h * vel
        return pos, vel

    @property
    def step_seconds(self) -> float:
        return self.timestep * self.frame_skip

    @property
    def position_step(self) -> float:
        """Position moved per environment step per unit of velocity: the step's seconds."""
        return self.step_seconds

    def mean_rate(self, traj: torch.Tensor, layout: Layout, stride: int) -> torch.Tensor:
        """``[B, H - 1, 2]`` the mean velocity over each transition's ``stride`` steps (semi-implicit Euler: step j
        moves by the velocity at j + 1)."""
        _require_velocity(layout, "kinematics")
        vel = layout.velocities(traj)
        k = stride
        return ((k - 1) * vel[:, :-1] + (k + 1) * vel[:, 1:]) / (2 * k)


POINT_MASS = PointMass()


@dataclass(frozen=True)
class KinematicPoint:
    """A point that its action moves directly (OGBench pointmaze): each environment step adds ``gain * action``
    to the position. The gain is the environment's (OGBench: 0.2), given by whoever builds the environment."""

    gain: float

    @property
    def position_step(self) -> float:
        """Position moved per environment step per unit of action."""
        return self.gain

    def mean_rate(self, traj: torch.Tensor, layout: Layout, stride: int) -> torch.Tensor:
        """``[B, H - 1, 2]`` the mean action over each transition's ``stride`` steps (step j moves by the action at
        j, linear between rows as ``trajectory.densify`` hands it on)."""
        act = layout.actions(traj)
        k = stride
        return ((k + 1) * act[:, :-1] + (k - 1) * act[:, 1:]) / (2 * k)


Body = PointMass | KinematicPoint
"""What moves a plan's position, the environment's: PointMaze's point mass or a kinematic point."""


def _require_velocity(layout: Layout, residual: str) -> None:
    """PointMaze's point mass moves by its velocity: refuse a layout without one (a mistake of the caller's)."""
    if not layout.has_velocity:
        raise BridgeplanError(f"the {residual} residual of PointMaze's point mass needs velocities, and the "
                              f"{layout.name} layout has none")


def _physical(x0: torch.Tensor, normalizer: Normalizer) -> torch.Tensor:
    return normalizer.unnormalize(x0)


def kinematics_error(traj: torch.Tensor, layout: Layout, stride: int, body: Body = POINT_MASS) -> torch.Tensor:
    """``[B, H - 1, 2]`` of physical trajectories ``traj [B, H, D]`` in ``layout``, in the units of ``body``'s rate
    (point mass: m/s; kinematic point: action units): see the module docstring."""
    pos = layout.positions(traj)
    return (pos[:, 1:] - pos[:, :-1]) / (stride * body.position_step) - body.mean_rate(traj, layout, stride)


def dynamics_error(traj: torch.Tensor, layout: Layout, stride: int, body: PointMass = POINT_MASS) -> torch.Tensor:
    """``[B, H - 1, 4]`` (m/s) of physical trajectories ``traj [B, H, D]`` in ``layout`` (which needs the
    velocity): see the module docstring."""
    _require_velocity(layout, "dynamics")
    prev = traj[:, :-1]
    action, pos, vel = layout.actions(prev), layout.positions(prev), layout.velocities(prev)
    for _ in range(stride):
        pos, vel = body.step(pos, vel, action)
    nxt = traj[:, 1:]
    return torch.cat([(layout.positions(nxt) - pos) / (stride * body.step_seconds), layout.velocities(nxt) - vel],
                     dim=-1)


def conditions_error(traj: torch.Tensor, conditions: Conditions, normalizer: Normalizer,
                     layout: Layout) -> torch.Tensor:
    """``[B, len(conditions), obs_dim]`` the conditioned states minus ``traj``'s there (physical; 0 where a row is
    NaN)."""
    if not conditions:
        return traj.new_zeros(traj.shape[0], 0, layout.obs_dim)
    index = sorted(conditions)
    wanted = torch.stack([conditions[t].to(traj.device, traj.dtype) for t in index], dim=1)
    wanted = normalizer.unnormalize(wanted, layout.state_columns)
    have = layout.states(traj[:, index])
    return torch.where(torch.isnan(wanted), torch.zeros_like(have), wanted - have)


def residual(name: str, x0: torch.Tensor, normalizer: Normalizer, layout: Layout, stride: int,
             conditions: Conditions | None = None, body: Body = POINT_MASS) -> torch.Tensor:
    """``R = 1/2 sum e^2`` per plan ``[B]`` of the normalized trajectories ``x0 [B, H, D]`` in ``layout``
    (differentiable); ``body`` moves the position in ``kinematics``."""
    traj = _physical(x0, normalizer)
    if name == "conditions":
        err = conditions_error(traj, conditions or {}, normalizer, layout)
    elif name == "kinematics":
        err = kinematics_error(traj, layout, stride, body)
    elif name == "dynamics":
        err = dynamics_error(traj, layout, stride)
    else:
        raise BridgeplanError(f"unknown residual {name!r}: choose from {', '.join(RESIDUALS)}")
    return 0.5 * err.pow(2).flatten(1).sum(1)


def plan_residuals(x0: torch.Tensor, normalizer: Normalizer, layout: Layout, stride: int) -> dict[str, np.ndarray]:
    """Root-mean-square ``kinematics`` and ``dynamics`` errors (m/s) per plan ``[B]`` of the normalized plans
    ``x0``: how far a sampled plan is from the point mass's motion (the ``conditions`` one is 0 on a sample)."""
    with torch.inference_mode(False), torch.no_grad():
        traj = _physical(x0.detach().clone().double(), normalizer)
        return {f"{name}_rms": fn(traj, layout, stride).pow(2).flatten(1).mean(1).sqrt().cpu().numpy()
                for name, fn in (("kinematics", kinematics_error), ("dynamics", dynamics_error))}


Objective = Callable[[torch.Tensor], torch.Tensor]
"""``objective(x0) -> [B]``: the weighted residual ``sum_r alpha_r R_r`` of normalized trajectories, per plan."""


def corrected(predict: X0Predictor, objective: Objective, form: str) -> X0Predictor:
    """``predict`` with every x0 prediction moved down the gradient of ``objective`` (``form`` x0 or deep: see the
    module docstring); the step sizes are in ``objective``. Works inside ``torch.inference_mode`` too."""
    check_choice("correction form", form, FORMS)

    def predict_corrected(x_n: torch.Tensor, n: int) -> torch.Tensor:
        if form == "x0":
            x0 = predict(x_n, n)
        with torch.inference_mode(False), torch.enable_grad():  # clones of inference tensors are normal ones
            if form == "x0":
                x0 = x0.clone().detach()
                wrt = x0.clone().requires_grad_(True)
                total = objective(wrt).sum()
            else:
                wrt = x_n.clone().requires_grad_(True)
                x0 = predict(wrt, n)
                total = objective(x0).sum()
            (grad,) = torch.autograd.grad(total, wrt)
        return (x0.detach() - grad).clamp(-1, 1)

    return predict_corrected


@dataclass(frozen=True)
class Correction:
    """A sampling option: which residuals, their step sizes (alpha, in ``R``'s physical units) and the form.

    ``Correction.parse(["dynamics=0.01"], "deep")``; :meth:`wrap` makes the predictor transform one plan batch
    samples with.
    """

    steps: tuple[tuple[str, float], ...]
    """``((residual, alpha), ...)``, each residual once, sorted by name."""
    form: str = "x0"

    def __post_init__(self):
        if not self.steps:
            raise BridgeplanError("a correction needs at least one residual (--correction RESIDUAL=STEP)")
        names = [name for name, _ in self.steps]
        for name, alpha in self.steps:
            check_choice("residual", name, RESIDUALS)
            if not math.isfinite(alpha) or alpha < 0:
                raise BridgeplanError(f"the step size of the {name} correction must be a finite number >= 0, "
                                      f"got {alpha}")
        if len(set(names)) != len(names):
            raise BridgeplanError(f"each residual takes one step size, got {', '.join(names)}")
        check_choice("correction form", self.form, FORMS)
        if self.form == "x0" and "conditions" in names:
            raise BridgeplanError("the conditions correction in x0 form would move only the conditioned entries of "
                                  "x0_hat, which every sampler overwrites (no effect): use --correction-form deep")
        object.__setattr__(self, "steps", tuple(sorted((n, float(a)) for n, a in self.steps)))

    @classmethod
    def parse(cls, specs: list[str], form: str = "x0") -> Correction:
        """``["dynamics=0.01", "kinematics=1e-4"]`` (``--correction`` values) and the form."""
        steps = []
        for text in specs:
            name, sep, value = text.partition("=")
            name = name.strip()
            if not sep:
                raise BridgeplanError(f"--correction takes RESIDUAL=STEP ({', '.join(RESIDUALS)}), got {text!r}")
            try:
                alpha = float(value)
            except ValueError:
                raise BridgeplanError(f"--correction {name}: the step size must be a number, got {value!r}") from None
            steps.append((name, alpha))
        return cls(tuple(steps), form)

    def tag(self) -> str:
        """How results name it, e.g. ``cddb-deep dynamics=0.01`` (the store's ``sampler`` column:
        :func:`sampling_tag`)."""
        return f"cddb-{self.form} " + " ".join(f"{n}={a:g}" for n, a in self.steps)

    def file_tag(self) -> str:
        """The same without spaces, for file names: ``cddb-deep-dynamics0.01``."""
        return f"cddb-{self.form}-" + "-".join(f"{n}{a:g}" for n, a in self.steps)

    def backward_passes(self, nfe: int) -> int:
        """Backward passes through the network per plan: one per call with the deep form."""
        return nfe if self.form == "deep" else 0

    def network_call_equivalents(self, nfe: int) -> int:
        """Forward passes per plan, a backward pass counted as :data:`BACKWARD_COST` of them."""
        return nfe + BACKWARD_COST * self.backward_passes(nfe)

    def to_dict(self, nfe: int) -> dict:
        return {"form": self.form, "steps": dict(self.steps), "tag": self.tag(), "forward_passes_per_plan": nfe,
                "backward_passes_per_plan": self.backward_passes(nfe),
                "network_call_equivalents_per_plan": self.network_call_equivalents(nfe)}

    def objective(self, conditions: Conditions, normalizer: Normalizer, layout: Layout, stride: int) -> Objective:
        """``x0 -> sum_r alpha_r R_r(x0)`` per plan, for one batch's conditions."""
        def total(x0: torch.Tensor) -> torch.Tensor:
            return sum(alpha * residual(name, x0, normalizer, layout, stride, conditions)
                       for name, alpha in self.steps)

        return total

    def wrap(self, conditions: Conditions, normalizer: Normalizer, layout: Layout,
             stride: int) -> Callable[[X0Predictor], X0Predictor]:
        """The predictor transform a process's ``sample(..., correct=...)`` takes, for one batch."""
        if conditions:  # inference tensors (a plan made under inference_mode) cannot enter autograd: copy them
            with torch.inference_mode(False):
                conditions = {t: c.clone() for t, c in conditions.items()}
        objective = self.objective(conditions, normalizer, layout, stride)
        return lambda predict: corrected(predict, objective, self.form)


def sampling_tag(process_tag: str, correction: Correction | None) -> str:
    """The results store's ``sampler`` of an evaluation: the process's ``sampling_tag()`` and the correction's
    :meth:`Correction.tag`, if any, e.g. ``mean cddb-x0 dynamics=0.0001`` ('' sampled as trained, uncorrected).
    The row (``EvalResult.sampling_tag``) and the runner's "missing" key (``Series.sampling_tag``) both use it."""
    return " ".join(t for t in (process_tag, correction.tag() if correction is not None else "") if t)
