"""Generative processes behind one interface (see ``ddpm.py`` and ``bridge.py``).

Every process is a frozen dataclass (``to_dict``, inverted by ``process_from_dict``) with

- ``training_loss(model, x0, x1, conditions, generator=None) -> scalar`` (``x0`` the clean normalized
  window ``[B, H, D]``, ``x1`` the prior sample for it, ignored by DDPM),
- ``predict_x0(model, x_n, n) -> x0_hat`` (clipped to [-1, 1]),
- ``max_nfe``, ``validate_nfe(nfe)``,
- ``sample(model, x_start, conditions, nfe, generator=None) -> x0`` (``x_start`` the prior sample:
  noise for DDPM), built on the pure samplers of ``samplers.py`` over the schedules of ``schedules.py``.

A new process is one dataclass with these methods and an entry in ``PROCESSES``.
"""

from __future__ import annotations

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.bridge import Bridge
from bridgeplan.processes.ddpm import DDPM

PROCESSES = {"ddpm": DDPM, "bridge": Bridge}


def make_process(name: str, **params):
    """A process by name with its parameters, e.g. ``make_process("bridge", steps=16, beta_max=0.3)``."""
    if name not in PROCESSES:
        raise BridgeplanError(f"unknown process {name!r}: choose from {', '.join(PROCESSES)}")
    try:
        return PROCESSES[name](**params)
    except TypeError as e:
        raise BridgeplanError(f"bad parameters for process {name!r}: {e}") from None


def process_from_dict(d: dict):
    """Inverse of ``process.to_dict()``."""
    d = dict(d)
    return make_process(d.pop("name"), **d)


__all__ = ["DDPM", "Bridge", "PROCESSES", "make_process", "process_from_dict"]
