"""Device choice: CUDA when present, overridable with ``--device``."""

from __future__ import annotations

import torch

from bridgeplan.errors import BridgeplanError


def resolve_device(name: str = "auto") -> torch.device:
    """``auto`` picks CUDA if available, else CPU; a named device must exist."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError as e:
        raise BridgeplanError(f"unknown device {name!r}: {e}") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise BridgeplanError(f"device {name!r} asked for, but CUDA is not available on this machine")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise BridgeplanError(f"device {name!r} asked for, but this machine has {torch.cuda.device_count()} "
                              "CUDA device(s)")
    if device.type == "mps" and not torch.backends.mps.is_available():
        raise BridgeplanError(f"device {name!r} asked for, but MPS is not available on this machine")
    return device
