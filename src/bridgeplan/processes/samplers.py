"""Samplers as small pure functions over ``(model, x, conditions, steps, ...)``.

Each takes the starting sample ``x`` (noise for DDPM, the prior for the bridge), the inpainting
``conditions``, and the decreasing list of ``steps`` at which the network is called (NFE =
``len(steps)``); each applies the conditions after every update and returns the final sample.
The last jump lands on the clean data, so it returns the final clipped x0 prediction.
"""

from __future__ import annotations

from typing import Callable

import torch

from bridgeplan.processes.schedules import gaussian_product
from bridgeplan.trajectory import Conditions, apply_conditions

X0Predictor = Callable[[torch.Tensor, int], torch.Tensor]
"""``predict_x0(x_n, n)``: the clean trajectory the network sees in ``x_n`` at step ``n`` (clipped)."""


def _noise(x: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    return torch.randn(x.shape, generator=generator, device=x.device, dtype=x.dtype)


def ddpm_posterior(alpha_bar_t: float, alpha_bar_s: float) -> tuple[float, float, float]:
    """DDPM's posterior q(x_s | x_t, x0) for ``s < t``: ``(coef_x0, coef_xt, var)``.

    ``beta`` is the noise added between the two steps, ``1 - alpha_bar_t / alpha_bar_s``, so this is
    also the strided (respaced) posterior when ``s < t - 1``.
    """
    beta = 1.0 - alpha_bar_t / alpha_bar_s
    coef_x0 = alpha_bar_s ** 0.5 * beta / (1 - alpha_bar_t)
    coef_xt = (1 - beta) ** 0.5 * (1 - alpha_bar_s) / (1 - alpha_bar_t)
    return coef_x0, coef_xt, (1 - alpha_bar_s) / (1 - alpha_bar_t) * beta


def ddpm_ancestral(predict_x0: X0Predictor, x: torch.Tensor, conditions: Conditions, steps: list[int],
                   alpha_bar: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Ancestral sampling with the posterior q(x_s | x_t, x0_hat) between consecutive ``steps``.

    With ``steps = [N-1, ..., 0]`` this is DDPM's chain (Diffuser); a subsequence is the strided
    (respaced) sampler of improved DDPM.
    """
    x = apply_conditions(x, conditions)
    for k, t in enumerate(steps):
        x0 = predict_x0(x, t)
        if k == len(steps) - 1:
            return apply_conditions(x0, conditions)
        coef_x0, coef_xt, var = ddpm_posterior(float(alpha_bar[t]), float(alpha_bar[steps[k + 1]]))
        x = apply_conditions(coef_x0 * x0 + coef_xt * x + var ** 0.5 * _noise(x, generator), conditions)
    return x


def ddim(predict_x0: X0Predictor, x: torch.Tensor, conditions: Conditions, steps: list[int],
         alpha_bar: torch.Tensor, eta: float = 0.0, generator: torch.Generator | None = None) -> torch.Tensor:
    """DDIM (Song et al. 2021) over ``steps``; ``eta = 0`` is deterministic, ``eta = 1`` ancestral-like."""
    x = apply_conditions(x, conditions)
    for k, t in enumerate(steps):
        x0 = predict_x0(x, t)
        if k == len(steps) - 1:
            return apply_conditions(x0, conditions)
        s = steps[k + 1]
        ab_t, ab_s = float(alpha_bar[t]), float(alpha_bar[s])
        eps = (x - ab_t ** 0.5 * x0) / (1 - ab_t) ** 0.5
        sigma = eta * ((1 - ab_s) / (1 - ab_t) * (1 - ab_t / ab_s)) ** 0.5
        x = ab_s ** 0.5 * x0 + max(1 - ab_s - sigma ** 2, 0.0) ** 0.5 * eps
        if sigma > 0:
            x = x + sigma * _noise(x, generator)
        x = apply_conditions(x, conditions)
    return x


def bridge_posterior(std_n: float, std_m: float) -> tuple[float, float, float]:
    """I2SB's posterior p(x_m | x_n, x0) for ``m < n``: ``(a, b, v)`` of ``a x0 + b x_n + sqrt(v) eps``.

    x_m sits at std ``std_m`` from x0 and x_n at ``d = sqrt(std_n^2 - std_m^2)`` further on; the
    posterior is the product of N(x0, std_m^2) and N(x_n, d^2).
    """
    return gaussian_product(std_m, (std_n ** 2 - std_m ** 2) ** 0.5)


def bridge_posterior_step(x0: torch.Tensor, x_n: torch.Tensor, std_n: float, std_m: float,
                          noise: torch.Tensor | None) -> torch.Tensor:
    """One draw of :func:`bridge_posterior` (its mean when ``noise`` is None)."""
    a, b, v = bridge_posterior(std_n, std_m)
    out = a * x0 + b * x_n
    return out if noise is None else out + v ** 0.5 * noise


def bridge_sample(predict_x0: X0Predictor, x: torch.Tensor, conditions: Conditions, steps: list[int],
                  std_fwd: torch.Tensor, ot_ode: bool = False,
                  generator: torch.Generator | None = None) -> torch.Tensor:
    """I2SB sampling from the prior ``x`` down ``steps`` (decreasing, ending at 0).

    The chain of posteriors marginalizes in closed form, so any subset of steps is exact for a
    perfect predictor. No noise goes into step 0 (or anywhere with ``ot_ode``).
    """
    x = apply_conditions(x, conditions)
    for k, n in enumerate(steps[:-1]):
        m = steps[k + 1]
        x0 = predict_x0(x, n)
        if m == 0:
            return apply_conditions(x0, conditions)
        noise = None if ot_ode else _noise(x, generator)
        x = bridge_posterior_step(x0, x, float(std_fwd[n]), float(std_fwd[m]), noise)
        x = apply_conditions(x, conditions)
    return x


AverageVelocity = Callable[[torch.Tensor, float, float], torch.Tensor]
"""``u(z_t, r, t)``: the network's average velocity of the flow over ``[r, t]`` at ``z_t``
(``z_r = z_t - (t - r) u``)."""


def jump_sample(average_velocity: AverageVelocity, x: torch.Tensor, conditions: Conditions,
                times: list[float]) -> torch.Tensor:
    """From ``x`` at ``times[0]`` down the decreasing ``times`` by jumps ``z_r = z_t - (t - r) u(z_t, r, t)``
    (NFE = ``len(times) - 1``), the conditions inpainted after every jump; the last lands on the data, clipped.

    With the exact average velocity every jump is exact, whatever its length (a mean flow, a shortcut model).
    """
    x = apply_conditions(x, conditions)
    for t, r in zip(times[:-1], times[1:]):
        x = apply_conditions(x - (t - r) * average_velocity(x, r, t), conditions)
    return apply_conditions(x.clamp(-1, 1), conditions)
