"""What the processes that jump along the flow from the prior share (``MeanFlow``, ``Shortcut``).

**The path** is flow matching's straight line (``flow.py`` with ``sigma = 0``) from the data x0 at t = 0 to its
prior sample x1 at t = 1, ``z_t = (1 - t) x0 + t x1``, velocity ``v = dz/dt = x1 - x0``; sampling runs it
backwards, from the prior sample at t = 1 down to the data at t = 0 (the flow's direction: a network that
learned nothing leaves the prior sample where it is).

**The network** takes two time inputs (``TemporalUNet(interval=True)``) and outputs an average velocity
``u(z_t, r, t)``, the jump to time ``r < t`` being ``z_r = z_t - (t - r) u`` (``samplers.jump_sample``). Its
inputs are the time ``steps * t`` (the range [0, N] of the other processes' step indices) and the process's
interval input (:meth:`JumpProcess.interval_input`, 0 for the instantaneous velocity). Sampling takes ``nfe``
equal jumps from t = 1 to 0; ``steps`` (N) is the finest grid, the largest NFE.
"""

from __future__ import annotations

import torch

from bridgeplan.processes.base import Correct, Process
from bridgeplan.processes.flow import linear_interpolant
from bridgeplan.processes.samplers import jump_sample
from bridgeplan.trajectory import Conditions, apply_conditions


class JumpProcess(Process):
    """Base of the processes whose network outputs the average velocity over a jump (see the module docstring)."""

    takes_interval = True
    predicts_x0 = False  # a jump moves z_t by a velocity; no x0 prediction for a correction to transform

    def interval_input(self, r: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """The network's second input for a jump from ``t`` to ``r`` (``[B]`` each)."""
        raise NotImplementedError

    def average_velocity(self, model, z: torch.Tensor, r: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """The network's ``u(z_t, r, t)`` on the batch ``z`` ``[B, H, D]``, times ``r <= t`` ``[B]``."""
        return model(z, self.steps * t, self.interval_input(r, t))

    def path(self, x0: torch.Tensor, x1: torch.Tensor, t: torch.Tensor, conditions: Conditions) -> torch.Tensor:
        """``z_t`` on the straight line from x0 (t = 0) to x1 (t = 1) at times ``t`` ``[B]``, conditions inpainted."""
        a, b, _ = linear_interpolant(t[:, None, None], 0.0)
        return apply_conditions(a * x0 + b * x1, conditions)

    def sample(self, model, x_start: torch.Tensor, conditions: Conditions, nfe: int,
               generator: torch.Generator | None = None, correct: Correct | None = None) -> torch.Tensor:
        """From the prior sample ``x_start`` (t = 1) to a trajectory (t = 0) in ``nfe`` equal jumps (no noise:
        ``generator`` is unused; ``correct`` must be None, see :attr:`predicts_x0`)."""
        self.validate_nfe(nfe)

        def velocity(z: torch.Tensor, r: float, t: float) -> torch.Tensor:
            full = z.new_full((z.shape[0],), 1.0)
            return self.average_velocity(model, z, r * full, t * full)

        return jump_sample(velocity, x_start, conditions, [1 - k / nfe for k in range(nfe + 1)])
