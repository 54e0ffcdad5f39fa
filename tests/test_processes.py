"""Schedules, DDPM/DDIM and the I2SB bridge checked against closed forms (tiny sizes)."""

from __future__ import annotations

import math

import pytest
import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes import DDPM, Bridge, Flow, make_process, process_from_dict
from bridgeplan.processes.samplers import bridge_posterior_step
from bridgeplan.processes.schedules import (
    bridge_stds,
    cosine_betas,
    gaussian_product,
    i2sb_betas,
    spaced_steps,
)
from bridgeplan.trajectory import MAZE2D

B, H, D = 5, 8, 6

ACT_DIM = MAZE2D.act_dim


def oracle(x0: torch.Tensor, process):
    """A network that sees the truth: its output makes predict_x0 return x0 exactly."""
    def model(x_n, t):
        if isinstance(process, Bridge):
            std = process.std_fwd.to(x_n.dtype)[t.long()][:, None, None]
            return (x_n - x0) / std
        return x0
    return model


def conditions_for(x0: torch.Tensor) -> dict[int, torch.Tensor]:
    return {0: x0[:, 0, ACT_DIM:], H - 1: x0[:, -1, ACT_DIM:]}


def data(seed=0) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.rand((B, H, D), generator=gen, dtype=torch.float64) * 1.8 - 0.9


def test_cosine_schedule_matches_closed_form():
    n, s = 10, 0.008
    betas = cosine_betas(n, s)
    f = [math.cos((t / n + s) / (1 + s) * math.pi / 2) ** 2 for t in range(n + 1)]
    expected = [min(1 - f[t + 1] / f[t], 0.999) for t in range(n)]
    assert torch.allclose(betas, torch.tensor(expected, dtype=torch.float64), atol=1e-12)
    # alpha_bar telescopes to f(t) / f(0) up to the last step, where f(n) = cos^2(pi / 2) = 0 makes
    # beta 1 and the clip takes over
    alpha_bar = torch.cumprod(1 - betas, 0)
    assert torch.allclose(alpha_bar[:-1], torch.tensor(f[1:n], dtype=torch.float64) / f[0], rtol=1e-12, atol=0)
    assert betas[-1] == 0.999 and math.isclose(alpha_bar[-1], f[n - 1] / f[0] * 0.001, rel_tol=1e-12)


