"""The processes' formulas against closed forms derived here independently.

Posterior coefficients come from conditioning a joint Gaussian (float64 covariance algebra over the
forward process), not from the textbook formulas the code uses; a process's label is tied to its
``predict_x0``; the consistent bridge's training marginals are checked against its own sampling chain.
"""

from __future__ import annotations

import math

import pytest
import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.processes import DDPM, Bridge, Flow
from bridgeplan.processes.samplers import bridge_posterior, bridge_sample, ddpm_ancestral, ddpm_posterior
from bridgeplan.processes.schedules import bridge_stds, chain_marginal, gaussian_product, i2sb_betas, spaced_steps
from bridgeplan.trajectory import MAZE2D

F64 = torch.float64

ACT_DIM = MAZE2D.act_dim


def regress(rows: list[list[float]], target: int, given: list[int]) -> tuple[list[float], float]:
    """Variables ``v = A z``, ``z ~ N(0, I)``: E[v_target | v_given] = coefs . v_given, and the residual variance."""
    a = torch.tensor(rows, dtype=F64)
    cov = a @ a.T
    s_gg = cov[given][:, given]
    s_tg = cov[target, given]
    coefs = torch.linalg.solve(s_gg, s_tg)
    return coefs.tolist(), float(cov[target, target] - s_tg @ coefs)


def ddpm_conditional(ab_t: float, ab_s: float) -> tuple[float, float, float]:
    """q(x_s | x_t, x0) from the forward chain x0 -> x_s -> x_t: ``(coef_x0, coef_xt, var)``."""
    r = ab_t / ab_s  # x_t = sqrt(r) x_s + sqrt(1 - r) e2, the forward step from s to t
    rows = [[1, 0, 0],
            [ab_s ** 0.5, (1 - ab_s) ** 0.5, 0],
            [r ** 0.5 * ab_s ** 0.5, r ** 0.5 * (1 - ab_s) ** 0.5, (1 - r) ** 0.5]]
    (c0, ct), var = regress(rows, 1, [0, 2])
    return c0, ct, var


def brownian_rows(stds: list[float]) -> list[list[float]]:
    """Rows of ``(x0, x_0, ..., x_{K-1})`` for a Brownian motion from x0 with variance ``stds[k]^2`` at k."""
    k = len(stds)
    incs = [stds[0]] + [(stds[j] ** 2 - stds[j - 1] ** 2) ** 0.5 for j in range(1, k)]
    rows = [[1.0] + [0.0] * k]
    for j in range(k):
        rows.append([1.0] + incs[: j + 1] + [0.0] * (k - j - 1))
    return rows


def close(got: float, want: float, tol: float = 1e-10) -> bool:
    return math.isclose(got, want, rel_tol=tol, abs_tol=tol)


# --- posterior coefficients -------------------------------------------------------------------------

def test_ddpm_posterior_matches_the_gaussian_conditional():
    """Every (t, s) pair, strided included, against the conditional of the joint of (x0, x_s, x_t)."""
    ab = DDPM(steps=20).alpha_bar.tolist()
    for t in range(1, 20):
        for s in range(t):
            got, want = ddpm_posterior(ab[t], ab[s]), ddpm_conditional(ab[t], ab[s])
            assert all(close(g, w) for g, w in zip(got, want)), (t, s, got, want)


def test_bridge_posterior_matches_the_brownian_conditional():
    """p(x_m | x_n, x0) for every m < n: x_m = x0 + std_m z1, x_n = x_m + sqrt(std_n^2 - std_m^2) z2."""
    std = Bridge(steps=16, beta_max=1.0).std_fwd.tolist()
    for n in range(1, 16):
        for m in range(n):
            d = (std[n] ** 2 - std[m] ** 2) ** 0.5
            (c0, cn), var = regress([[1, 0, 0], [1, std[m], 0], [1, std[m], d]], 1, [0, 2])
            a, b, v = bridge_posterior(std[n], std[m])
            assert close(a, c0) and close(b, cn) and close(v, var), (n, m)


def one_step_moments(sampler, x_t_value: float, x0_value: float, t: int, s: int, n_samples: int = 40000):
    """Mean and variance of the state a sampler hands the network at ``s`` after one step from a fixed x_t."""
    x0 = torch.full((n_samples, 1, 1), x0_value, dtype=F64)
    seen = {}

    def predict(x, k):
        seen[k] = x
        return x0

    sampler(predict, torch.full_like(x0, x_t_value), [t, s, 0], torch.Generator().manual_seed(11))
    return float(seen[s].mean()), float(seen[s].var())


