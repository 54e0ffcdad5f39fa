"""Shortcut models (Frans et al. 2024, "One Step Diffusion via Shortcut Models") on the flow from the run's prior.

The network ``s(z_t, t, d)`` is conditioned on a step size ``d`` and predicts the average velocity of the flow
from the prior (``jumps.py``) over the jump from t to ``t - d``: ``z_{t-d} = z_t - d s(z_t, t, d)``. Trained
from scratch on two targets at once:

- **flow matching** at the finest step ``d = 1 / N`` (taken as the instantaneous velocity, as the paper does at
  its finest level): ``s(z_t, t, 1/N)`` regresses ``v = x1 - x0`` at uniform times t;
- **self-consistency** on a share ``bootstrap_share`` of the batch: one jump of ``2d`` is two jumps of ``d``,
  ``s(z_t, t, 2d) <- sg((s(z_t, t, d) + s(z', t - d, d)) / 2)`` with ``z' = z_t - d s(z_t, t, d)``, at
  ``2d = 2^-j`` (j uniform in 0..log2(N) - 1) and times t on the grid of ``2d``.

``steps`` (N) must be a power of two; sampling takes ``nfe`` equal jumps of ``d = 1 / nfe``, so the NFE must be
a power of two up to N (the step sizes the network was trained on). The network's interval input is
``N d - 1``: 0 for the finest step (flow matching's), N - 1 for the single jump.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.jumps import JumpProcess
from bridgeplan.trajectory import Conditions, apply_conditions


def is_power_of_two(n: int) -> bool:
    return n >= 1 and n & (n - 1) == 0


@dataclass(frozen=True)
class Shortcut(JumpProcess):
    """A shortcut model from the prior, sampled in a power-of-two NFE up to ``steps``; see the module docstring."""

    steps: int = 16
    """The finest step is ``1 / steps`` (a power of two: the largest NFE)."""
    bootstrap_share: float = 0.25
    """Share of each batch trained on self-consistency (the rest on flow matching)."""
    name = "shortcut"
    display_name = "shortcut"

    def __post_init__(self):
        if not is_power_of_two(self.steps):
            raise BridgeplanError(f"shortcut steps must be a power of two (step sizes halve), got {self.steps}")
        if not 0 <= self.bootstrap_share <= 1:
            raise BridgeplanError(f"bootstrap_share must be in [0, 1], got {self.bootstrap_share}")

    def validate_nfe(self, nfe: int) -> None:
        if not (is_power_of_two(nfe) and nfe <= self.max_nfe):
            raise BridgeplanError(f"nfe must be a power of two up to {self.max_nfe} for the shortcut model with "
                                  f"{self.steps} steps (it jumps by the step sizes it was trained on), got {nfe}")

    def interval_input(self, r: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return self.steps * (t - r) - 1

    def training_targets(self, model, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                         generator: torch.Generator | None = None
                         ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(z_t, r, t, target)`` for the whole batch: flow matching's ``(r = t - 1/N, v)`` on the first rows,
        self-consistency's ``(r = t - 2d, sg(two jumps of d))`` on the last ``bootstrap_share`` of them."""
        batch, n = x0.shape[0], self.steps
        levels = n.bit_length() - 1  # step sizes 2d = 1, 1/2, ..., 2/N
        boot = round(batch * self.bootstrap_share) if levels else 0
        t = torch.rand(batch, generator=generator, device=x0.device, dtype=x0.dtype).clamp_min(1 / n)
        jump = torch.full_like(t, 1 / n)
        if boot:
            two_d = 0.5 ** torch.randint(0, levels, (boot,), generator=generator, device=x0.device).to(x0.dtype)
            grid = torch.floor(torch.rand(boot, generator=generator, device=x0.device, dtype=x0.dtype) / two_d)
            t[batch - boot:], jump[batch - boot:] = (grid + 1) * two_d, two_d
        z = self.path(x0, x1, t, conditions)
        target = x1 - x0
        if boot:
            rows = slice(batch - boot, None)
            zb, tb, d = z[rows], t[rows], jump[rows] / 2
            with torch.no_grad():
                first = self.average_velocity(model, zb, tb - d, tb)
                mid = apply_conditions(zb - d[:, None, None] * first, {k: c[rows] for k, c in conditions.items()})
                second = self.average_velocity(model, mid, tb - 2 * d, tb - d)
            target = torch.cat([target[:batch - boot], (first + second) / 2])
        return z, t - jump, t, target

    def training_loss(self, model, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> torch.Tensor:
        z, r, t, target = self.training_targets(model, x0, x1, conditions, generator)
        return torch.mean((self.average_velocity(model, z, r, t) - target) ** 2)