@pytest.mark.parametrize("n", [10, 11, 1000])
def test_i2sb_schedule_symmetric_and_cumulative(n):
    betas = i2sb_betas(n, 0.3)
    assert len(betas) == n
    assert torch.allclose(betas, betas.flip(0))
    b = torch.linspace(1e-2, (0.3 / n) ** 0.5, n, dtype=torch.float64) ** 2
    assert torch.allclose(betas[: n // 2], b[: n // 2])
    fwd, bwd = bridge_stds(betas)
    assert torch.all(fwd[1:] > fwd[:-1]) and torch.all(bwd[1:] < bwd[:-1])
    for k in (0, n // 3, n - 1):
        assert math.isclose(fwd[k] ** 2, float(betas[: k + 1].sum()), rel_tol=1e-12)
        assert math.isclose(bwd[k] ** 2, float(betas[k:].sum()), rel_tol=1e-12)


def test_gaussian_product():
    s1, s2 = torch.tensor(0.3, dtype=torch.float64), torch.tensor(0.7, dtype=torch.float64)
    mu0, mu1, var = gaussian_product(s1, s2)
    # the product of N(a, s1^2) and N(b, s2^2) has precision 1/s1^2 + 1/s2^2
    assert math.isclose(var, 1 / (1 / 0.09 + 1 / 0.49), rel_tol=1e-12)
    assert math.isclose(mu0, var / 0.09, rel_tol=1e-12) and math.isclose(mu1, var / 0.49, rel_tol=1e-12)


def test_spaced_steps():
    assert spaced_steps(16, 1) == [15, 0]
    assert spaced_steps(16, 15) == list(range(15, -1, -1))
    assert spaced_steps(1000, 4) == [999, 749, 500, 250, 0]


@pytest.mark.parametrize("process, nfes", [
    (DDPM(steps=10), range(1, 11)),
    (DDPM(steps=10, sampler="ddim"), range(1, 11)),
    (DDPM(steps=10, sampler="ddim", eta=1.0), (1, 3, 10)),
    (Bridge(steps=12), range(1, 12)),
    (Bridge(steps=12, beta_max=1.0, ot_ode=True), (1, 5, 11)),
])
def test_oracle_returns_data_exactly_at_every_nfe(process, nfes):
    x0 = data()
    cond = conditions_for(x0)
    gen = torch.Generator().manual_seed(1)
    for nfe in nfes:
        x_start = torch.randn((B, H, D), generator=gen, dtype=torch.float64)
        out = process.sample(oracle(x0, process), x_start, cond, nfe, generator=gen)
        assert torch.allclose(out, x0, atol=1e-12), (process, nfe)


def test_ddim_eta0_keeps_the_noise_direction():
    """With a perfect predictor, deterministic DDIM walks along x_t = sqrt(ab) x0 + sqrt(1 - ab) eps."""
    process = DDPM(steps=20, sampler="ddim")
    x0, eps = data(), torch.randn((B, H, D), generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    ab = process.alpha_bar
    seen = []

    def model(x_t, t):
        k = int(t[0])
        seen.append(torch.allclose(x_t, ab[k].sqrt() * x0 + (1 - ab[k]).sqrt() * eps, atol=1e-10))
        return x0

    x_start = ab[19].sqrt() * x0 + (1 - ab[19]).sqrt() * eps
    process.sample(model, x_start, {}, 5)
    assert len(seen) == 5 and all(seen)


def test_strided_ancestral_keeps_the_forward_marginal():
    """With a perfect predictor, a strided ancestral jump T -> s from x_T ~ q(x_T | x0) gives q(x_s | x0)."""
    process = DDPM(steps=20)
    ab = process.alpha_bar
    n_samples, x0_value = 40000, 0.6
    x0 = torch.full((n_samples, 1, 1), x0_value, dtype=torch.float64)
    gen = torch.Generator().manual_seed(7)
    eps = torch.randn(x0.shape, generator=gen, dtype=torch.float64)
    x_start = ab[19].sqrt() * x0 + (1 - ab[19]).sqrt() * eps
    seen = {}

    def model(x_t, t):
        seen[int(t[0])] = x_t
        return x0

    process.sample(model, x_start, {}, 3, generator=gen)
    assert sorted(seen) == [0, 10, 19]
    s = 10
    assert abs(float(seen[s].mean()) - float(ab[s].sqrt()) * x0_value) < 0.01
    assert abs(float(seen[s].var()) - float(1 - ab[s])) < 0.03 * float(1 - ab[s])


def test_ddpm_full_loop_no_noise():
    """Diffuser's chain with the noise switched off and a perfect predictor lands on the data."""
    process = DDPM(steps=8)
    x0 = data()
    calls = []

    def model(x_t, t):
        calls.append(int(t[0]))
        return x0

    out = process.sample(model, torch.zeros((B, H, D), dtype=torch.float64), {}, 8,
                         generator=torch.Generator().manual_seed(0))
    assert calls == list(range(7, -1, -1))
    assert torch.allclose(out, x0, atol=1e-12)


def test_bridge_marginal_endpoints_and_moments():
    bridge = Bridge(steps=20, beta_max=0.3)
    n_samples = 40000
    x0 = torch.full((n_samples, 1, 1), 0.5, dtype=torch.float64)
    x1 = torch.full((n_samples, 1, 1), -0.8, dtype=torch.float64)
    gen = torch.Generator().manual_seed(0)
    mu0, mu1, var = gaussian_product(bridge.std_fwd, bridge.std_bwd)
    for n in (0, 7, 19):
        x_n = bridge.marginal(x0, x1, torch.full((n_samples,), n), gen)
        mean = float(mu0[n]) * 0.5 + float(mu1[n]) * -0.8
        assert abs(float(x_n.mean()) - mean) < 4 * math.sqrt(float(var[n]) / n_samples) + 1e-12
        assert abs(float(x_n.var()) - float(var[n])) < 0.05 * float(var[n]) + 1e-12
    # step 0 is (almost) the data and the last step (almost) the prior
    assert float(mu0[0]) > 0.99 and float(mu1[-1]) > 0.99
    ot = Bridge(steps=20, beta_max=0.3, ot_ode=True).marginal(x0[:3], x1[:3], torch.tensor([0, 10, 19]))
    assert torch.allclose(ot[:, 0, 0], mu0[[0, 10, 19]] * 0.5 + mu1[[0, 10, 19]] * -0.8)


def test_bridge_one_jump_equals_chain_of_steps():
    """p(x_m | x_n, x0) is the composition of the single-step posteriors (closed-form marginalization)."""
    bridge = Bridge(steps=16, beta_max=1.0)
    std = bridge.std_fwd
    n_samples, n, m = 40000, 12, 3
    x0 = torch.full((n_samples, 1, 1), 0.4, dtype=torch.float64)
    x_n = torch.full((n_samples, 1, 1), -0.6, dtype=torch.float64)
    gen = torch.Generator().manual_seed(5)

    def noise():
        return torch.randn(x0.shape, generator=gen, dtype=torch.float64)

    jump = bridge_posterior_step(x0, x_n, float(std[n]), float(std[m]), noise())
    x = x_n
    for k in range(n, m, -1):
        x = bridge_posterior_step(x0, x, float(std[k]), float(std[k - 1]), noise())
    assert abs(float(jump.mean()) - float(x.mean())) < 0.01
    assert abs(float(jump.var()) - float(x.var())) < 0.05 * float(jump.var())
    # and the closed form of the jump: variance of the product of (std_m, sqrt(std_n^2 - std_m^2))
    d = (std[n] ** 2 - std[m] ** 2).sqrt()
    assert abs(float(jump.var()) - float(gaussian_product(std[m], d)[2])) < 0.05 * float(jump.var())


@pytest.mark.parametrize("process", [DDPM(steps=6), DDPM(steps=6, sampler="ddim", eta=0.5), Bridge(steps=6)])
def test_conditions_hold_in_every_sample(process):
    x0 = data()
    cond = conditions_for(x0)
    gen = torch.Generator().manual_seed(0)

    def model(x, t):  # an untrained, arbitrary network
        return torch.tanh(3 * x + t[:, None, None])

    for nfe in (1, process.max_nfe):
        x_start = torch.randn((B, H, D), generator=gen, dtype=torch.float64)
        out = process.sample(model, x_start, cond, nfe, gen)
        assert torch.equal(out[:, 0, ACT_DIM:], cond[0]) and torch.equal(out[:, -1, ACT_DIM:], cond[H - 1])


def test_nfe_and_process_errors():
    with pytest.raises(BridgeplanError, match="nfe"):
        Bridge(steps=16).validate_nfe(16)
    with pytest.raises(BridgeplanError, match="nfe"):
        DDPM(steps=16).validate_nfe(0)
    with pytest.raises(BridgeplanError, match="unknown process"):
        make_process("magic")
    with pytest.raises(BridgeplanError, match="unknown sampler"):
        DDPM(sampler="euler")
    with pytest.raises(BridgeplanError, match="bad parameters"):
        make_process("ddpm", beta_max=0.3)
    assert DDPM(steps=16).max_nfe == 16 and Bridge(steps=16).max_nfe == 15
    DDPM(steps=16).validate_nfe(16)
    Bridge(steps=16).validate_nfe(1)


@pytest.mark.parametrize("process", [DDPM(steps=10, sampler="ddim", eta=0.5),
                                     Bridge(steps=12, beta_max=1.0, ot_ode=True),
                                     Bridge(steps=12, consistent=True)])
def test_processes_round_trip_through_dicts(process):
    import json

    d = json.loads(json.dumps(process.to_dict()))
    assert process_from_dict(d) == process
    assert make_process(d["name"], **{k: v for k, v in d.items() if k != "name"}) == process


def test_bridge_dict_without_consistent_is_i2sb():
    """Runs saved before the ``consistent`` field read back as I2SB's bridge."""
    assert process_from_dict({"name": "bridge", "steps": 16, "beta_max": 1.0, "ot_ode": False}).consistent is False


@pytest.mark.parametrize("process", [DDPM(steps=10), Bridge(steps=10), Flow(steps=10, sigma=0.2)])
def test_training_reduces_the_loss(process):
    from bridgeplan.nets.unet import TemporalUNet

    torch.manual_seed(0)
    net = TemporalUNet(D, dim=8, dim_mults=(1, 2))
    x0 = data().float()
    cond = conditions_for(x0)
    x1 = torch.zeros_like(x0)
    gen = torch.Generator().manual_seed(0)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)

    @torch.no_grad()
    def loss_now():
        g = torch.Generator().manual_seed(123)
        return sum(float(process.training_loss(net, x0, x1, cond, g)) for _ in range(20)) / 20

    before = loss_now()
    for _ in range(100):
        loss = process.training_loss(net, x0, x1, cond, gen)
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss_now() < 0.7 * before


def test_bridge_mean_sampler_is_the_noise_free_chain():
    """`sampler="mean"` samples a bridge trained with noise by its posterior means: the OT-ODE chain of the same
    network, deterministic whatever the generator, and the same training (run name and loss untouched)."""
    x1 = torch.randn((B, H, D), generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    cond = conditions_for(data())

    def model(x, t):  # an untrained, arbitrary network
        return torch.tanh(3 * x + t[:, None, None])

    posterior, mean, ode = Bridge(8), Bridge(8, sampler="mean"), Bridge(8, ot_ode=True)

    def sample(process, nfe, seed):
        return process.sample(model, x1, cond, nfe, torch.Generator().manual_seed(seed))

    assert torch.equal(sample(mean, 7, 0), sample(ode, 7, 0)) and torch.equal(sample(mean, 7, 0), sample(mean, 7, 1))
    assert not torch.equal(sample(posterior, 7, 0), sample(posterior, 7, 1))
    assert torch.equal(sample(mean, 1, 0), sample(posterior, 1, 1))  # one call: no posterior step to draw
    assert mean.variant() == posterior.variant() == {} and posterior.with_sampler("mean") == mean
    with pytest.raises(BridgeplanError, match="unknown sampler"):
        Bridge(8, sampler="ode")
    with pytest.raises(BridgeplanError, match="no eta"):
        posterior.with_sampler("mean", eta=0.5)


def test_sampling_tag_names_what_differs_from_the_trained_default():
    """Results stores key evaluations by it: '' for a process sampled as it is by default."""
    assert DDPM(8).sampling_tag() == "" and Bridge(8).sampling_tag() == ""
    assert DDPM(8).with_sampler("ddim").sampling_tag() == "ddim"
    assert DDPM(8).with_sampler("ddim", eta=0.5).sampling_tag() == "ddim eta=0.5"
    assert Bridge(8, consistent=True).with_sampler("mean").sampling_tag() == "mean"
    assert Bridge(8).with_sampler("mean").with_sampler("posterior").sampling_tag() == ""
    assert Flow(8, sigma=0.5).with_sampler("stochastic").sampling_tag() == "stochastic"
