"""What an evaluated method is, as a structured key: :class:`MethodKey`.

A key holds what was trained (the process, its diffusion steps and the training parameters that differ from
their defaults, the prior, the share of training windows that wait) and how it was evaluated (the sampling tag,
the :class:`~bridgeplan.replan.Execution`, the task set). Tables name methods by keys; the text a table shows
is rendered from a key (:func:`label`, :func:`describe`), never parsed back from it.

The committed stores name an execution by its tag alone (``replan32-warm-pursuit1``): :func:`parse_execution`
is the one place that reads such a tag back, and it checks that ``Execution.tag()`` writes the same tag again.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from bridgeplan.config import method_label
from bridgeplan.envs.controllers import CONTROLLERS
from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.processes import PROCESSES, make_process
from bridgeplan.processes.base import Process
from bridgeplan.replan import Execution

OPEN_LOOP = Execution()
"""The default execution: one plan per episode, tracked by Diffuser's controller (tag '')."""


def execution_name(execution: Execution) -> str:
    """How a report's table titles name an execution: tracked, pursued (lookahead L), else its tag."""
    if execution == OPEN_LOOP:
        return "tracked"
    if execution.plans_once and execution.controller == "pursuit":
        return f"pursued (lookahead {execution.lookahead:g})"
    return execution.tag()


@dataclass(frozen=True)
class MethodKey:
    """One evaluated method: what was trained and how it was sampled and executed, on which task set."""

    process: str
    """The process's registry name (``ddpm``, ``bridge``, ``flow``)."""
    steps: int
    """Its diffusion steps N."""
    params: tuple[tuple[str, Any], ...] = ()
    """Its other training parameters that differ from their defaults, sorted by name
    (``(("consistent", True),)``); sampling parameters are in :attr:`sampler`."""
    prior: str = "gaussian"
    hold_share: float = 0.0
    """Share of training windows that wait at the goal (0: Diffuser's windows)."""
    sampler: str = ""
    """``Process.sampling_tag()`` of the evaluation: '' for the process's default sampler, else e.g. ``mean``,
    ``ddim`` or ``ddim eta=0.5``."""
    execution: Execution = field(default=OPEN_LOOP)
    multi_task: bool = False
    """False: the single-task evaluation tasks; True: Multi2D's."""

    def trained(self) -> Process:
        """The trained process (sampling fields at their defaults)."""
        return make_process(self.process, steps=self.steps, **dict(self.params))

    def replace(self, **changes) -> MethodKey:
        """The same key with some fields changed, e.g. ``key.replace(execution=PURSUIT1, multi_task=True)``."""
        return dataclasses.replace(self, **changes)

    @property
    def tag(self) -> str:
        """The execution's tag ('' for open loop, tracked)."""
        return self.execution.tag()


def method(process: str, prior: str = "gaussian", *, steps: int, hold_share: float = 0.0, sampler: str = "",
           execution: Execution = OPEN_LOOP, multi_task: bool = False, **params) -> MethodKey:
    """A key from a process's name and parameters, normalized as the stores' rows are: ``method("bridge", "line",
    steps=16, consistent=True)``. A parameter at its default is dropped, so the key equals the one read from a
    row whose config spells the default out; unknown parameters raise :class:`BridgeplanError`."""
    trained = make_process(process, steps=steps, **params)
    if set(params) & set(trained.sampling_fields):
        raise BridgeplanError(f"{sorted(set(params) & set(trained.sampling_fields))} choose how {process} is sampled: "
                              f"give them as sampler=TAG")
    return key_of(trained, prior, hold_share=hold_share, sampler=sampler, execution=execution, multi_task=multi_task)


def key_of(process: Process, prior: str, *, hold_share: float = 0.0, sampler: str | None = None,
           execution: Execution = OPEN_LOOP, multi_task: bool = False) -> MethodKey:
    """The key of a run of ``process`` from ``prior``; ``sampler`` None takes ``process.sampling_tag()``."""
    check_choice("process", process.name, PROCESSES)
    return MethodKey(process=process.name, steps=int(process.steps), params=tuple(sorted(process.variant().items())),
                     prior=prior if process.uses_prior else "gaussian", hold_share=float(hold_share or 0.0),
                     sampler=process.sampling_tag() if sampler is None else sampler, execution=execution,
                     multi_task=bool(multi_task))


def label(key: MethodKey) -> str:
    """The method's name in tables: the run's label (``TrainConfig.label``: ``bridge (line; consistent=True)``,
    ``DDPM, hold 0.5``) and the sampler where it is not the process's default (``bridge (line) by mean``).
    The execution and the task set are not part of it (:func:`describe`)."""
    name = method_label(key.trained(), key.prior, key.hold_share)
    return f"{name} by {key.sampler}" if key.sampler else name


def tasks_label(key: MethodKey) -> str:
    return "Multi2D" if key.multi_task else "single-task"


def describe(key: MethodKey) -> str:
    """Everything the key says, in words: ``bridge (line), N=16, replan32-warm-pursuit1, Multi2D``."""
    parts = [label(key), f"N={key.steps}", key.tag or "open loop, track", tasks_label(key)]
    return ", ".join(parts)


def parse_execution(tag: str) -> Execution:
    """The :class:`Execution` whose ``tag()`` is ``tag`` ('' -> open loop, tracked); a tag it would not write
    raises :class:`BridgeplanError`. Tags: ``replanK``, ``tolD``, ``afterstepS``, ``candM-SELECT``, ``warm``,
    ``arrival-RULE``, ``CONTROLLERR`` in that order, joined by ``-`` (``replan32-warm-arrival-keep``,
    ``pursuit1.5``)."""
    fields: dict[str, Any] = {}
    parts = tag.split("-") if tag else []
    i = 0
    try:
        while i < len(parts):
            part = parts[i]
            if part.startswith("replan"):
                fields["replan_every"] = int(part.removeprefix("replan"))
            elif part.startswith("tol"):
                fields["tolerance"] = float(part.removeprefix("tol"))
            elif part.startswith("afterstep"):
                fields["after_step"] = int(part.removeprefix("afterstep"))
            elif part.startswith("objtol"):
                fields["object_tolerance"] = float(part.removeprefix("objtol"))
            elif part.startswith("cand"):
                fields["candidates"], fields["select"] = int(part.removeprefix("cand")), parts[i + 1]
                i += 1
            elif part == "warm":
                fields["warm"] = True
            elif part == "arrival":
                fields["arrival"] = parts[i + 1]
                i += 1
            elif controller := next((c for c in CONTROLLERS if part.startswith(c) and part != c), None):
                fields["controller"], fields["lookahead"] = controller, float(part.removeprefix(controller))
            else:
                raise ValueError(part)
            i += 1
        execution = Execution(**fields)
    except (ValueError, IndexError, TypeError):
        execution = None
    if execution is None or execution.tag() != tag:
        raise BridgeplanError(f"unknown execution tag {tag!r}: expected parts replanK, tolD, afterstepS, "
                              f"candM-SELECT, warm, arrival-RULE, {'R/'.join(CONTROLLERS)}R joined by '-' in that "
                              f"order")
    return execution
