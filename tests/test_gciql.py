"""GCIQL (bridgeplan.gciql) in GCBC's one training loop: its losses against their closed forms, which network each
loss moves, the slow critics, the goals' rewards, exact resume, and a trained value that ranks goals by distance."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from bridgeplan.gcbc import GCBCConfig, GoalDataset, load_policy, read_metrics, train_gcbc
from bridgeplan.gciql import GCIQL, expectile_loss
from tests.test_gcbc import line_dataset

TINY = {"hidden_dims": (16, 16), "batch_size": 32, "log_every": 5, "checkpoint_every": 10, "device": "cpu",
        "agent": "gciql", "alpha": 1.0}


def test_expectile_loss():
    diff = torch.tensor([-2.0, -1.0, 0.0, 1.0, 3.0])
    np.testing.assert_allclose(expectile_loss(diff, 0.9).numpy(), [0.1 * 4, 0.1 * 1, 0.0, 0.9 * 1, 0.9 * 9],
                               rtol=1e-6)


def _batch(n=8, obs_dim=3, act_dim=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    obs, nxt, goals = (torch.randn(n, obs_dim, generator=g) for _ in range(3))
    actions = torch.rand(n, act_dim, generator=g) * 2 - 1
    reached = (torch.rand(n, generator=g) < 0.3).float()
    return obs, nxt, actions, goals, goals.flip(0), reached - 1, 1 - reached


def test_each_loss_moves_its_own_network():
    """The total loss's gradient on each network is that of its own term, computed by hand (the others constants);
    the slow critics get none."""
    torch.manual_seed(0)
    agent = GCIQL(3, 2, (8,))
    obs, nxt, actions, vg, ag, rewards, masks = _batch()
    loss, logged = agent.loss(obs, nxt, actions, vg, ag, rewards, masks, 0.99, 0.9, 0.5)
    loss.backward()
    assert all(p.grad is None for p in agent.target_critic.parameters())
    got = {n: p.grad.clone() for n, p in agent.named_parameters() if p.grad is not None}
    agent.zero_grad()
    with torch.no_grad():  # the value's target: the slow critics' minimum; the critics': r + discount * mask * V(s')
        q_slow = agent.target_critic(obs, vg, actions).min(0).values
        backup = rewards + 0.99 * masks * agent.value(nxt, vg)[0]
    v = agent.value(obs, vg)[0]
    diff = q_slow - v
    value_loss = (torch.where(diff >= 0, 0.9, 0.1) * diff ** 2).mean()
    critic_loss = ((agent.critic(obs, vg, actions) - backup) ** 2).sum(0).mean()
    (value_loss + critic_loss).backward()
    for name, p in [*agent.value.named_parameters(prefix="value"), *agent.critic.named_parameters(prefix="critic")]:
        torch.testing.assert_close(got[name], p.grad, msg=name)
    torch.testing.assert_close(logged[:2], torch.stack([value_loss, critic_loss]).detach())
    assert any(got[n].abs().sum() > 0 for n in got if n.startswith("actor"))


def test_slow_critics_follow_by_polyak():
    agent = GCIQL(3, 2, (8,))
    before = [p.clone() for p in agent.target_critic.parameters()]
    with torch.no_grad():
        for p in agent.critic.parameters():
            p.add_(1.0)
    agent.update_target(0.25)
    for b, p, t in zip(before, agent.critic.parameters(), agent.target_critic.parameters()):
        torch.testing.assert_close(t, 0.75 * b + 0.25 * p)


def test_rewards_mark_goals_that_are_the_state(tmp_path, monkeypatch):
    """Value goals: the state itself with probability 0.2 (reward 0, the backup stops there), else reward -1."""
    from bridgeplan import gcbc

    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz")), **{**TINY, "batch_size": 4000})
    step = gcbc._GCIQLStep(config, GoalDataset.for_config(config), torch.device("cpu"))
    seen = {}

    def spy(obs, nxt, actions, vg, ag, rewards, masks, *args):
        seen.update(rewards=rewards, masks=masks, same=(vg == obs).all(1), next=nxt, obs=obs, actions=actions)
        return torch.zeros(()), torch.zeros(4)

    monkeypatch.setattr(step.net, "loss", spy)
    obs = torch.as_tensor(step.data.observations)
    step.loss(obs, torch.as_tensor(step.data.actions), np.random.default_rng(0))
    reached = seen["rewards"] == 0
    assert torch.equal(reached, seen["masks"] == 0) and torch.equal(reached, seen["same"])
    assert 0.18 < reached.float().mean() < 0.26  # 0.2, and now and then a future state equal to it (none here)
    # the state after each: on these lines one step moves by 0.2 times the action
    torch.testing.assert_close(seen["next"] - seen["obs"], 0.2 * seen["actions"])


def test_resume_is_exact(tmp_path):
    """N steps in one go and N/2 + N/2 give the same networks (critics and slow critics too); the policy loads as
    GCBC's."""
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz")), steps=20, lr=1e-3, **TINY)
    straight, interrupted = tmp_path / "straight", tmp_path / "interrupted"
    train_gcbc(config, straight, progress=False)
    train_gcbc(dataclasses.replace(config, steps=10), interrupted, progress=False)
    train_gcbc(config, interrupted, resume=True, progress=False)
    a = torch.load(straight / "checkpoint.pt", weights_only=False)
    b = torch.load(interrupted / "checkpoint.pt", weights_only=False)
    assert a["agent"].keys() == b["agent"].keys() and any(k.startswith("target_critic") for k in a["agent"])
    for key in a["agent"]:
        assert torch.equal(a["agent"][key], b["agent"][key]), key
    assert set(read_metrics(straight)[0]) >= {"value_loss", "critic_loss", "actor_loss", "mse"}
    assert load_policy(straight).step == 20


def test_a_trained_value_ranks_goals_by_distance(tmp_path):
    """After training, the value of a state is higher for a goal 2 steps along its line than for one 12 steps along."""
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz")), steps=600, lr=1e-3, seed=1,
                        **{**TINY, "hidden_dims": (64, 64), "batch_size": 256, "log_every": 300,
                           "checkpoint_every": 600})
    run = train_gcbc(config, tmp_path / "run", progress=False)
    agent = GCIQL(2, 2, (64, 64))
    agent.load_state_dict(torch.load(run / "checkpoint.pt", weights_only=False)["agent"])
    data = GoalDataset(config.dataset)
    obs = torch.as_tensor(data.observations)
    starts = torch.arange(0, len(obs), 16)  # each line's first state; its states 2 and 12 steps on
    near, far = agent.value(obs[starts], obs[starts + 2])[0], agent.value(obs[starts], obs[starts + 12])[0]
    assert (near > far).float().mean() > 0.8
