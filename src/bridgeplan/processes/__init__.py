"""Generative processes behind one interface: ``training_loss(model, x0, x1, conditions, generator)``
and ``sample(model, x_start, conditions, nfe, generator)``; see ``ddpm.py`` and ``bridge.py``."""

from __future__ import annotations

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.bridge import Bridge
from bridgeplan.processes.ddpm import DDPM

PROCESSES = {"ddpm": DDPM, "bridge": Bridge}


def make_process(name: str, **params):
    if name not in PROCESSES:
        raise BridgeplanError(f"unknown process {name!r}: choose from {', '.join(PROCESSES)}")
    return PROCESSES[name](**params)
