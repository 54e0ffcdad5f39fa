"""Per-dimension min/max normalization to [-1, 1] (Diffuser's "LimitsNormalizer")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class Normalizer:
    """Maps each column of a ``[..., dim]`` array from ``[low, high]`` to ``[-1, 1]`` and back.

    Saved in every checkpoint (``to_dict``) and reused at planning time, so a plan is unnormalized
    with the limits of the data the model was trained on.
    """

    low: tuple[float, ...]
    high: tuple[float, ...]

    @classmethod
    def fit(cls, data: np.ndarray) -> "Normalizer":
        """Limits of ``data`` ``[N, dim]``; a constant column gets a unit range to avoid division by 0."""
        low = data.min(axis=0).astype(np.float64)
        high = data.max(axis=0).astype(np.float64)
        flat = high - low < 1e-8
        high = np.where(flat, low + 1.0, high)
        return cls(tuple(low.tolist()), tuple(high.tolist()))

    def _limits(self, like):
        low, high = np.asarray(self.low), np.asarray(self.high)
        if isinstance(like, torch.Tensor):
            return (torch.as_tensor(low, dtype=like.dtype, device=like.device),
                    torch.as_tensor(high, dtype=like.dtype, device=like.device))
        return low, high

    def normalize(self, x, dims: slice = slice(None)):
        """``x[..., d]`` for the columns ``dims`` of the normalizer (all by default) into [-1, 1]."""
        low, high = self._limits(x)
        low, high = low[dims], high[dims]
        return 2.0 * (x - low) / (high - low) - 1.0

    def unnormalize(self, x, dims: slice = slice(None)):
        """Inverse of :meth:`normalize`."""
        low, high = self._limits(x)
        low, high = low[dims], high[dims]
        return (x + 1.0) / 2.0 * (high - low) + low

    def to_dict(self) -> dict:
        return {"low": list(self.low), "high": list(self.high)}

    @classmethod
    def from_dict(cls, d: dict) -> "Normalizer":
        return cls(tuple(d["low"]), tuple(d["high"]))
