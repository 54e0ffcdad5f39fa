"""DDPM distilled into one or two network calls: consistency distillation (Song et al. 2023, as Consistency Policy
does for Diffuser-style policies) of a trained DDPM run, the teacher.

The student is a DDPM network of the teacher's shape and schedule (it starts from the teacher's weights: ``train``
loads them) whose x0 output is trained to be the **consistency function** of the teacher's probability-flow ODE
(DDIM with ``eta = 0``): the end point at the data of the teacher's ODE through ``(x_n, n)``. Training, at a
uniform step n of the forward process ``x_n ~ q(x_n | x0)``:

- n >= ``skip``: one teacher DDIM step from n to ``m = n - skip`` gives ``x_m``; the target is the student's own
  output there, ``sg(f(x_m, m))`` (the stop-gradient form of improved consistency training, no EMA target);
- n < ``skip``: the ODE's last jump, from below ``skip`` to the data, is the teacher's x0 prediction itself,
  the target.

So the targets at the last steps are the teacher's and consistency carries them up to n = N - 1, where one call
maps noise to a trajectory. Sampling is DDPM's (``ancestral`` or ``ddim``) with the student's x0 predictions at
``nfe`` evenly spaced steps from N - 1 down (NFE 2: N - 1 and (N - 1) / 2, the multistep consistency sampler; not
DDPM's N - 1 and 0, where a consistency function has nothing left to do). The student takes 1 or 2 calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes.ddpm import DDPM
from bridgeplan.trajectory import Conditions, apply_conditions

MAX_NFE = 2


@dataclass(frozen=True)
class Distill(DDPM):
    """A DDPM student distilled from the DDPM run ``teacher`` (its run directory); see the module docstring."""

    teacher: str = ""
    """The teacher's run directory (a DDPM run of the same maze, shape, network and steps)."""
    skip: int = 1
    """Teacher steps per consistency step (1: adjacent steps)."""
    name = "distill"
    display_name = "DDPM distilled"
    distills = True

    def __post_init__(self):
        super().__post_init__()
        if not 1 <= self.skip < self.steps:
            raise BridgeplanError(f"distill skip must be in 1..{self.steps - 1} (the teacher's steps), got {self.skip}")

    def variant(self) -> dict:
        """As DDPM's, without the teacher's path: runs are named and keyed by what was trained, and the teacher is
        the DDPM run of the same seed (``RunInfo.portable_config`` records it by its name)."""
        return {k: v for k, v in super().variant().items() if k != "teacher"}

    @property
    def max_nfe(self) -> int:
        return MAX_NFE

    def validate_nfe(self, nfe: int) -> None:
        if not 1 <= nfe <= MAX_NFE:
            raise BridgeplanError(f"nfe must be 1 or 2 for a DDPM distilled into one or two steps, got {nfe}")

    def sample_steps(self, nfe: int) -> list[int]:
        """``nfe`` evenly spaced steps from N - 1 down, none at 0: ``[N - 1]`` or ``[N - 1, (N - 1) / 2]``."""
        self.validate_nfe(nfe)
        return [round((self.steps - 1) * (1 - k / nfe)) for k in range(nfe)]

    def consistency_pair(self, model, teacher, x0: torch.Tensor, conditions: Conditions,
                         generator: torch.Generator | None = None
                         ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(x_n, n, target)``: a draw of the forward process at uniform steps n and its detached consistency
        target through the ``teacher`` network (module docstring)."""
        n = torch.randint(0, self.steps, (x0.shape[0],), generator=generator, device=x0.device)
        ab = self.alpha_bar.to(x0.device, x0.dtype)
        noise = torch.randn(x0.shape, generator=generator, device=x0.device, dtype=x0.dtype)
        ab_n = ab[n][:, None, None]
        x_n = apply_conditions(ab_n.sqrt() * x0 + (1 - ab_n).sqrt() * noise, conditions)
        with torch.no_grad():
            x0_teacher = teacher(x_n, n.to(x0.dtype)).clamp(-1, 1)
            m = n - self.skip
            inside = m >= 0  # rows whose teacher step lands on a step of the chain, not yet on the data
            ab_m = ab[m.clamp_min(0)][:, None, None]
            eps = (x_n - ab_n.sqrt() * x0_teacher) / (1 - ab_n).sqrt()
            x_m = apply_conditions(ab_m.sqrt() * x0_teacher + (1 - ab_m).sqrt() * eps, conditions)
            own = model(x_m, m.clamp_min(0).to(x0.dtype)).clamp(-1, 1)
            target = torch.where(inside[:, None, None], own, x0_teacher)
        return x_n, n, target

    def training_loss(self, model, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None, teacher=None) -> torch.Tensor:
        """The consistency-distillation loss against ``teacher``, the teacher's network (``x1``, a prior sample, is
        unused: the student starts from noise as DDPM does)."""
        if teacher is None:
            raise BridgeplanError("distill trains against its teacher's network: train it with `bridgeplan train`")
        x_n, n, target = self.consistency_pair(model, teacher, x0, conditions, generator)
        return torch.mean((model(x_n, n.to(x0.dtype)) - target) ** 2)
