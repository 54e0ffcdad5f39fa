"""Goal-conditioned implicit Q-learning (GCIQL), OGBench's strongest simple baseline, re-implemented in PyTorch from
``impls/agents/gciql.py``; trained by the one loop of :mod:`bridgeplan.gcbc` (``GCBCConfig.agent = "gciql"``).

- a value ``V(s, g)``, two critics ``Q_1, Q_2(s, g, a)`` and their slow copy (Polyak, ``tau``), MLPs with layer
  normalization; the actor is GCBC's policy (:class:`bridgeplan.nets.policy.GoalPolicy`, constant std 1);
- rewards from goals alone: ``r = 0`` where the goal is the state itself (its index), else ``-1``, and the target stops
  there (``mask = 0``);
- value: the expectile (0.9) regression of ``V(s, g)`` on ``min(Q'_1, Q'_2)(s, g, a)`` of the slow critics;
- critics: ``Q_i(s, g, a) -> r + discount * mask * V(s', g)``;
- actor, DDPG+BC: ``-min Q(s, g, clip(pi(s, g))) / mean|Q|`` (the scale held fixed) ``+ alpha * NLL(a | s, g)``;
- each loss moves its own network only (the others enter it as constants), one Adam over the three;
- goals: the value's from the state itself (0.2), a future state at a geometric offset (0.5) or a random state (0.3);
  the actor's a future state uniformly, as GCBC's.
"""

from __future__ import annotations

import copy
from typing import Sequence

import torch
from torch import nn
from torch.func import functional_call

from bridgeplan.nets.policy import GoalPolicy, unit_gaussian_nll


class GoalValue(nn.Module):
    """``MLP(concat(inputs))`` to a scalar, GELU and layer normalization after every hidden layer (OGBench's
    ``GCValue``); ``ensemble`` heads side by side (the critics)."""

    def __init__(self, in_dim: int, hidden_dims: Sequence[int], ensemble: int = 1, layer_norm: bool = True):
        super().__init__()
        self.nets = nn.ModuleList()
        for _ in range(ensemble):
            layers: list[nn.Module] = []
            width = in_dim
            for size in hidden_dims:
                layers += [nn.Linear(width, size), nn.GELU(approximate="tanh")]
                layers += [nn.LayerNorm(size)] if layer_norm else []
                width = size
            layers.append(nn.Linear(width, 1))
            self.nets.append(nn.Sequential(*layers))

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        """``[ensemble, B]`` values."""
        x = torch.cat(inputs, dim=-1)
        return torch.stack([net(x).squeeze(-1) for net in self.nets])


def expectile_loss(diff: torch.Tensor, expectile: float) -> torch.Tensor:
    """``|expectile - 1(diff < 0)| * diff^2`` per element."""
    weight = torch.where(diff >= 0, expectile, 1.0 - expectile)
    return weight * diff.square()


class GCIQL(nn.Module):
    """The actor, the value, the critics and the slow critics of one GCIQL agent."""

    def __init__(self, obs_dim: int, action_dim: int, hidden_dims: Sequence[int], layer_norm: bool = True):
        super().__init__()
        self.actor = GoalPolicy(obs_dim, obs_dim, action_dim, hidden_dims)
        self.value = GoalValue(2 * obs_dim, hidden_dims, 1, layer_norm)
        self.critic = GoalValue(2 * obs_dim + action_dim, hidden_dims, 2, layer_norm)
        self.target_critic = copy.deepcopy(self.critic).requires_grad_(False)

    @staticmethod
    def _frozen(module: nn.Module, *inputs: torch.Tensor) -> torch.Tensor:
        """``module(*inputs)`` with its parameters as constants (gradients reach the inputs only)."""
        params = {k: v.detach() for k, v in module.named_parameters()}
        return functional_call(module, params, inputs)

    def loss(self, obs, next_obs, actions, value_goals, actor_goals, rewards, masks, discount: float,
             expectile: float, alpha: float) -> tuple[torch.Tensor, torch.Tensor]:
        """The summed loss and ``[value, critic, actor, actor's mse]`` (detached)."""
        with torch.no_grad():
            q_target = self.target_critic(obs, value_goals, actions).min(dim=0).values
            next_v = self.value(next_obs, value_goals)[0]
            q_backup = rewards + discount * masks * next_v
        v = self.value(obs, value_goals)[0]
        value_loss = expectile_loss(q_target - v, expectile).mean()
        q = self.critic(obs, value_goals, actions)
        critic_loss = (q - q_backup).square().sum(dim=0).mean()
        mean = self.actor(obs, actor_goals)
        q_pi = self._frozen(self.critic, obs, actor_goals, mean.clamp(-1.0, 1.0)).min(dim=0).values
        q_loss = -q_pi.mean() / (q_pi.abs().mean().detach() + 1e-6)
        bc_loss = alpha * unit_gaussian_nll(mean, actions).mean()
        actor_loss = q_loss + bc_loss
        logged = torch.stack([value_loss, critic_loss, actor_loss, (mean - actions).square().mean()]).detach()
        return value_loss + critic_loss + actor_loss, logged

    @torch.no_grad()
    def update_target(self, tau: float) -> None:
        for p, tp in zip(self.critic.parameters(), self.target_critic.parameters()):
            tp.mul_(1.0 - tau).add_(p, alpha=tau)
