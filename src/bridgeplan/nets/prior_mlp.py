"""The thesis's learned prior: a two-layer MLP from (start, goal) to a whole trajectory."""

from __future__ import annotations

import torch
from torch import nn


class PriorMLP(nn.Module):
    """``Linear(2 obs_dim, H D) -> LeakyReLU(0.1) -> Linear(H D, H D)``, reshaped to ``[B, H, D]``."""

    def __init__(self, obs_dim: int, horizon: int, transition_dim: int):
        super().__init__()
        self.horizon, self.transition_dim = horizon, transition_dim
        width = horizon * transition_dim
        self.net = nn.Sequential(nn.Linear(2 * obs_dim, width), nn.LeakyReLU(0.1), nn.Linear(width, width))

    def forward(self, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        out = self.net(torch.cat([start, goal], dim=-1))
        return out.view(-1, self.horizon, self.transition_dim)
