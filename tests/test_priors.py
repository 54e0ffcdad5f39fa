"""Priors: shapes, inpainted endpoints, the straight line in physical units, the learned prior (tiny)."""

from __future__ import annotations

import pytest
import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.prior_mlp import PriorMLP
from bridgeplan.normalizer import Normalizer
from bridgeplan.priors import (
    MAX_SPEED,
    PRIORS,
    SIM_DT,
    GaussianPrior,
    LearnedPrior,
    LinePrior,
    make_prior,
    train_prior_loss,
)
from bridgeplan.trajectory import MAZE2D

B, H = 4, 8
NORMALIZER = Normalizer(low=(-1.0, -1.0, -2.0, -1.0, -5.0, -5.0), high=(1.0, 1.0, 3.0, 4.0, 5.0, 5.0))
ACT_DIM, OBS_DIM, TRANSITION_DIM = MAZE2D.act_dim, MAZE2D.obs_dim, MAZE2D.transition_dim
STATE = slice(ACT_DIM, None)


def conditions(start_xy, goal_xy, start_v=None):
    """Normalized planner-style conditions: the start with a velocity, the goal at rest."""
    start_xy = torch.as_tensor(start_xy, dtype=torch.float32)
    goal_xy = torch.as_tensor(goal_xy, dtype=torch.float32)
    start_v = torch.full_like(start_xy, 0.3) if start_v is None else start_v
    start = torch.cat([start_xy, start_v], dim=-1)
    goal = torch.cat([goal_xy, torch.zeros_like(goal_xy)], dim=-1)
    return {0: NORMALIZER.normalize(start, STATE), H - 1: NORMALIZER.normalize(goal, STATE)}


def some_conditions():
    g = torch.Generator().manual_seed(0)
    start = torch.rand((B, 2), generator=g) * 4 - 1
    goal = torch.rand((B, 2), generator=g) * 4 - 1
    return conditions(start, goal)


def all_priors():
    torch.manual_seed(0)
    return [GaussianPrior(MAZE2D), LinePrior(NORMALIZER, MAZE2D), LearnedPrior(PriorMLP(OBS_DIM, H, TRANSITION_DIM))]


@pytest.mark.parametrize("prior", all_priors(), ids=lambda p: p.name)
def test_shape_and_endpoints(prior):
    cond = some_conditions()
    x = prior.sample(cond, H, B, generator=torch.Generator().manual_seed(1))
    assert x.shape == (B, H, TRANSITION_DIM) and x.dtype == torch.float32
    assert torch.isfinite(x).all()
    assert torch.equal(x[:, 0, ACT_DIM:], cond[0]) and torch.equal(x[:, -1, ACT_DIM:], cond[H - 1])


def test_gaussian_prior_is_seeded_white_noise():
    cond = some_conditions()
    a = GaussianPrior(MAZE2D).sample(cond, H, B, torch.Generator().manual_seed(3))
    b = GaussianPrior(MAZE2D).sample(cond, H, B, torch.Generator().manual_seed(3))
    assert torch.equal(a, b)
    big = GaussianPrior(MAZE2D).sample({0: cond[0][:1].expand(4000, -1), 63: cond[H - 1][:1].expand(4000, -1)},
                                 64, 4000, torch.Generator().manual_seed(4))
    inner = big[:, 1:-1]
    assert abs(float(inner.mean())) < 0.01 and abs(float(inner.std()) - 1) < 0.01


