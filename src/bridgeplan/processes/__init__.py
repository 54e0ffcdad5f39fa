"""Generative processes behind one interface (see ``base.py``, ``ddpm.py``, ``bridge.py``, ``flow.py``, and the
one-step ``meanflow.py`` and ``shortcut.py`` on ``jumps.py``, and ``distill.py``, DDPM distilled).

A process is the one definition of a method: training, sweeps, evaluation, reports and the bench
all ask it. Every process is a frozen dataclass derived from :class:`Process` (``to_dict``,
inverted by ``process_from_dict``; ``label``, ``run_tag``, ``uses_prior``, ``with_sampler``) with

- ``training_pair(x0, x1, conditions, generator=None) -> (x_n, n, target)`` (``x0`` the clean normalized
  window ``[B, H, D]``, ``x1`` the prior sample for it, ignored by DDPM) and ``training_target``; the
  base class's ``training_loss`` is the L2 between the network's output on ``(x_n, n)`` and ``target``
  (weighted per step by ``output_weight``, equal by default); a process trained otherwise (the mean flow's
  JVP, the shortcut's self-consistency) overrides ``training_loss`` itself,
- ``predict_x0(model, x_n, n) -> x0_hat`` (clipped to [-1, 1]; only where ``predicts_x0``: the jump processes
  move by average velocities instead, their network taking a second time input, ``takes_interval``),
- ``max_nfe``, ``validate_nfe(nfe)``,
- ``sample(model, x_start, conditions, nfe, generator=None) -> x0`` (``x_start`` the prior sample:
  noise for DDPM), built on the pure samplers of ``samplers.py`` over the schedules of ``schedules.py``.

A new process is one such dataclass in its own file and an entry in ``PROCESSES``.
"""

from __future__ import annotations

import dataclasses

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.processes.base import Process
from bridgeplan.processes.bridge import Bridge
from bridgeplan.processes.ddpm import DDPM
from bridgeplan.processes.distill import Distill
from bridgeplan.processes.flow import Flow
from bridgeplan.processes.meanflow import MeanFlow
from bridgeplan.processes.shortcut import Shortcut

PROCESSES: dict[str, type[Process]] = {"ddpm": DDPM, "bridge": Bridge, "flow": Flow, "meanflow": MeanFlow,
                                       "shortcut": Shortcut, "distill": Distill}


def make_process(name: str, **params) -> Process:
    """A process by name with its parameters, e.g. ``make_process("bridge", steps=16, beta_max=0.3)``."""
    check_choice("process", name, PROCESSES)
    try:
        return PROCESSES[name](**params)
    except TypeError as e:
        raise BridgeplanError(f"bad parameters for process {name!r}: {e}") from None


def parse_process_params(name: str, assignments: list[str]) -> dict:
    """``["beta_max=0.3", "ot_ode=true"]`` -> typed keyword arguments for process ``name`` (each value takes
    the type of the field's default), so a new process's parameters reach the CLI with no new flags."""
    check_choice("process", name, PROCESSES)
    defaults = {f.name: f.default for f in dataclasses.fields(PROCESSES[name])}
    params = {}
    for text in assignments:
        key, sep, value = text.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in defaults:
            raise BridgeplanError(f"--process-param takes FIELD=VALUE with a field of {name} "
                                  f"({', '.join(defaults)}), got {text!r}")
        kind = type(defaults[key])
        try:
            if kind is bool:
                if value.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(value)
                params[key] = value.lower() in ("true", "1")
            else:
                params[key] = kind(value)
        except ValueError:
            raise BridgeplanError(f"--process-param {key} takes a {kind.__name__}, got {value!r}") from None
    return params


def process_from_dict(d: dict) -> Process:
    """Inverse of ``process.to_dict()``.

    Runs saved before the process was the config (bridgeplan 0.1) stored the bridge's fields for
    DDPM runs too, at their defaults; fields the process does not have are dropped for that reason.
    """
    d = dict(d)
    name = d.pop("name", None)
    check_choice("process", name, PROCESSES)
    known = {f.name for f in dataclasses.fields(PROCESSES[name])}
    return make_process(name, **{k: v for k, v in d.items() if k in known})


__all__ = ["DDPM", "Bridge", "Flow", "MeanFlow", "Shortcut", "Distill", "Process",
           "PROCESSES", "make_process", "parse_process_params",
           "process_from_dict"]
