"""What every process shares: serialization, its name in tables and run names, and which of its
fields only change how it is sampled (not what is trained)."""

from __future__ import annotations

import dataclasses
from typing import Callable, ClassVar

import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.samplers import X0Predictor
from bridgeplan.trajectory import Conditions

Correct = Callable[[X0Predictor], X0Predictor]
"""A transform of the sampler's x0 predictor (``consistency.Correction.wrap``): ``sample(..., correct=...)``."""


class Process:
    """Base of the frozen process dataclasses (``DDPM``, ``Bridge``, ...)."""

    name: ClassVar[str]
    """Registry key and the ``--process`` value."""
    display_name: ClassVar[str]
    """How tables and figures call the method."""
    uses_prior: ClassVar[bool] = True
    """False: the process always starts from N(0, I) (DDPM); True: from the run's prior."""
    sampling_fields: ClassVar[tuple[str, ...]] = ()
    """Fields that choose how a trained model is sampled; changing them needs no retraining."""
    samplers: ClassVar[tuple[str, ...]] = ()
    """Samplers ``with_sampler`` accepts (empty: the process has one way to sample)."""
    takes_interval: ClassVar[bool] = False
    """True: the network takes a second time input besides the time (the mean flow's interval, the shortcut's step
    size; ``TemporalUNet(interval=True)``)."""
    distills: ClassVar[bool] = False
    """True: trained against a teacher's network (its run in the ``teacher`` field): ``training_loss`` takes it as
    ``teacher`` and the student starts from its weights (``runs.load_teacher``)."""
    forward_mode: ClassVar[bool] = False
    """True: training differentiates the network in forward mode (the mean flow's Jacobian-vector product), which a
    ``torch.compile``'d network does not support (its kernels have no forward-mode derivative)."""
    predicts_x0: ClassVar[bool] = True
    """True: every sampler step goes through :meth:`predict_x0`, so a correction of x0 (``sample``'s ``correct``)
    applies; a process whose sampler does not (none so far) sets False and corrections refuse it."""

    def to_dict(self) -> dict:
        """JSON-ready fields plus ``name``; inverted by ``processes.process_from_dict``."""
        return {"name": self.name, **dataclasses.asdict(self)}

    def variant(self) -> dict:
        """Training fields that differ from their defaults, ``steps`` aside (it is always named)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name != "steps" and f.name not in self.sampling_fields and getattr(self, f.name) != f.default}

    def label(self, prior: str) -> str:
        """The method's name in tables: ``DDPM``, ``bridge (line)``, ``bridge (line; beta_max=0.3)``."""
        inside = ([prior] if self.uses_prior else []) + [f"{k}={v}" for k, v in self.variant().items()]
        return f"{self.display_name} ({'; '.join(inside)})" if inside else self.display_name

    def run_tag(self, prior: str) -> list[str]:
        """The parts of a run's name that say what was trained: ``[bridge, line, N16, beta_max0.3]``."""
        tag = [self.name] + ([prior] if self.uses_prior else []) + [f"N{self.steps}"]
        return tag + [k if v is True else f"{k}{v}" for k, v in self.variant().items()]

    def network_input(self, x_n: torch.Tensor, n: int | torch.Tensor) -> torch.Tensor:
        """What the network is given of ``x_n`` at step ``n`` (sampling) or steps ``n`` ``[B]`` (training): ``x_n``
        itself unless the process scales it (a preconditioned bridge's ``c_in``)."""
        return x_n

    def network(self, model, x_n: torch.Tensor, n: int) -> torch.Tensor:
        """The network's output on the batch ``x_n`` at step ``n`` (given as a float, as in training)."""
        return model(self.network_input(x_n, n), torch.full((x_n.shape[0],), float(n), device=x_n.device))

    def predict_x0(self, model, x_n: torch.Tensor, n: int) -> torch.Tensor:
        """The clean trajectory the network sees in ``x_n`` at step ``n``, clipped to [-1, 1]. By default the
        network predicts x0 itself (Diffuser's parametrization; a process with another one overrides this and
        :meth:`training_target` together)."""
        return self.network(model, x_n, n).clamp(-1, 1)

    def x0_predictor(self, model, correct: Correct | None = None) -> X0Predictor:
        """``predict_x0(x_n, n)`` of ``model`` for the samplers, transformed by ``correct`` when given."""
        def predict(x_n: torch.Tensor, n: int) -> torch.Tensor:
            return self.predict_x0(model, x_n, n)

        return predict if correct is None else correct(predict)

    def training_target(self, x0: torch.Tensor, x_n: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
        """The regression label at ``(x_n, n)``: the inverse of :meth:`predict_x0` (here x0 itself)."""
        return x0

    def output_weight(self, n: torch.Tensor) -> torch.Tensor | None:
        """Per-sample weight ``[B]`` of the squared output error at steps ``n``; None: equal weights."""
        return None

    def training_loss(self, model, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> torch.Tensor:
        """L2 between the network's output and the label of the process's ``training_pair`` (``x1``: the
        prior sample for ``x0``; a process without a prior ignores it), weighted by :meth:`output_weight`."""
        x_n, n, target = self.training_pair(x0, x1, conditions, generator)
        sq = (model(self.network_input(x_n, n), n.float()) - target) ** 2
        weight = self.output_weight(n)
        if weight is None:
            return torch.mean(sq)
        return torch.mean(weight.to(sq.dtype)[:, None, None] * sq)

    def sampling_tag(self) -> str:
        """The sampling fields that differ from their defaults ('' when none do), e.g. ``mean`` or ``ddim eta=0.5``:
        the sampler by its name, others as ``field=value``. Results stores key evaluations by it."""
        changed = [(f.name, getattr(self, f.name)) for f in dataclasses.fields(self)
                   if f.name in self.sampling_fields and getattr(self, f.name) != f.default]
        return " ".join(str(v) if k == "sampler" else f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                        for k, v in changed)

    @property
    def max_nfe(self) -> int:
        """The most network calls a plan may take: one per step unless the process says otherwise."""
        return self.steps

    def validate_nfe(self, nfe: int) -> None:
        """Refuse an NFE this process cannot be sampled with (1..``max_nfe`` unless the process says otherwise)."""
        if not 1 <= nfe <= self.max_nfe:
            raise BridgeplanError(f"nfe must be in 1..{self.max_nfe} for {self.display_name} with {self.steps} steps, "
                                  f"got {nfe}")

    def usable_samplers(self) -> tuple[str, ...]:
        """The :attr:`samplers` this process, with its parameters, can be sampled by (all of them by default)."""
        return self.samplers

    def with_sampler(self, sampler: str, eta: float = 0.0) -> Process:
        """The same trained process sampled another way; only processes with samplers to choose have it, and only
        DDPM's take ``eta``."""
        if not self.samplers:
            raise BridgeplanError(f"--sampler: {self.name} has one way to sample")
        if eta != 0:
            raise BridgeplanError(f"{self.display_name} samplers take no eta (it is DDIM's), got {eta}")
        return dataclasses.replace(self, sampler=sampler)