def test_line_prior_in_physical_units():
    start, goal = torch.tensor([[0.0, 0.5], [2.0, 3.0]]), torch.tensor([[1.4, 0.29], [2.0, 3.0]])
    cond = {0: conditions(start, goal)[0][:2], H - 1: conditions(start, goal)[H - 1][:2]}
    x = LinePrior(NORMALIZER, MAZE2D).sample(cond, H, 2)
    traj = NORMALIZER.unnormalize(x.double())
    act, pos, vel = traj[..., :2], traj[..., 2:4], traj[..., 4:]
    frac = torch.arange(H, dtype=torch.float64)[None, :, None] / (H - 1)
    expected = start.double()[:, None] + frac * (goal - start).double()[:, None]
    assert torch.allclose(pos, expected, atol=1e-5)
    # interior velocities: the constant one covering the line in (H-1) steps of SIM_DT seconds, clipped
    v = ((goal - start).double() / ((H - 1) * SIM_DT)).clamp(-MAX_SPEED, MAX_SPEED)
    assert torch.allclose(vel[:, 1:-1], v[:, None].expand(-1, H - 2, -1), atol=1e-5)
    assert torch.allclose(vel[0, 1, 1], torch.tensor(-3.0, dtype=torch.float64), atol=1e-5)  # -0.21 / 0.07
    assert torch.allclose(vel[0, 1, 0], torch.tensor(MAX_SPEED, dtype=torch.float64), atol=1e-5)  # 20 -> 5
    # the action: the unit vector toward the goal at every step; zero when start == goal
    d = (goal - start)[0].double()
    assert torch.allclose(act[0], (d / d.norm())[None].expand(H, -1), atol=1e-5)
    assert torch.allclose(act[1], torch.zeros(H, 2, dtype=torch.float64), atol=1e-5)
    # endpoints: the start's own velocity, the goal at rest
    assert torch.allclose(vel[:, 0], torch.full((2, 2), 0.3, dtype=torch.float64), atol=1e-5)
    assert torch.allclose(vel[:, -1], torch.zeros(2, 2, dtype=torch.float64), atol=1e-5)


def test_max_speed_matches_the_simulator():
    pytest.importorskip("mujoco")
    from bridgeplan.envs.maze2d.sim import MAX_SPEED as SIM_MAX_SPEED

    assert MAX_SPEED == SIM_MAX_SPEED


def test_learned_prior_is_the_net_output_and_trains():
    torch.manual_seed(0)
    net = PriorMLP(OBS_DIM, H, TRANSITION_DIM)
    cond = some_conditions()
    x = LearnedPrior(net).sample(cond, H, B)
    with torch.no_grad():
        raw = net(cond[0], cond[H - 1])
    assert torch.equal(x[:, 1:-1], raw[:, 1:-1]) and torch.equal(x[:, :, :ACT_DIM], raw[:, :, :ACT_DIM])
    assert not x.requires_grad
    # a few Adam steps on a fixed batch of windows reduce the prior's loss
    x0 = torch.rand((16, H, TRANSITION_DIM), generator=torch.Generator().manual_seed(2)) * 2 - 1
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    with torch.no_grad():
        before = float(train_prior_loss(net, x0, MAZE2D))
    for _ in range(50):
        loss = train_prior_loss(net, x0, MAZE2D)
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        assert float(train_prior_loss(net, x0, MAZE2D)) < 0.5 * before


def test_registry_and_errors():
    assert set(PRIORS) == {"gaussian", "line", "learned", "coarse", "warm"}
    net = PriorMLP(OBS_DIM, H, TRANSITION_DIM)
    for name in PRIORS:
        prior = make_prior(name, NORMALIZER, MAZE2D, net=net)
        assert prior.name == name
    with pytest.raises(BridgeplanError, match="unknown prior .spline.*gaussian, line, learned, coarse, warm"):
        make_prior("spline", NORMALIZER, MAZE2D)
    with pytest.raises(BridgeplanError, match="learned prior needs"):
        make_prior("learned", NORMALIZER, MAZE2D)
    cond = some_conditions()
    with pytest.raises(BridgeplanError, match="horizon 8, not 16"):
        LearnedPrior(net).sample({0: cond[0], 15: cond[H - 1]}, 16, B)
    with pytest.raises(BridgeplanError, match="t=0 and t=15"):
        GaussianPrior(MAZE2D).sample(cond, 16, B)
    with pytest.raises(BridgeplanError, match="batch"):
        LinePrior(NORMALIZER, MAZE2D).sample(cond, H, B + 1)


@pytest.mark.parametrize("prior", all_priors(), ids=lambda p: p.name)
def test_conditions_hold_from_every_prior_through_every_process(prior):
    from bridgeplan.processes import make_process

    cond = some_conditions()

    def model(x, t):  # an arbitrary, untrained network
        return torch.tanh(2 * x - 0.1 * t[:, None, None])

    for process in (make_process("ddpm", steps=5), make_process("ddpm", steps=5, sampler="ddim", eta=1.0),
                    make_process("bridge", steps=5)):
        gen = torch.Generator().manual_seed(0)
        for nfe in (1, process.max_nfe):
            x = process.sample(model, prior.sample(cond, H, B, gen), cond, nfe, gen)
            assert torch.equal(x[:, 0, ACT_DIM:], cond[0]) and torch.equal(x[:, -1, ACT_DIM:], cond[H - 1])