def assert_moments(mean, var, want_mean, want_var, n_samples=40000):
    assert abs(mean - want_mean) < 5 * math.sqrt(want_var / n_samples), (mean, want_mean)
    assert abs(var - want_var) < 5 * math.sqrt(2 / n_samples) * want_var, (var, want_var)


def test_ddpm_ancestral_step_has_the_conditional_moments():
    """One step of the sampler itself (not just its coefficients), Monte Carlo against the closed form."""
    ab = DDPM(steps=20).alpha_bar
    t, s, x_t, x0 = 12, 5, -0.7, 0.6
    c0, ct, var = ddpm_conditional(float(ab[t]), float(ab[s]))
    mean, v = one_step_moments(lambda p, x, st, g: ddpm_ancestral(p, x, {}, st, ab, g), x_t, x0, t, s)
    assert_moments(mean, v, c0 * x0 + ct * x_t, var)


def test_bridge_sampler_step_has_the_conditional_moments():
    std = Bridge(steps=16, beta_max=1.0).std_fwd
    n, m, x_n, x0 = 12, 6, -0.7, 0.6
    sn, sm = float(std[n]), float(std[m])
    (c0, cn), var = regress([[1, 0, 0], [1, sm, 0], [1, sm, (sn ** 2 - sm ** 2) ** 0.5]], 1, [0, 2])
    mean, v = one_step_moments(lambda p, x, st, g: bridge_sample(p, x, {}, st, std, generator=g), x_n, x0, n, m)
    assert_moments(mean, v, c0 * x0 + cn * x_n, var)


# --- the training label is the inverse of predict_x0 ------------------------------------------------

@pytest.mark.parametrize("process", [DDPM(steps=10), Bridge(steps=10), Bridge(steps=10, beta_max=0.3, ot_ode=True),
                                     Bridge(steps=10, consistent=True), Bridge(steps=10, predict="x0"),
                                     Bridge(steps=10, weighting="uniform"), Bridge(steps=10, predict="ddbm"),
                                     Bridge(steps=10, predict="ddbm", weighting="ddbm", sigma_01=0.2, ot_ode=True),
                                     Bridge(steps=10, predict="ddbm", consistent=True), Flow(steps=10),
                                     Flow(steps=10, sigma=0.5), Flow(steps=1, sigma=0.2)])
def test_exact_label_has_zero_loss_and_predicts_x0(process):
    """A network that outputs the exact label has zero loss and its x0 prediction is x0 at every step."""
    b, h = 64, 8
    gen = torch.Generator().manual_seed(0)
    x0 = torch.rand((b, h, 6), generator=gen, dtype=F64) * 1.8 - 0.9
    x1 = torch.randn((b, h, 6), generator=gen, dtype=F64)
    cond = {0: x0[:, 0, ACT_DIM:], h - 1: x0[:, -1, ACT_DIM:]}

    def exact_label(x0):  # from the network's input back to x_n (a preconditioned input is x_n scaled)
        return lambda x_in, n: process.training_target(x0, x_in / process.network_input(torch.ones_like(x_in),
                                                                                          n.long()), n.long())

    assert float(process.training_loss(exact_label(x0), x0, x1, cond, gen)) < 1e-28
    x_n, n, _ = process.training_pair(x0, x1, cond, gen)
    for k in n.unique().tolist():
        rows = n == k
        assert torch.allclose(process.predict_x0(exact_label(x0[rows]), x_n[rows], k), x0[rows], atol=1e-12), k
    # and at every step, for any state (the label's inverse does not depend on where x_n came from)
    for k in range(process.steps):
        x = torch.randn((b, h, 6), generator=gen, dtype=F64)
        assert torch.allclose(process.predict_x0(exact_label(x0), x, k), x0, atol=1e-12), k


# --- the consistent bridge --------------------------------------------------------------------------

