"""DDPM as Diffuser trains it: cosine schedule, x0 prediction, L2 loss, inpainted conditions."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import torch

from bridgeplan.errors import BridgeplanError, check_choice
from bridgeplan.processes.base import Correct, Process
from bridgeplan.processes.samplers import ddim, ddpm_ancestral
from bridgeplan.processes.schedules import cosine_betas
from bridgeplan.trajectory import Conditions, apply_conditions

SAMPLERS = ("ancestral", "ddim")


@dataclass(frozen=True)
class DDPM(Process):
    """Diffusion over ``steps`` noise levels; sampled by ``sampler`` in any NFE from 1 to ``steps``.

    The network predicts x0 from ``(x_t, t)``, ``t`` the step index 0..steps-1 as a float (Diffuser).
    ``ancestral`` with NFE = steps is Diffuser's chain; fewer NFE take evenly spaced steps (strided
    ancestral, i.e. improved DDPM's respacing, or DDIM with ``eta``; ``eta = 0`` is deterministic).
    To sample a trained DDPM another way, ``dataclasses.replace(process, sampler="ddim", eta=0.0)``:
    the sampler does not change training.
    """

    steps: int = 64
    sampler: str = "ancestral"
    eta: float = 0.0
    name = "ddpm"
    display_name = "DDPM"
    uses_prior = False
    sampling_fields = ("sampler", "eta")
    samplers = SAMPLERS

    def __post_init__(self):
        if self.steps < 1:
            raise BridgeplanError(f"diffusion steps must be >= 1, got {self.steps}")
        check_choice("sampler", self.sampler, SAMPLERS)
        if self.eta < 0:
            raise BridgeplanError(f"eta must be >= 0, got {self.eta}")

    @cached_property
    def alpha_bar(self) -> torch.Tensor:
        return torch.cumprod(1 - cosine_betas(self.steps), 0)

    def with_sampler(self, sampler: str, eta: float = 0.0) -> DDPM:
        return dataclasses.replace(self, sampler=sampler, eta=eta)

    def training_pair(self, x0: torch.Tensor, x1: torch.Tensor, conditions: Conditions,
                      generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(x_t, t, target)`` with x_t from q(x_t | x0) at a uniform random step t (``x1`` unused)."""
        t = torch.randint(0, self.steps, (x0.shape[0],), generator=generator, device=x0.device)
        ab = self.alpha_bar.to(x0.device, x0.dtype)[t][:, None, None]
        noise = torch.randn(x0.shape, generator=generator, device=x0.device, dtype=x0.dtype)
        x_t = apply_conditions(ab.sqrt() * x0 + (1 - ab).sqrt() * noise, conditions)
        return x_t, t, self.training_target(x0, x_t, t)

    def sample_steps(self, nfe: int) -> list[int]:
        """``nfe`` evenly spaced steps from ``steps - 1`` down to 0."""
        self.validate_nfe(nfe)
        if nfe == 1:
            return [self.steps - 1]
        return sorted({round(i * (self.steps - 1) / (nfe - 1)) for i in range(nfe)}, reverse=True)

    def sample(self, model, x_start: torch.Tensor, conditions: Conditions, nfe: int,
               generator: torch.Generator | None = None, correct: Correct | None = None) -> torch.Tensor:
        """From noise ``x_start`` to a trajectory in ``nfe`` network calls (x0 predictions transformed by
        ``correct``, e.g. a consistency correction)."""
        steps = self.sample_steps(nfe)
        predict = self.x0_predictor(model, correct)
        if self.sampler == "ddim":
            return ddim(predict, x_start, conditions, steps, self.alpha_bar, self.eta, generator)
        return ddpm_ancestral(predict, x_start, conditions, steps, self.alpha_bar, generator)
