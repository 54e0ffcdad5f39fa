"""The goal-conditioned policy of GCBC: an MLP on ``concat(state, goal)`` giving the mean of a Gaussian.

It follows OGBench's GCBC actor (``impls/agents/gcbc.py`` building ``GCActor`` of ``impls/utils/networks.py``
with its defaults), re-written for PyTorch:

- hidden layers ``(512, 512, 512)``, each ``Linear`` then GELU, the last hidden layer activated too
  (``activate_final=True``); no layer norm (the ``MLP``'s default, which ``GCActor`` keeps);
- GELU in its tanh approximation, which is what ``flax.linen.gelu`` computes by default;
- weights initialised by variance scaling on the mean of fan-in and fan-out, uniform (Glorot uniform), biases
  zero; the output (mean) layer with scale 0.01, i.e. Glorot uniform with gain 0.1, so the first actions are
  near zero;
- a diagonal Gaussian with *constant* standard deviation 1 (``const_std=True``, ``state_dependent_std=False``);
  no tanh squashing. With a fixed std the negative log-likelihood is ``0.5 ||a - mean||^2`` plus a
  constant, so training is regression of the mean; the loss (:func:`unit_gaussian_nll`) is still the full NLL, so
  it reads as OGBench's ``actor_loss``.

Not carried over: OGBench's learnable, state-independent log-std (``const_std=False``, not GCBC's setting)
and its visual encoders (pointmaze observations are positions).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

# flax's variance_scaling(scale, "fan_avg", "uniform") is Glorot uniform with gain sqrt(scale).
_MEAN_LAYER_GAIN = math.sqrt(1e-2)


def unit_gaussian_nll(mean: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """``-log N(actions; mean, I)`` per row, ``[B]``: half the squared error plus ``(a / 2) log(2 pi)``."""
    return 0.5 * (mean - actions).square().sum(-1) + 0.5 * actions.shape[-1] * math.log(2 * math.pi)


class GoalPolicy(nn.Module):
    """``mean = head(MLP(concat(observation, goal)))``; the action distribution is ``N(mean, I)``."""

    def __init__(self, obs_dim: int, goal_dim: int, action_dim: int,
                 hidden_dims: Sequence[int] = (512, 512, 512)):
        super().__init__()
        self.obs_dim, self.goal_dim, self.action_dim = obs_dim, goal_dim, action_dim
        self.hidden_dims = tuple(hidden_dims)
        layers: list[nn.Module] = []
        width = obs_dim + goal_dim
        for size in self.hidden_dims:
            layers += [nn.Linear(width, size), nn.GELU(approximate="tanh")]
            width = size
        self.trunk = nn.Sequential(*layers)
        self.mean = nn.Linear(width, action_dim)
        for layer in self.trunk:
            if isinstance(layer, nn.Linear):
                nn.init.xavier_uniform_(layer.weight)
                nn.init.zeros_(layer.bias)
        nn.init.xavier_uniform_(self.mean.weight, gain=_MEAN_LAYER_GAIN)
        nn.init.zeros_(self.mean.bias)

    def forward(self, observations: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        """The mean action, ``[B, action_dim]``, for observations ``[B, obs_dim]`` and goals ``[B, goal_dim]``."""
        return self.mean(self.trunk(torch.cat([observations, goals], dim=-1)))

    @torch.no_grad()
    def act(self, observations: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        """The deterministic action: the mean clipped to ``[-1, 1]`` (OGBench evaluates at temperature 0,
        where a sample is the mean, then clips)."""
        return self(observations, goals).clamp(-1.0, 1.0)
