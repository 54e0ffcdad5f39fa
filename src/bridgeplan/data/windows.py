"""Fixed-horizon training windows ``[horizon, actions + state]``, normalized to [-1, 1].

Windows are cut from continuous segments only (they cross goal changes, as Diffuser's did, but
never a reset or a file boundary). The start/goal conditions of a window are its own first and
last states (``train.conditions_of``).
"""

from __future__ import annotations

import numpy as np
import torch

from bridgeplan.data.normalizer import Normalizer
from bridgeplan.data.stream import Stream
from bridgeplan.errors import BridgeplanError


class WindowDataset(torch.utils.data.Dataset):
    def __init__(self, stream: Stream, horizon: int, normalizer: Normalizer):
        if horizon < 2:
            raise BridgeplanError(f"horizon must be at least 2, got {horizon}")
        starts = [np.arange(lo, hi - horizon + 1) for lo, hi in stream.segment_bounds() if hi - lo >= horizon]
        if not starts:
            longest = max(hi - lo for lo, hi in stream.segment_bounds())
            raise BridgeplanError(f"horizon {horizon} is longer than every continuous segment of the dataset "
                                  f"(longest: {longest} steps)")
        self.horizon = horizon
        self.starts = torch.as_tensor(np.concatenate(starts))
        self.data = torch.as_tensor(normalizer.normalize(stream.transitions()), dtype=torch.float32)
        self._offsets = torch.arange(horizon)

    def __len__(self) -> int:
        return len(self.starts)

    def __getitem__(self, i: int) -> torch.Tensor:
        s = int(self.starts[i])
        return self.data[s:s + self.horizon]

    def batch(self, indices: torch.Tensor) -> torch.Tensor:
        """Windows ``[len(indices), horizon, 6]`` in one gather."""
        return self.data[self.starts[indices][:, None] + self._offsets]
