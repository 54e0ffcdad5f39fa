"""Diffuser's temporal U-Net over trajectories ``[batch, horizon, transition_dim]``.

Conv1d(kernel 5) -> GroupNorm(8) -> Mish blocks; residual temporal blocks that add the
diffusion-time embedding after their first block; Conv1d(3, stride 2) down, ConvTranspose1d(4,
stride 2) up; no attention. ``dim=32, dim_mults=(1, 4, 8)`` is Diffuser's Maze2D network
(3,682,118 parameters with ``transition_dim=6``: Diffuser's "about 3.7 M").

The network maps ``x`` ``[batch, horizon, transition_dim]`` and a float time ``t`` ``[batch]`` (DDPM
passes its step index, the bridge its step index n) to a tensor of the same shape as ``x``; what the
output means (x0 or I2SB's scaled difference) is the process's business. A network built with
``interval=True`` takes a second float ``[batch]`` (the mean flow's interval, the shortcut's step size),
embedded like the time and added to its embedding; built without it, it has exactly the parameters (and the
initial weights, at one seed) it always had, so every earlier run's checkpoint loads and plans unchanged.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import torch
from torch import nn

from bridgeplan.errors import BridgeplanError


@dataclass(frozen=True)
class UNetConfig:
    """Size of a :class:`TemporalUNet` (``TrainConfig.model``)."""

    dim: int = 32
    """Base channel width (a positive multiple of 8, for GroupNorm(8)); also the time-embedding width."""
    dim_mults: tuple[int, ...] = (1, 4, 8)
    """Channel multipliers, one per level; each level after the first halves the horizon."""

    def __post_init__(self):
        object.__setattr__(self, "dim_mults", tuple(int(m) for m in self.dim_mults))
        if self.dim <= 0 or self.dim % 8 or not self.dim_mults or min(self.dim_mults) <= 0:
            raise BridgeplanError(f"U-Net needs dim a positive multiple of 8 (GroupNorm(8)) and positive "
                                  f"multipliers, got dim={self.dim}, dim_mults={self.dim_mults}")

    @property
    def downsample_factor(self) -> int:
        """The horizon must be divisible by this: ``2 ** (len(dim_mults) - 1)``."""
        return 2 ** (len(self.dim_mults) - 1)

    def check_horizon(self, horizon: int) -> None:
        """:class:`BridgeplanError` unless ``horizon`` is a positive multiple of :attr:`downsample_factor`."""
        if horizon <= 0 or horizon % self.downsample_factor:
            raise BridgeplanError(f"horizon {horizon} must be positive and divisible by the U-Net's "
                                  f"downsampling factor {self.downsample_factor} "
                                  f"(dim_mults={self.dim_mults})")


class SinusoidalEmbedding(nn.Module):
    """Embedding of a float time: ``[sin(t w_k), cos(t w_k)]``, ``w_k = 10000^(-k / (half - 1))``."""

    def __init__(self, dim: int):
        super().__init__()
        self.dim = dim

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        half = self.dim // 2
        t = t if t.is_floating_point() else t.float()  # in float64 for a float64 network (the tests' exact checks)
        k = torch.arange(half, device=t.device, dtype=t.dtype)
        freqs = torch.exp(-math.log(10000) * k / (half - 1))
        args = t[:, None] * freqs[None]
        return torch.cat([args.sin(), args.cos()], dim=-1)


_TWO = torch.tensor(2.0)
"""2 as a 0-dim tensor, which adds as the number 2 does (same dtype, device and bits): a Python number is made into
a tensor at each call, a tenth of a batch-1 forward pass."""


class _MishFunction(torch.autograd.Function):
    """Mish with one exponential: ``tanh(softplus(x)) = n / (n + 2)`` with ``n = e^x (e^x + 2)``, and its
    derivative ``t + x (1 - t^2) sigmoid(x)`` from the same ``e^x``. torch's own kernel evaluates exp, log1p and
    tanh forward and again backward: on the small networks it took a quarter of a training step at batch 256.
    Forward-mode too (``jvp``, for the mean flow's Jacobian-vector product by ``torch.autograd.forward_ad``); the
    ``setup_context`` form that ``torch.func.jvp`` needs would have to return ``t`` and ``e`` as outputs, which
    costs about 100 us per call (a tenth of a cpu-small training step), so the network is not for torch.func."""

    @staticmethod
    def factors(x):
        """``(tanh(softplus(x)), e^x)``."""
        e = x.clamp(max=20.0).exp_()  # beyond 20, t is 1 in float32 (and e^2x would overflow near 44)
        n = (e + _TWO).mul_(e)
        return n.div_(n + _TWO), e

    @staticmethod
    def forward(ctx, x):
        t, e = _MishFunction.factors(x)
        ctx.save_for_backward(x, t, e)
        ctx.save_for_forward(x, t, e)
        return x * t

    @staticmethod
    def _derivative(x, t, e):
        sigmoid = e.div(e + 1)
        return (t * t).neg_().add_(1).mul_(sigmoid).mul_(x).add_(t)

    @staticmethod
    def backward(ctx, grad):
        return _MishFunction._derivative(*ctx.saved_tensors).mul_(grad)

    @staticmethod
    def jvp(ctx, tangent):
        return _MishFunction._derivative(*ctx.saved_tensors).mul_(tangent)


class Mish(nn.Module):
    """``x * tanh(softplus(x))``, as ``nn.Mish`` (equal to float32 rounding), in fewer operations. In inference mode
    (planning) the same operations without the autograd function around them: the same numbers, and at batch 1,
    where each call's fixed cost is most of it, a quarter less of the network's time."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if torch.is_inference_mode_enabled():
            return x * _MishFunction.factors(x)[0]
        return _MishFunction.apply(x)


class ConvBlock(nn.Sequential):
    """Conv1d -> GroupNorm -> Mish."""

    def __init__(self, c_in: int, c_out: int, kernel: int = 5, groups: int = 8):
        super().__init__(nn.Conv1d(c_in, c_out, kernel, padding=kernel // 2), nn.GroupNorm(groups, c_out),
                         Mish())


class ResidualTemporalBlock(nn.Module):
    def __init__(self, c_in: int, c_out: int, embed_dim: int, kernel: int = 5):
        super().__init__()
        self.blocks = nn.ModuleList([ConvBlock(c_in, c_out, kernel), ConvBlock(c_out, c_out, kernel)])
        self.time_mlp = nn.Sequential(Mish(), nn.Linear(embed_dim, c_out))
        self.skip = nn.Conv1d(c_in, c_out, 1) if c_in != c_out else nn.Identity()

    def forward(self, x: torch.Tensor, emb: torch.Tensor) -> torch.Tensor:
        h = self.blocks[0](x) + self.time_mlp(emb)[:, :, None]
        return self.blocks[1](h) + self.skip(x)


class TemporalUNet(nn.Module):
    """Maps a noisy trajectory and a diffusion time ``t`` (float, ``[batch]``) to a trajectory.

    ``horizon``, when given, is checked against the downsampling factor at construction; every
    forward call checks the horizon of its input as well.
    """

    def __init__(self, transition_dim: int, dim: int = 32, dim_mults: tuple[int, ...] = (1, 4, 8),
                 horizon: int | None = None, interval: bool = False):
        super().__init__()
        self.config = UNetConfig(dim, tuple(dim_mults))
        self.transition_dim = transition_dim
        self.downsample_factor = self.config.downsample_factor
        if horizon is not None:
            self.config.check_horizon(horizon)
        dim, dim_mults = self.config.dim, self.config.dim_mults
        dims = [transition_dim, *(dim * m for m in dim_mults)]
        pairs = list(zip(dims[:-1], dims[1:]))
        self.time_mlp = nn.Sequential(SinusoidalEmbedding(dim), nn.Linear(dim, dim * 4), Mish(),
                                      nn.Linear(dim * 4, dim))
        self.downs = nn.ModuleList()
        for k, (c_in, c_out) in enumerate(pairs):
            last = k == len(pairs) - 1
            self.downs.append(nn.ModuleList([
                ResidualTemporalBlock(c_in, c_out, dim), ResidualTemporalBlock(c_out, c_out, dim),
                nn.Conv1d(c_out, c_out, 3, stride=2, padding=1) if not last else nn.Identity()]))
        mid = dims[-1]
        self.mid = nn.ModuleList([ResidualTemporalBlock(mid, mid, dim), ResidualTemporalBlock(mid, mid, dim)])
        self.ups = nn.ModuleList()
        # as in Diffuser: every up level upsamples, and the first level's skip goes unused
        for c_in, c_out in reversed(pairs[1:]):
            self.ups.append(nn.ModuleList([
                ResidualTemporalBlock(c_out * 2, c_in, dim), ResidualTemporalBlock(c_in, c_in, dim),
                nn.ConvTranspose1d(c_in, c_in, 4, stride=2, padding=1)]))
        self.final = nn.Sequential(ConvBlock(dim, dim), nn.Conv1d(dim, transition_dim, 1))
        # built last, so the modules above draw the same initial weights with or without it
        self.interval_mlp = nn.Sequential(SinusoidalEmbedding(dim), nn.Linear(dim, dim * 4), Mish(),
                                          nn.Linear(dim * 4, dim)) if interval else None

    @classmethod
    def from_config(cls, config: UNetConfig, transition_dim: int, horizon: int | None = None,
                    interval: bool = False) -> "TemporalUNet":
        return cls(transition_dim, config.dim, config.dim_mults, horizon, interval)

    def forward(self, x: torch.Tensor, t: torch.Tensor, interval: torch.Tensor | None = None) -> torch.Tensor:
        """``x`` ``[batch, horizon, transition_dim]``, ``t`` ``[batch]`` (any dtype), and ``interval`` ``[batch]``
        exactly when the network was built with one -> shape of ``x``."""
        if x.shape[1] % self.downsample_factor:
            self.config.check_horizon(x.shape[1])
        if (interval is None) != (self.interval_mlp is None):
            raise BridgeplanError("this network takes a second time input (an interval)" if interval is None else
                                  "this network takes one time input; an interval needs a network built with one")
        h = x.transpose(1, 2)
        emb = self.time_mlp(t)
        if interval is not None:
            emb = emb + self.interval_mlp(interval)
        skips = []
        for block1, block2, down in self.downs:
            h = block2(block1(h, emb), emb)
            skips.append(h)
            h = down(h)
        for block in self.mid:
            h = block(h, emb)
        for block1, block2, up in self.ups:
            h = torch.cat([h, skips.pop()], dim=1)
            h = up(block2(block1(h, emb), emb))
        return self.final(h).transpose(1, 2)


class FrozenUNet(nn.Module):
    """A :class:`TemporalUNet` for planning, its Python cost per module traced away: under ``torch.inference_mode``,
    on inputs of the horizon and dtype it was frozen for, the network runs as one TorchScript graph
    (``torch.jit.trace``, then ``torch.jit.freeze``), traced once here and good for any batch size; elsewhere
    (training, CDDB's gradients, another horizon or dtype) it is the eager network itself. The same operations:
    the same numbers. At batch 1 a cpu-small decision is mostly that Python cost (``bridgeplan bench --frozen``)."""

    def __init__(self, net: TemporalUNet, horizon: int):
        super().__init__()
        if not (hasattr(torch.jit, "trace") and hasattr(torch.jit, "freeze")):
            raise BridgeplanError(f"a frozen network needs TorchScript (torch.jit), which torch {torch.__version__} "
                                  f"does not have: plan without --frozen")
        self.net = net.eval()
        weight = next(net.parameters())
        self.horizon, self.dtype = horizon, weight.dtype
        x = torch.zeros(1, horizon, net.transition_dim, dtype=weight.dtype, device=weight.device)
        t = torch.zeros(1, dtype=weight.dtype, device=weight.device)
        with warnings.catch_warnings(), torch.inference_mode():
            warnings.simplefilter("ignore")  # TorchScript's deprecation notice, and the horizon's check traced as a
            # constant (this horizon's, checked here by the eager network)
            self.graph = torch.jit.freeze(torch.jit.trace(net, (x, t) if net.interval_mlp is None else (x, t, t),
                                                          check_trace=False))

    def forward(self, x: torch.Tensor, t: torch.Tensor, interval: torch.Tensor | None = None) -> torch.Tensor:
        if (torch.is_inference_mode_enabled() and x.shape[1] == self.horizon and x.dtype == self.dtype
                and t.dtype == self.dtype and (interval is None) == (self.net.interval_mlp is None)):
            return self.graph(x, t) if interval is None else self.graph(x, t, interval)
        return self.net(x, t, interval)
