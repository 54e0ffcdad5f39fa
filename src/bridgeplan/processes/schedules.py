"""Noise schedules as pure functions (float64 tensors), separate from the samplers."""

from __future__ import annotations

import torch


def cosine_betas(n: int, s: float = 0.008) -> torch.Tensor:
    """Nichol & Dhariwal's cosine schedule, as Diffuser uses it: betas from alpha_bar(t) = cos^2, clipped."""
    t = torch.linspace(0, n, n + 1, dtype=torch.float64) / n
    alpha_bar = torch.cos((t + s) / (1 + s) * torch.pi / 2) ** 2
    alpha_bar = alpha_bar / alpha_bar[0]
    return (1 - alpha_bar[1:] / alpha_bar[:-1]).clamp(0, 0.999)


def i2sb_betas(n: int, beta_max: float) -> torch.Tensor:
    """I2SB's symmetric schedule: quadratic ramp from 1e-4 up to ``beta_max / n`` and mirrored.

    ``b = linspace(sqrt(1e-4), sqrt(beta_max / n), n) ** 2``; the first half of ``b`` then its mirror
    image. For odd ``n`` the middle value ``b[n // 2]`` is kept once, so the schedule stays symmetric
    and has length ``n``.
    """
    b = torch.linspace(1e-4 ** 0.5, (beta_max / n) ** 0.5, n, dtype=torch.float64) ** 2
    half = b[: n // 2]
    middle = b[n // 2: n // 2 + 1] if n % 2 else b[:0]
    return torch.cat([half, middle, half.flip(0)])


def bridge_stds(betas: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``std_fwd[n] = sqrt(sum_{k<=n} beta_k)``, ``std_bwd[n] = sqrt(sum_{k>=n} beta_k)``."""
    return betas.cumsum(0).sqrt(), betas.flip(0).cumsum(0).flip(0).sqrt()


def gaussian_product(s1: torch.Tensor | float, s2: torch.Tensor | float) -> tuple:
    """Coefficients of the product of N(x0, s1^2) and N(x1, s2^2): ``(mu0, mu1, var)``.

    Elementwise, so ``s1``, ``s2`` are tensors of stds per step or plain floats (one posterior step).
    """
    denom = s1 ** 2 + s2 ** 2
    return s2 ** 2 / denom, s1 ** 2 / denom, s1 ** 2 * s2 ** 2 / denom


def chain_marginal(std_fwd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(mu0, mu1, var)`` of x_n given (x0, x1) implied by the sampling chain (a consistent bridge).

    The chain starts from x1 as the state at the last step (std ``std_fwd[-1]``) and steps down with
    the posteriors of ``samplers.bridge_posterior``, which are those of a Brownian motion from x0 with
    variance ``std_fwd[n]^2`` at step n. Pinned at x1 at the last step, that is the Brownian bridge:
    weight ``std_fwd[n]^2 / std_fwd[-1]^2`` on x1, i.e. the product of (``std_fwd[n]``, the std still
    to go ``sqrt(std_fwd[-1]^2 - std_fwd[n]^2)``). At the last step it is x1 itself (var 0).
    """
    to_go = (std_fwd[-1] ** 2 - std_fwd ** 2).sqrt()
    return gaussian_product(std_fwd, to_go)


def spaced_steps(n: int, nfe: int) -> list[int]:
    """``nfe + 1`` evenly spaced steps from ``n - 1`` down to 0 (I2SB: ``round(i (n-1) / nfe)``)."""
    steps = sorted({round(i * (n - 1) / nfe) for i in range(nfe + 1)}, reverse=True)
    return steps