def test_chain_marginal_is_the_brownian_bridge_to_the_last_step():
    """chain_marginal against conditioning the Brownian motion on (x0, x_{N-1} = x1) numerically."""
    for n_steps, beta_max in ((16, 1.0), (7, 0.3), (2, 1.0)):
        std = bridge_stds(i2sb_betas(n_steps, beta_max))[0]
        rows = brownian_rows(std.tolist())
        mu0, mu1, var = chain_marginal(std)
        for n in range(n_steps - 1):
            (c0, c1), v = regress(rows, 1 + n, [0, n_steps])
            assert close(float(mu0[n]), c0) and close(float(mu1[n]), c1) and close(float(var[n]), v), (n_steps, n)
        # the chain starts at x1 itself
        assert float(mu0[-1]) == 0 and float(mu1[-1]) == 1 and float(var[-1]) == 0
    # the symmetric schedule puts half the variance before the middle: weight 1/2 on x1 there
    assert close(float(chain_marginal(bridge_stds(i2sb_betas(16, 1.0))[0])[1][7]), 0.5)


def chain_moments(bridge: Bridge, nfe: int) -> dict[int, tuple[float, float, float]]:
    """Exact (x0 weight, x1 weight, variance) of the state the chain hands the network at each call.

    Propagated through the posterior coefficients from x = x1 (weight 1 on x1, variance 0).
    """
    w0, w1, var = 0.0, 1.0, 0.0
    std = bridge.std_fwd.tolist()
    steps = spaced_steps(bridge.steps, nfe)
    out = {}
    for n, m in zip(steps, steps[1:]):
        out[n] = (w0, w1, var)
        a, b, v = bridge_posterior(std[n], std[m])
        w0, w1, var = a + b * w0, b * w1, b * b * var + v
    return out


@pytest.mark.parametrize("n_steps, beta_max", [(16, 1.0), (16, 0.3), (5, 1.0), (1000, 0.3)])
def test_consistent_marginal_equals_the_chain_exactly(n_steps, beta_max):
    bridge = Bridge(steps=n_steps, beta_max=beta_max, consistent=True)
    mu0, mu1, var = (c.tolist() for c in bridge.marginal_coefs)
    for nfe in {1, 2, 5, n_steps - 1} & set(range(1, n_steps)):
        for n, (w0, w1, v) in chain_moments(bridge, nfe).items():
            assert close(w0, mu0[n]) and close(w1, mu1[n]) and close(v, var[n]), (nfe, n)


def test_i2sb_marginal_is_off_the_chain_at_n16():
    """The mismatch the consistent option removes: at N = 16, beta_max 1 the x1 weight at the middle
    step is 0.43 in I2SB's training marginal against 0.50 in the chain, and the variances differ."""
    bridge = Bridge(steps=16, beta_max=1.0)
    mu0, mu1, var = (c.tolist() for c in bridge.marginal_coefs)
    chain = chain_moments(bridge, 15)
    # step 7 closes the first half: std_fwd^2 = T / 2 and std_bwd^2 = T / 2 + beta_7, T the total
    total = float(bridge.std_fwd[-1] ** 2)
    assert close(mu1[7], 0.5 / (1 + float(bridge.betas[7]) / total)) and abs(mu1[7] - 0.4298) < 1e-4
    assert close(chain[7][1], 0.5)
    assert max(abs(mu1[n] - chain[n][1]) for n in chain) > 0.09
    assert max(var[n] / chain[n][2] for n in range(1, 15)) > 7  # at step 14: 7.7x


def sampled_chain(bridge: Bridge, nfe: int, x0_value: float, x1_value: float, n_samples: int):
    """The states the real sampler hands a perfect x0 predictor at each call, from fixed (x0, x1)."""
    x0 = torch.full((n_samples, 1, 1), x0_value, dtype=F64)
    std = bridge.std_fwd
    seen = {}

    def model(x_n, n):
        k = int(n[0])
        seen[k] = x_n
        return (x_n - x0) / std[k]

    bridge.sample(model, torch.full_like(x0, x1_value), {}, nfe, torch.Generator().manual_seed(3))
    return seen


def chain_matches_training(bridge: Bridge, nfe: int, n_samples: int = 20000) -> bool:
    """Whether every sampled chain state's mean and variance match the training marginal (5 standard errors)."""
    x0, x1 = 0.5, -0.8
    mu0, mu1, var = (c.tolist() for c in bridge.marginal_coefs)
    seen = sampled_chain(bridge, nfe, x0, x1, n_samples)
    assert sorted(seen, reverse=True) == spaced_steps(bridge.steps, nfe)[:-1]
    for n, x in seen.items():
        mean, v = float(x.mean()), float(x.var())
        scale = max(var[n], v)
        if abs(mean - (mu0[n] * x0 + mu1[n] * x1)) > 5 * math.sqrt(scale / n_samples) + 1e-12:
            return False
        if abs(v - var[n]) > 5 * math.sqrt(2 / n_samples) * scale + 1e-12:
            return False
    return True


