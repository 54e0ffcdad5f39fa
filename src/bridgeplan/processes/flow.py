"""Flow matching / stochastic interpolants from the run's prior x1 to the data x0.

The path (``path="linear"``, the only one so far) between the clean window x0 and its prior sample x1 is

    x_t = (1 - t) x0 + t x1 + g(t) z,    g(t) = sigma * sqrt(t (1 - t)),    z ~ N(0, I),

a straight line (rectified flow / conditional flow matching) when ``sigma = 0``, and for ``sigma > 0``
the marginals of a Brownian bridge from x0 at t = 0 to x1 at t = 1 with diffusion ``sigma^2``: the
noise vanishes at both ends, so x_1 is the prior sample itself and x_0 the data.

**Times.** ``steps`` (N) discrete times ``t_n = (n + 1) / N`` for n = 0..N-1; the network gets ``n`` as a
float in [0, N-1], the convention of DDPM and the bridge (same U-Net, same time embedding range), and
training draws n uniformly, so training and sampling see the same N times. ``t_{N-1} = 1`` is the prior
sample itself (where sampling starts); the sampler's last jump goes to t = 0, where no call is made.
Sampling takes any NFE from 1 to N: the calls are at ``nfe`` evenly spaced times of the grid ``j / N``.

**Parametrization: the network predicts x0** (clipped to [-1, 1] by ``predict_x0``), the target of
Diffuser's DDPM here, not the velocity. The target keeps the normalized data's range [-1, 1] at every
t (the velocity target ``x1 - x0 + g'(t) z`` has ``g'`` unbounded at both ends when ``sigma > 0``); the
last step lands on the x0 prediction itself, as in the other processes; and the samplers below need
only x0: on the path, ``(x_t - x0) / t = x1 - x0 + (g(t) / t) z``.

**Samplers** (between consecutive times t > s of the grid; conditions inpainted after every update):

- ``euler``: ``x_s = x0_hat + (s / t) (x_t - x0_hat)``, i.e. ``x_s = x_t + (s - t) v_hat`` with
  ``v_hat = (x_t - x0_hat) / t``. With ``sigma = 0`` this is Euler on the probability-flow ODE of the
  interpolant (``v_hat = E[x1 - x0 | x_t]``); a perfect predictor walks the straight line exactly at
  any NFE. With ``sigma > 0`` it is the stochastic sampler with its noise dropped (the posterior mean,
  like I2SB's OT-ODE sampling), not the probability-flow ODE (that would also need E[z | x_t], which an
  x0 predictor does not give): its states are less spread than the path's marginals.
- ``stochastic``: the path's own posterior, the Brownian bridge from x0_hat at 0 to x_t at t:
  ``x_s = x0_hat + (s / t) (x_t - x0_hat) + sigma sqrt(s (t - s) / t) eps``. It does not depend on x1
  (the bridge is Markov), and it keeps the path's marginal given (x0, x1): a perfect predictor's chain
  from x1 hands the network x_s with mean ``(1 - s) x0 + s x1`` and variance ``g(s)^2`` at every NFE.
  It needs ``sigma > 0`` (with ``sigma = 0`` it would be ``euler``; that is refused as a likely mistake).

With the stochastic sampler this is, up to the time variable, the bridge's ``consistent`` chain
(``Bridge(consistent=True)``): a Brownian bridge whose variance grows linearly in t here instead of
with I2SB's symmetric beta schedule, and an x0 output instead of I2SB's scaled difference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.processes.base import Correct, Process
from bridgeplan.processes.samplers import X0Predictor
from bridgeplan.processes.schedules import spaced_steps
from bridgeplan.trajectory import Conditions, apply_conditions

PATHS = ("linear",)
SAMPLERS = ("euler", "stochastic")


def flow_time(n, n_steps: int):
    """The time ``t_n = (n + 1) / N`` of network step ``n`` (an int or a tensor of ints)."""
    return (n + 1) / n_steps


def linear_interpolant(t, sigma: float) -> tuple:
    """``(a, b, g)`` of ``x_t = a x0 + b x1 + g z`` on the linear path: ``(1 - t, t, sigma sqrt(t (1 - t)))``.

    Elementwise: ``t`` a float or a tensor of times in [0, 1].
    """
    g = sigma * (t * (1 - t)) ** 0.5
    return 1 - t, t, g


def flow_posterior(t: float, s: float, sigma: float) -> tuple[float, float, float]:
    """The path's x_s given (x0, x_t) for ``0 <= s < t <= 1``: ``(coef_x0, coef_xt, var)``.

    The Brownian bridge from x0 at time 0 to x_t at time t, evaluated at s: weight ``s / t`` on x_t and
    variance ``sigma^2 s (t - s) / t``; no weight on x1.
    """
    return 1 - s / t, s / t, sigma ** 2 * s * (t - s) / t


def flow_sample(predict_x0: X0Predictor, x: torch.Tensor, conditions: Conditions, steps: list[int],
                n_steps: int, sigma: float, stochastic: bool,
                generator: torch.Generator | None = None) -> torch.Tensor:
    """From the prior sample ``x`` (at time ``t_{steps[0]}``) down the decreasing network ``steps`` to t = 0.

    NFE = ``len(steps)``; each update is :func:`flow_posterior` between consecutive times, its mean only
    unless ``stochastic``; the last call's x0 prediction is the sample.
    """
    x = apply_conditions(x, conditions)
    for k, n in enumerate(steps):
        x0 = predict_x0(x, n)
        if k == len(steps) - 1:
            return apply_conditions(x0, conditions)
        coef_x0, coef_xt, var = flow_posterior(flow_time(n, n_steps), flow_time(steps[k + 1], n_steps), sigma)
        x = coef_x0 * x0 + coef_xt * x
        if stochastic and var > 0:
            x = x + var ** 0.5 * torch.randn(x.shape, generator=generator, device=x.device, dtype=x.dtype)
        x = apply_conditions(x, conditions)
    return x


@dataclass(frozen=True)
class Flow(Process):
    """Flow matching (``sigma = 0``) or a stochastic interpolant (``sigma > 0``) from the prior, over
    ``steps`` (N) discrete times; the network predicts x0; sampled by ``sampler`` at any NFE 1..N.

    See the module docstring for the path, the times and the samplers. ``sampler`` does not change
    training: ``process.with_sampler("stochastic")`` samples a trained run the other way.
    """

    steps: int = 16
    sigma: float = 0.0
    path: str = "linear"
    sampler: str = "euler"
    name = "flow"
    display_name = "flow"
    sampling_fields = ("sampler",)
    samplers = SAMPLERS

    def __post_init__(self):
        if self.steps < 1:
            raise BridgeplanError(f"flow steps must be >= 1, got {self.steps}")
        if not math.isfinite(self.sigma) or self.sigma < 0:
            raise BridgeplanError(f"flow sigma must be a finite number >= 0, got {self.sigma}")
        check_choice("flow path", self.path, PATHS)
        check_choice("sampler", self.sampler, SAMPLERS)
        if self.sampler == "stochastic" and self.sigma == 0:
            raise BridgeplanError("the stochastic flow sampler puts back the path's noise, and sigma=0 has none "
                                  "(it would be the euler sampler): train with sigma > 0 or use euler")

    def usable_samplers(self) -> tuple[str, ...]:
        """``stochastic`` needs the path's noise (``sigma > 0``)."""
        return SAMPLERS if self.sigma > 0 else ("euler",)

    def interpolate(self, x0: torch.Tensor, x1: torch.Tensor, n: torch.Tensor,
                    generator: torch.Generator | None = None) -> torch.Tensor:
        """A draw of x_t on the path given (x0, x1) at the times of steps ``n`` ``[B]``."""
        t = flow_time(n.to(x0.dtype), self.steps)[:, None, None]
        a, b, g = linear_interpolant(t, self.sigma)
        x_t = a * x0 + b * x1
        if self.sigma > 0:
            x_t = x_t + g * torch.randn(x0.shape, generator=generator, device=x0.device, dtype=x0.dtype)
        return x_t

    def training_pair(self, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(x_t, n, target)`` with x_t on the path at a uniform random step n in [0, N-1]."""
        n = torch.randint(0, self.steps, (x0.shape[0],), generator=generator, device=x0.device)
        x_t = apply_conditions(self.interpolate(x0, x1, n, generator), conditions)
        return x_t, n, self.training_target(x0, x_t, n)

    def sample_steps(self, nfe: int) -> list[int]:
        """The ``nfe`` network steps, decreasing from N-1 (t = 1): evenly spaced on the grid ``j / N``."""
        self.validate_nfe(nfe)
        return [j - 1 for j in spaced_steps(self.steps + 1, nfe)[:-1]]

    def sample(self, model, x_start: torch.Tensor, conditions: Conditions, nfe: int,
               generator: torch.Generator | None = None, correct: Correct | None = None) -> torch.Tensor:
        """From the prior sample ``x_start`` to a trajectory in ``nfe`` network calls (x0 predictions transformed
        by ``correct``, e.g. a consistency correction)."""
        return flow_sample(self.x0_predictor(model, correct), x_start, conditions, self.sample_steps(nfe),
                           self.steps, self.sigma, self.sampler == "stochastic", generator)
