"""Fixed-horizon training windows ``[horizon, actions + state]`` (the stream's layout), normalized to [-1, 1].

A window holds every ``stride``-th transition of a stretch of ``(horizon - 1) * stride + 1`` steps
(stride 1: consecutive steps, Diffuser's). Windows are cut from continuous segments only: they cross
goal changes (as Diffuser's did) but never a reset, a stream boundary or a gap in a file. A window is
returned as ``x [H, D]`` alone (float32, normalized); its start/goal conditions are its own first and last states
(``trajectory.window_conditions``), which the trainer takes from ``x``.
"""

from __future__ import annotations

import numpy as np
import torch

from bridgeplan.data.stream import Stream
from bridgeplan.errors import BridgeplanError
from bridgeplan.normalizer import Normalizer
from bridgeplan.trajectory import Layout, span


def window_starts(stream: Stream, horizon: int) -> np.ndarray:
    """Start index of every window ``[s, s + horizon)`` that lies inside one continuous segment."""
    if horizon < 2:
        raise BridgeplanError(f"horizon must be at least 2, got {horizon}")
    starts = [np.arange(lo, hi - horizon + 1) for lo, hi in stream.segment_bounds() if hi - lo >= horizon]
    if not starts:
        longest = max((hi - lo for lo, hi in stream.segment_bounds()), default=0)
        raise BridgeplanError(f"horizon {horizon} is longer than every continuous segment of the dataset "
                              f"(longest: {longest} steps)")
    return np.concatenate(starts).astype(np.int64)


class WindowDataset(torch.utils.data.Dataset):
    """All windows of ``horizon`` states ``stride`` steps apart of ``stream``, normalized by ``normalizer`` (fit
    on ``stream.transitions()``); ``dataset[i]`` is ``x [horizon, D]`` float32 in the stream's ``layout`` (Maze2D:
    ``(ax, ay, x, y, vx, vy)``); ``dataset.batch(indices)`` gathers ``[B, horizon, D]`` at once."""

    def __init__(self, stream: Stream, horizon: int, normalizer: Normalizer, stride: int = 1):
        self.horizon, self.stride = int(horizon), int(stride)
        self.layout = stream.layout
        self.dataset = stream.identity()
        """The data's :meth:`Stream.identity`: every run saves it, every result row carries it."""
        if len(normalizer.low) != self.layout.transition_dim:
            raise BridgeplanError(f"the normalizer has {len(normalizer.low)} columns, the {stream.maze} data's "
                                  f"transitions {self.layout.transition_dim}")
        self.starts = torch.as_tensor(window_starts(stream, span(self.horizon, self.stride)))
        self.data = torch.as_tensor(normalizer.normalize(stream.transitions()), dtype=torch.float32)
        self._offsets = torch.arange(self.horizon) * self.stride

    def __len__(self) -> int:
        return len(self.starts)

    def __getitem__(self, i: int) -> torch.Tensor:
        return self.data[int(self.starts[i]) + self._offsets]

    def batch(self, indices: torch.Tensor) -> torch.Tensor:
        """Windows ``[len(indices), horizon, D]`` in one gather (on the device the data is on)."""
        return self.data[self.starts[torch.as_tensor(indices, device=self.data.device)][:, None] + self._offsets]

    def to(self, device: torch.device | str) -> "WindowDataset":
        """Moves the windows' data to ``device`` (in place; returns ``self``): training gathers its batches there,
        so no batch crosses from host to device."""
        self.starts, self.data, self._offsets = (t.to(device) for t in (self.starts, self.data, self._offsets))
        return self


def hold_tails(x: torch.Tensor, share: float, rest: torch.Tensor, layout: Layout,
               generator: torch.Generator | None = None) -> torch.Tensor:
    """Windows ``x [B, H, D]`` (normalized, in ``layout``) of which a random ``share`` wait still from a random
    index k in 1..H-2 on: every state after k keeps k's position with zero velocity (if the state has one) and
    zero action. ``rest`` ``[D]`` is the normalized all-zero transition (its action and velocity columns are
    used). The last state, the window's goal condition, is then a position at rest, as the planner's goal is."""
    b, h, _ = x.shape
    held = torch.rand(b, generator=generator, device=x.device) < share
    k = torch.randint(1, h - 1, (b,), generator=generator, device=x.device)
    after = (torch.arange(h, device=x.device)[None, :] > k[:, None]) & held[:, None]
    still = x[torch.arange(b, device=x.device), k].clone()
    layout.actions(still)[...] = layout.actions(rest)
    if layout.has_velocity:
        layout.velocities(still)[...] = layout.velocities(rest)
    return torch.where(after[..., None], still[:, None, :], x)