@pytest.mark.parametrize("nfe", [15, 5, 1])
def test_sampled_chain_matches_the_consistent_training_marginal(nfe):
    assert chain_matches_training(Bridge(steps=16, beta_max=1.0, consistent=True), nfe)
    # the same check has the power to see I2SB's marginal off the chain
    assert not chain_matches_training(Bridge(steps=16, beta_max=1.0), nfe)


def test_consistent_ot_ode_chain_is_the_training_mean():
    """Without noise the chain is deterministic: each state equals the consistent marginal's mean."""
    for consistent, matches in ((True, True), (False, False)):
        bridge = Bridge(steps=16, beta_max=1.0, ot_ode=True, consistent=consistent)
        mu0, mu1, _ = bridge.marginal_coefs
        seen = sampled_chain(bridge, 15, 0.5, -0.8, 2)
        errs = [abs(float(x[0]) - (float(mu0[n]) * 0.5 + float(mu1[n]) * -0.8)) for n, x in seen.items()]
        assert (max(errs) < 1e-12) == matches, (consistent, max(errs))


@pytest.mark.parametrize("consistent", [False, True])
def test_training_draws_follow_the_marginal(consistent):
    """training_pair's x_n per step has the marginal's moments; the consistent one starts at x1 itself."""
    bridge = Bridge(steps=16, beta_max=1.0, consistent=consistent)
    n_samples = 160000
    x0 = torch.full((n_samples, 1, 1), 0.5, dtype=F64)
    x1 = torch.full((n_samples, 1, 1), -0.8, dtype=F64)
    x_n, n, _ = bridge.training_pair(x0, x1, {}, torch.Generator().manual_seed(4))
    mu0, mu1, var = (c.tolist() for c in bridge.marginal_coefs)
    # the chain never calls the network at step 0, so the consistent bridge does not train there
    assert sorted(n.unique().tolist()) == list(range(1 if consistent else 0, 16))
    for k in range(1, 16):
        x = x_n[n == k]
        want_mean = mu0[k] * 0.5 + mu1[k] * -0.8
        assert abs(float(x.mean()) - want_mean) < 5 * math.sqrt(var[k] / len(x)) + 1e-12, k
        assert abs(float(x.var()) - var[k]) < 5 * math.sqrt(2 / len(x)) * var[k] + 1e-12, k
    if consistent:
        assert torch.equal(x_n[n == 15], x1[n == 15])


def test_default_bridge_keeps_i2sb_marginal():
    """Existing runs keep their meaning: without ``consistent`` the marginal is I2SB's product."""
    bridge = Bridge(steps=16, beta_max=1.0)
    for got, want in zip(bridge.marginal_coefs, gaussian_product(bridge.std_fwd, bridge.std_bwd)):
        assert torch.equal(got, want)
    assert Bridge().consistent is False and Bridge().to_dict()["consistent"] is False


# --- the bridge's loss ablation (predict x weighting) ----------------------------------------------------

