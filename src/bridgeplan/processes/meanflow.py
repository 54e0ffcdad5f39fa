"""Mean flows (Geng et al. 2025, "Mean Flows for One-step Generative Modeling") from the run's prior.

The network predicts the average velocity of the flow from the prior (``jumps.py``: the straight line from the
data x0 at t = 0 to the prior sample x1 at t = 1) over an interval ``[r, t]``,

    u(z_t, r, t) = 1 / (t - r) * integral_r^t v(z_s, s) ds,    so that    z_r = z_t - (t - r) u(z_t, r, t),

and one network call jumps from the prior sample to the data: ``x0 = x1 - u(x1, 0, 1)``. Differentiating
``(t - r) u = integral_r^t v`` in t gives the MeanFlow identity ``u = v - (t - r) du/dt``, with ``du/dt`` the
total derivative along the flow, ``v . d_z u + d_t u`` (r fixed): a Jacobian-vector product of the network with
tangents ``(v, 0, 1)`` on ``(z, r, t)``, by forward-mode AD (``torch.autograd.forward_ad``; the U-Net's fast Mish
supports it, not ``torch.func``'s transforms, see ``nets/unet.py``). Training regresses ``u_theta(z_t, r, t)`` on
``sg(v - (t - r) du_theta/dt)`` with the conditional velocity ``v = x1 - x0`` of the sampled pair; at ``r = t``
that is flow matching's loss on the instantaneous velocity. The network's interval input is
``steps * (t - r)`` (0: the instantaneous velocity), the paper's ``(t, t - r)`` conditioning.

Times: ``t`` and ``r`` uniform in [0, 1], sorted so that ``r <= t``; a share ``1 - interval_share`` of them
with ``r = t`` (the paper's best ratio: 25% of intervals of nonzero length). Loss: per sample, the mean squared
error weighted by ``sg(1 / (error + 1e-3)^adaptive_p)`` (the paper's adaptive weighting; 0: plain L2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch.autograd import forward_ad

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.jumps import JumpProcess
from bridgeplan.trajectory import Conditions

ADAPTIVE_EPS = 1e-3
"""The constant of the adaptive weight ``1 / (error + c)^p`` (the paper's ``c``)."""


@dataclass(frozen=True)
class MeanFlow(JumpProcess):
    """A mean flow from the prior, sampled in any NFE from 1 to ``steps`` (equal jumps); see the module docstring."""

    steps: int = 16
    """The finest grid of jumps (the largest NFE) and the scale of the network's time inputs."""
    interval_share: float = 0.25
    """Share of training draws with ``r < t`` (the rest have ``r = t``: flow matching)."""
    adaptive_p: float = 1.0
    """Power of the adaptive loss weight (0: plain L2)."""
    name = "meanflow"
    display_name = "mean flow"
    forward_mode = True

    def __post_init__(self):
        if self.steps < 1:
            raise BridgeplanError(f"mean flow steps must be >= 1, got {self.steps}")
        if not 0 <= self.interval_share <= 1:
            raise BridgeplanError(f"interval_share must be in [0, 1], got {self.interval_share}")
        if not (math.isfinite(self.adaptive_p) and self.adaptive_p >= 0):
            raise BridgeplanError(f"adaptive_p must be a finite number >= 0, got {self.adaptive_p}")

    def interval_input(self, r: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return self.steps * (t - r)

    def draw_times(self, batch: int, generator: torch.Generator | None, device,
                   dtype) -> tuple[torch.Tensor, torch.Tensor]:
        """``(r, t)`` ``[batch]`` each: uniform, ``r <= t``, and ``r = t`` but for a share ``interval_share``."""
        a, b = torch.rand((2, batch), generator=generator, device=device, dtype=dtype)
        t, r = torch.maximum(a, b), torch.minimum(a, b)
        keep = torch.rand(batch, generator=generator, device=device, dtype=dtype) < self.interval_share
        return torch.where(keep, r, t), t

    def training_terms(self, model, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                       generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(u, target, error)``: the network's average velocity at a draw of ``(z_t, r, t)``, its detached
        MeanFlow target ``v - (t - r) du/dt`` and the squared error per sample ``[B]`` (mean over elements)."""
        r, t = self.draw_times(x0.shape[0], generator, x0.device, x0.dtype)
        z = self.path(x0, x1, t, conditions)
        v = x1 - x0  # zero where the conditions hold: x1 is inpainted with x0's own states

        with forward_ad.dual_level():  # tangents (v, 0, 1) on (z, r, t): r is left a plain tensor
            out = self.average_velocity(model, forward_ad.make_dual(z, v), r,
                                        forward_ad.make_dual(t, torch.ones_like(t)))
            u, dudt = forward_ad.unpack_dual(out)
        target = (v - (t - r)[:, None, None] * dudt).detach()
        error = ((u - target) ** 2).flatten(1).mean(1)
        return u, target, error

    def training_loss(self, model, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> torch.Tensor:
        """The adaptively weighted MeanFlow loss (module docstring)."""
        error = self.training_terms(model, x0, x1, conditions, generator)[2]
        if self.adaptive_p == 0:
            return error.mean()
        weight = (error.detach() + ADAPTIVE_EPS) ** -self.adaptive_p
        return (weight * error).mean()
