"""The trajectory layout shared by data, networks, processes and planner.

A trajectory is a tensor ``[batch, horizon, transition_dim]`` whose columns are
``(actions, state)`` = ``(ax, ay, x, y, vx, vy)`` (Diffuser's layout). Goal reaching is
inpainting: ``conditions`` maps a time index to the state (normalized) that the trajectory must
have there, ``{0: start, horizon - 1: goal}``, each ``[batch, obs_dim]``; a row of NaN leaves that
trajectory free at that index (conditions that hold for some episodes of a batch only).
"""

from __future__ import annotations

import numpy as np
import torch

ACT_DIM = 2
OBS_DIM = 4
TRANSITION_DIM = ACT_DIM + OBS_DIM

Conditions = dict[int, torch.Tensor]


def apply_conditions(x: torch.Tensor, conditions: Conditions, act_dim: int = ACT_DIM) -> torch.Tensor:
    """Overwrite the state columns of ``x`` at the conditioned time indices (returns a new tensor); rows of
    ``state`` that are NaN leave theirs as they are.

    Used by training and by every sampler step alike, so conditions hold exactly in every sample.
    """
    x = x.clone()
    for t, state in conditions.items():
        state = state.to(x.dtype)
        x[:, t, act_dim:] = torch.where(torch.isnan(state), x[:, t, act_dim:], state)
    return x


def window_conditions(x0: torch.Tensor) -> Conditions:
    """Start and goal conditions of a training window ``[B, H, D]``: its first and last states (Diffuser)."""
    return {0: x0[:, 0, ACT_DIM:], x0.shape[1] - 1: x0[:, -1, ACT_DIM:]}


def span(horizon: int, stride: int) -> int:
    """Environment steps covered by ``horizon`` planned states ``stride`` steps apart (both ends included)."""
    return (horizon - 1) * stride + 1


def densify(x, stride: int):
    """Plans ``x [N, H, D]`` whose states are ``stride`` environment steps apart, linearly interpolated to every
    step: ``[N, (H - 1) * stride + 1, D]``, equal to ``x`` at every ``stride``-th step."""
    x = np.asarray(x)
    if stride == 1:
        return x
    frac = (np.arange(stride) / stride)[None, None, :, None]
    a, b = x[:, :-1, None], x[:, 1:, None]
    inner = (a + frac * (b - a)).reshape(len(x), -1, x.shape[2])
    return np.concatenate([inner, x[:, -1:]], axis=1)