@pytest.mark.parametrize("predict", ["eps", "x0", "ddbm"])
@pytest.mark.parametrize("weighting", ["i2sb", "uniform", "ddbm"])
def test_bridge_loss_is_the_weighted_x0_error(predict, weighting):
    """Every variant's loss is ``mean(w(n) |x0_hat - x0|^2)`` with I2SB's ``w = 1 / std_fwd[n]^2``, 1 or DDBM's
    ``1 / c_out[n]^2``, for any network: the output is what ``predict`` says (DDBM's network given ``c_in x_n``), and
    the weighting alone sets w."""
    bridge = Bridge(steps=16, predict=predict, weighting=weighting)
    b, h = 256, 8
    x0 = torch.rand((b, h, 6), generator=torch.Generator().manual_seed(1), dtype=F64) * 1.8 - 0.9
    x1 = torch.randn((b, h, 6), generator=torch.Generator().manual_seed(2), dtype=F64)
    cond = {0: x0[:, 0, ACT_DIM:], h - 1: x0[:, -1, ACT_DIM:]}
    net = torch.nn.Linear(6, 6).double()

    def model(x, n):
        return torch.tanh(net(x)) * (1 + n[:, None, None] / 16)

    loss = bridge.training_loss(model, x0, x1, cond, torch.Generator().manual_seed(3))
    x_n, n, _ = bridge.training_pair(x0, x1, cond, torch.Generator().manual_seed(3))
    std = bridge.std_fwd.double()[n][:, None, None]
    c_in, c_skip, c_out = (c[n][:, None, None] for c in bridge.ddbm_scalings)
    if predict == "ddbm":
        x0_hat = c_skip * x_n + c_out * model(c_in * x_n, n.float())
    else:
        out = model(x_n, n.float())
        x0_hat = x_n - std * out if predict == "eps" else out
    w = {"i2sb": 1 / std ** 2, "uniform": torch.ones_like(std), "ddbm": 1 / c_out ** 2}[weighting]
    assert torch.allclose(loss, torch.mean(w * (x0_hat - x0) ** 2), rtol=1e-10)


def test_bridge_default_loss_is_unchanged():
    """I2SB's loss is the plain L2 on its label, bit for bit (runs trained before the ablation resume exactly)."""
    bridge = Bridge(steps=16)
    x0 = torch.rand((32, 8, 6), generator=torch.Generator().manual_seed(1)) * 1.8 - 0.9
    x1 = torch.randn((32, 8, 6), generator=torch.Generator().manual_seed(2))
    cond = {0: x0[:, 0, ACT_DIM:], 7: x0[:, -1, ACT_DIM:]}
    net = torch.nn.Linear(6, 6)
    loss = bridge.training_loss(lambda x, n: net(x), x0, x1, cond, torch.Generator().manual_seed(3))
    x_n, n, target = bridge.training_pair(x0, x1, cond, torch.Generator().manual_seed(3))
    assert torch.equal(loss, torch.mean((net(x_n) - target) ** 2))


@pytest.mark.parametrize("sigma_01", [0.0, 0.2])
@pytest.mark.parametrize("ot_ode", [False, True])
def test_ddbm_scalings_give_unit_variance_input_and_label(sigma_01, ot_ode):
    """DDBM's preconditioning, Monte Carlo at its assumed moments: x0 and x1 with standard deviations sigma_0 and
    sigma_1 and covariance sigma_01, x_n drawn by the bridge's own marginal; then at every step the network's input
    ``c_in x_n`` and the label have unit variance, and the label is uncorrelated with x_n (c_skip is x0's regression
    on x_n: what is left for the network is what x_n cannot tell)."""
    bridge = Bridge(steps=10, predict="ddbm", sigma_0=0.4, sigma_1=0.6, sigma_01=sigma_01, ot_ode=ot_ode)
    gen, m = torch.Generator().manual_seed(4), 200_000
    z = torch.randn((2, m), generator=gen, dtype=F64)
    rho = sigma_01 / (0.4 * 0.6)
    x0 = 0.4 * z[0]
    x1 = 0.6 * (rho * z[0] + (1 - rho ** 2) ** 0.5 * z[1])
    for k in range(bridge.steps):
        n = torch.full((m,), k)
        x_n = bridge.marginal(x0.view(m, 1, 1), x1.view(m, 1, 1), n, gen)
        net_in, label = bridge.network_input(x_n, n).ravel(), bridge.training_target(x0.view(m, 1, 1), x_n, n).ravel()
        assert abs(float(net_in.var()) - 1) < 0.02 and abs(float(label.var()) - 1) < 0.02, k
        assert abs(float(torch.corrcoef(torch.stack([label, x_n.ravel()]))[0, 1])) < 0.01, k


def test_ddbm_refuses_impossible_moments():
    for bad in ({"sigma_0": 0.0}, {"sigma_1": -1.0}, {"sigma_01": 0.25}):
        with pytest.raises(BridgeplanError, match="ddbm's moments need"):
            Bridge(predict="ddbm", **bad)


@pytest.mark.parametrize("field", ["predict", "weighting"])
def test_bridge_refuses_unknown_loss_variants(field):
    with pytest.raises(BridgeplanError, match=f"unknown {'prediction' if field == 'predict' else 'weighting'}"):
        Bridge(**{field: "v"})
