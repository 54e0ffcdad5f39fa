"""The I2SB bridge (Liu et al. 2023) between a prior trajectory x1 and the target x0."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.base import Process
from bridgeplan.processes.samplers import bridge_sample
from bridgeplan.processes.schedules import bridge_stds, chain_marginal, gaussian_product, i2sb_betas, spaced_steps
from bridgeplan.trajectory import Conditions, apply_conditions


@dataclass(frozen=True)
class Bridge(Process):
    """I2SB over ``steps`` (N) discrete steps with the symmetric schedule up to ``beta_max``.

    The network follows I2SB's parametrization: it predicts ``(x_n - x0) / std_fwd[n]``, so
    ``x0_hat = x_n - std_fwd[n] * out``. Sampling takes any NFE from 1 to N - 1.

    ``consistent`` trains on the marginal the sampling chain itself implies (``schedules.chain_marginal``)
    instead of I2SB's product of ``(std_fwd[n], std_bwd[n])``, whose variances count ``beta_n`` twice
    (harmless at N = 1000, not at N = 16), and only at the steps 1..N-1 where the chain calls the
    network; x_{N-1} is then x1 itself, where the chain starts. Sampling is the same either way.
    """

    steps: int = 16
    beta_max: float = 1.0
    ot_ode: bool = False
    consistent: bool = False
    name = "bridge"
    display_name = "bridge"

    def __post_init__(self):
        if self.steps < 2:
            raise BridgeplanError(f"the bridge needs at least 2 diffusion steps, got {self.steps}")
        if self.beta_max <= 0:
            raise BridgeplanError(f"beta_max must be positive, got {self.beta_max}")

    @cached_property
    def betas(self) -> torch.Tensor:
        return i2sb_betas(self.steps, self.beta_max)

    @cached_property
    def std_fwd(self) -> torch.Tensor:
        return bridge_stds(self.betas)[0]

    @cached_property
    def std_bwd(self) -> torch.Tensor:
        return bridge_stds(self.betas)[1]

    @property
    def max_nfe(self) -> int:
        return self.steps - 1

    def validate_nfe(self, nfe: int) -> None:
        if not 1 <= nfe <= self.max_nfe:
            raise BridgeplanError(f"nfe must be in 1..{self.max_nfe} for the bridge with {self.steps} steps "
                                  f"(NFE < N), got {nfe}")

    @cached_property
    def marginal_coefs(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(mu0, mu1, var)`` per step of the training marginal of x_n given (x0, x1)."""
        if self.consistent:
            return chain_marginal(self.std_fwd)
        return gaussian_product(self.std_fwd, self.std_bwd)

    def marginal(self, x0: torch.Tensor, x1: torch.Tensor, n: torch.Tensor,
                 generator: torch.Generator | None = None) -> torch.Tensor:
        """Sample x_n given (x0, x1): ``mu0 x0 + mu1 x1 + sqrt(var) eps`` (no noise with ``ot_ode``)."""
        mu0, mu1, var = (c.to(x0.device, x0.dtype)[n][:, None, None] for c in self.marginal_coefs)
        x_n = mu0 * x0 + mu1 * x1
        if not self.ot_ode:
            eps = torch.randn(x0.shape, generator=generator, device=x0.device, dtype=x0.dtype)
            x_n = x_n + var.sqrt() * eps
        return x_n

    def predict_x0(self, model, x_n: torch.Tensor, n: int) -> torch.Tensor:
        return (x_n - float(self.std_fwd[n]) * self.network(model, x_n, n)).clamp(-1, 1)

    def training_target(self, x0: torch.Tensor, x_n: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
        """I2SB's label ``(x_n - x0) / std_fwd[n]``, the inverse of ``predict_x0``."""
        return (x_n - x0) / self.std_fwd.to(x0.device, x0.dtype)[n][:, None, None]

    def training_pair(self, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(x_n, n, target)`` at a uniform random step n in [0, N-1] ([1, N-1] with ``consistent``)."""
        low = 1 if self.consistent else 0
        n = torch.randint(low, self.steps, (x0.shape[0],), generator=generator, device=x0.device)
        x_n = apply_conditions(self.marginal(x0, x1, n, generator), conditions)
        return x_n, n, self.training_target(x0, x_n, n)

    def sample(self, model, x_start: torch.Tensor, conditions: Conditions, nfe: int,
               generator: torch.Generator | None = None) -> torch.Tensor:
        """From the prior sample ``x_start`` to a trajectory in ``nfe`` network calls."""
        self.validate_nfe(nfe)
        return bridge_sample(lambda x, n: self.predict_x0(model, x, n), x_start, conditions,
                             spaced_steps(self.steps, nfe), self.std_fwd, self.ot_ode, generator)
