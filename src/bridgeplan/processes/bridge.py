"""The I2SB bridge (Liu et al. 2023) between a prior trajectory x1 and the target x0."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import torch

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.processes.base import Correct, Process
from bridgeplan.processes.samplers import bridge_sample
from bridgeplan.processes.schedules import bridge_stds, chain_marginal, gaussian_product, i2sb_betas, spaced_steps
from bridgeplan.trajectory import Conditions, apply_conditions

PREDICTIONS = ("eps", "x0", "ddbm")
WEIGHTINGS = ("i2sb", "uniform", "ddbm")
SAMPLERS = ("posterior", "mean")


@dataclass(frozen=True)
class Bridge(Process):
    """I2SB over ``steps`` (N) discrete steps with the symmetric schedule up to ``beta_max``.

    The network follows I2SB's parametrization: it predicts ``(x_n - x0) / std_fwd[n]``, so
    ``x0_hat = x_n - std_fwd[n] * out``. Sampling takes any NFE from 1 to N - 1.

    ``predict`` and ``weighting`` take the loss apart for an ablation (issue 15: why DDPM, trained as Diffuser
    does on x0 with equal weight per step, lags the bridge early). Every variant is a weighted L2 on x0,
    ``w(n) |x0_hat - x0|^2``: ``weighting`` ``i2sb`` is I2SB's ``w = 1 / std_fwd[n]^2`` (its plain L2 on the
    scaled difference), ``uniform`` is Diffuser's ``w = 1``; ``predict`` only changes what the network outputs
    (``eps``: the scaled difference, ``x0``: the trajectory), so at one weighting the objective is the same
    function of ``x0_hat`` and the two differ in the network's output alone.

    ``predict`` ``ddbm`` is the parametrization of denoising diffusion bridge models (Zhou et al., ICLR 2024), EDM's
    preconditioning carried to a bridge: ``x0_hat = c_skip x_n + c_out F(c_in x_n, n)`` where, with the marginal
    ``x_n = b x0 + a x1 + c eps`` (``marginal_coefs``) and the second moments ``sigma_0^2`` (x0's), ``sigma_1^2``
    (x1's) and ``sigma_01`` (their covariance) of the normalized data and prior, ``c_in`` gives the network's input
    unit variance, ``c_skip`` is the regression of x0 on x_n and ``c_out`` the rest's standard deviation, so that
    the label ``(x0 - c_skip x_n) / c_out`` has unit variance at every step (:meth:`ddbm_scalings`). Its own weighting,
    ``weighting="ddbm"``, is ``w = 1 / c_out^2`` on the x0 error: an equal weight on the network's output. The
    defaults are DDBM's (``sigma_data`` 0.5 for both ends, no covariance); the sampler is unchanged.

    ``consistent`` trains on the marginal the sampling chain itself implies (``schedules.chain_marginal``)
    instead of I2SB's product of ``(std_fwd[n], std_bwd[n])``, whose variances count ``beta_n`` twice
    (harmless at N = 1000, not at N = 16), and only at the steps 1..N-1 where the chain calls the
    network; x_{N-1} is then x1 itself, where the chain starts. Sampling is the same either way.

    ``sampler`` chooses how a trained bridge is sampled (no retraining): ``posterior`` is I2SB's chain, each step
    a draw from the Gaussian posterior; ``mean`` takes each posterior's mean, no noise (I2SB's OT-ODE sampler on
    a bridge trained with noise). Why ``mean``: at N = 16 the network does not remove the noise the posterior
    steps put in, and the plans come out ragged from NFE 2 on (docs/history/plan-roughness.md).
    """

    steps: int = 16
    beta_max: float = 1.0
    ot_ode: bool = False
    consistent: bool = False
    predict: str = "eps"
    """What the network outputs: ``eps`` I2SB's ``(x_n - x0) / std_fwd[n]``, ``x0`` the clean trajectory, ``ddbm``
    DDBM's preconditioned ``(x0 - c_skip[n] x_n) / c_out[n]`` from ``c_in[n] x_n``."""
    weighting: str = "i2sb"
    """Per-step weight of the squared x0 error: ``i2sb`` ``1 / std_fwd[n]^2`` (I2SB), ``uniform`` 1 (Diffuser),
    ``ddbm`` ``1 / c_out[n]^2`` (DDBM's)."""
    sigma_0: float = 0.5
    """``predict="ddbm"``: the standard deviation of the (normalized) data it assumes."""
    sigma_1: float = 0.5
    """``predict="ddbm"``: the standard deviation of the prior's samples it assumes."""
    sigma_01: float = 0.0
    """``predict="ddbm"``: the covariance of a datum and its prior sample it assumes."""
    sampler: str = "posterior"
    """``posterior`` (I2SB's chain, with noise) or ``mean`` (the posterior means, no noise); training ignores it."""
    name = "bridge"
    display_name = "bridge"
    sampling_fields = ("sampler",)
    samplers = SAMPLERS

    def __post_init__(self):
        if self.steps < 2:
            raise BridgeplanError(f"the bridge needs at least 2 diffusion steps, got {self.steps}")
        if self.beta_max <= 0:
            raise BridgeplanError(f"beta_max must be positive, got {self.beta_max}")
        check_choice("prediction", self.predict, PREDICTIONS)
        check_choice("weighting", self.weighting, WEIGHTINGS)
        check_choice("sampler", self.sampler, SAMPLERS)
        if not (self.sigma_0 > 0 and self.sigma_1 > 0 and self.sigma_01 ** 2 < (self.sigma_0 * self.sigma_1) ** 2):
            raise BridgeplanError(f"ddbm's moments need sigma_0 > 0, sigma_1 > 0 and |sigma_01| < sigma_0 sigma_1, got "
                                  f"{self.sigma_0}, {self.sigma_1}, {self.sigma_01}")

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
        """A bridge's chain has N - 1 steps: NFE < N."""
        return self.steps - 1

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

    @cached_property
    def ddbm_scalings(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(c_in, c_skip, c_out)`` per step of ``predict="ddbm"`` (see the class docstring; ``ot_ode``: no noise)."""
        b, a, var = self.marginal_coefs
        c2 = torch.zeros_like(var) if self.ot_ode else var
        s0, s1, s01 = self.sigma_0 ** 2, self.sigma_1 ** 2, self.sigma_01
        total = a ** 2 * s1 + b ** 2 * s0 + 2 * a * b * s01 + c2  # Var(x_n)
        c_out = (a ** 2 * (s0 * s1 - s01 ** 2) + s0 * c2).sqrt() / total.sqrt()
        return total.rsqrt(), (b * s0 + a * s01) / total, c_out

    def network_input(self, x_n: torch.Tensor, n: int | torch.Tensor) -> torch.Tensor:
        if self.predict != "ddbm":
            return x_n
        c_in = self.ddbm_scalings[0].to(x_n.device, x_n.dtype)[n]
        return x_n * (c_in if c_in.dim() == 0 else c_in[:, None, None])

    def predict_x0(self, model, x_n: torch.Tensor, n: int) -> torch.Tensor:
        if self.predict == "x0":
            return super().predict_x0(model, x_n, n)
        if self.predict == "ddbm":
            _, c_skip, c_out = self.ddbm_scalings
            return (float(c_skip[n]) * x_n + float(c_out[n]) * self.network(model, x_n, n)).clamp(-1, 1)
        return (x_n - float(self.std_fwd[n]) * self.network(model, x_n, n)).clamp(-1, 1)

    def training_target(self, x0: torch.Tensor, x_n: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
        """The label, the inverse of ``predict_x0``: I2SB's ``(x_n - x0) / std_fwd[n]``, x0 itself, or DDBM's
        ``(x0 - c_skip[n] x_n) / c_out[n]``."""
        if self.predict == "x0":
            return x0
        if self.predict == "ddbm":
            _, c_skip, c_out = (c.to(x0.device, x0.dtype)[n][:, None, None] for c in self.ddbm_scalings)
            return (x0 - c_skip * x_n) / c_out
        return (x_n - x0) / self.std_fwd.to(x0.device, x0.dtype)[n][:, None, None]

    def output_weight(self, n: torch.Tensor) -> torch.Tensor | None:
        """Weight per sample of the squared error of the network's output that makes the loss ``w(n) |x0_hat -
        x0|^2`` (the x0 error is the output's times ``std_fwd[n]`` with ``eps``, ``c_out[n]`` with ``ddbm``); None
        where it is 1 (each prediction with its own weighting: I2SB's loss computed exactly as before)."""
        if self.weighting == {"eps": "i2sb", "x0": "uniform", "ddbm": "ddbm"}[self.predict]:
            return None
        std2, c_out2 = self.std_fwd.to(n.device)[n] ** 2, self.ddbm_scalings[2].to(n.device)[n] ** 2
        w = {"i2sb": 1 / std2, "uniform": torch.ones_like(std2), "ddbm": 1 / c_out2}[self.weighting]
        return w * {"eps": std2, "x0": 1, "ddbm": c_out2}[self.predict]

    def training_pair(self, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(x_n, n, target)`` at a uniform random step n in [0, N-1] ([1, N-1] with ``consistent``)."""
        low = 1 if self.consistent else 0
        n = torch.randint(low, self.steps, (x0.shape[0],), generator=generator, device=x0.device)
        x_n = apply_conditions(self.marginal(x0, x1, n, generator), conditions)
        return x_n, n, self.training_target(x0, x_n, n)

    def sample(self, model, x_start: torch.Tensor, conditions: Conditions, nfe: int,
               generator: torch.Generator | None = None, correct: Correct | None = None) -> torch.Tensor:
        """From the prior sample ``x_start`` to a trajectory in ``nfe`` network calls (x0 predictions transformed
        by ``correct``, e.g. a consistency correction)."""
        self.validate_nfe(nfe)
        return bridge_sample(self.x0_predictor(model, correct), x_start, conditions,
                             spaced_steps(self.steps, nfe), self.std_fwd, self.ot_ode or self.sampler == "mean",
                             generator)
