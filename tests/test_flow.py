"""The flow process (flow matching / stochastic interpolants from the prior) against closed forms, and
through the real CLI on the tiny dataset."""

from __future__ import annotations

import json
import math

import pytest
import torch

from bridgeplan.cli import main
from bridgeplan.errors import BridgeplanError
from bridgeplan.processes import Flow, make_process, parse_process_params, process_from_dict
from bridgeplan.processes.flow import flow_posterior, flow_sample, flow_time, linear_interpolant
from bridgeplan.trajectory import MAZE2D
from tests.test_process_maths import close, regress
from tests.test_train import train_args

F64 = torch.float64
B, H, D = 5, 8, 6

ACT_DIM = MAZE2D.act_dim


def data(seed=0) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.rand((B, H, D), generator=gen, dtype=F64) * 1.8 - 0.9


def conditions_for(x0: torch.Tensor) -> dict[int, torch.Tensor]:
    return {0: x0[:, 0, ACT_DIM:], H - 1: x0[:, -1, ACT_DIM:]}


def oracle(x0: torch.Tensor):
    """A network that sees the truth: it outputs x0 (the flow's label)."""
    return lambda x_t, n: x0


# --- the path, against a Brownian bridge built independently ---------------------------------------

def bridge_rows(times: list[float], sigma: float) -> list[list[float]]:
    """Rows over ``z = (x0, x1, e_1..e_K)`` of ``(x0, x1, x_u for u in times, increasing)``.

    x_u = (1 - u) x0 + u x1 + sigma (W_u - u W_1), W a Brownian motion built from independent
    increments e_k over [0, times..., 1].
    """
    grid = list(times) + ([1.0] if times[-1] < 1 else [])
    incs = [grid[0]] + [grid[k] - grid[k - 1] for k in range(1, len(grid))]
    width = 2 + len(grid)

    def w(k):  # W at grid[k]: the first k + 1 increments
        return [incs[j] ** 0.5 if j <= k else 0.0 for j in range(len(grid))]

    w1 = w(len(grid) - 1)
    rows = [[1.0] + [0.0] * (width - 1), [0.0, 1.0] + [0.0] * (width - 2)]
    for k, u in enumerate(times):
        noise = [sigma * (a - u * b) for a, b in zip(w(k), w1)]
        rows.append([1 - u, u] + noise)
    return rows


@pytest.mark.parametrize("sigma", [0.3, 1.0])
def test_path_marginal_and_posterior_are_the_brownian_bridge(sigma):
    """linear_interpolant's (a, b, g) and flow_posterior's coefficients against conditioning the joint
    Gaussian of (x0, x1, x_s, x_t): the posterior puts no weight on x1 (the bridge is Markov)."""
    for t in (0.2, 0.5, 0.9):
        a, b, g = linear_interpolant(t, sigma)
        (c0, c1), var = regress(bridge_rows([t], sigma), 2, [0, 1])
        assert close(a, c0) and close(b, c1) and close(g ** 2, var), t
        for s in (0.05, t / 2, t - 0.01):
            (c0, c1, ct), var = regress(bridge_rows([s, t], sigma), 2, [0, 1, 3])
            coef_x0, coef_xt, v = flow_posterior(t, s, sigma)
            assert close(c1, 0.0) and close(coef_x0, c0) and close(coef_xt, ct) and close(v, var), (t, s)
    # the noise vanishes at both ends
    assert linear_interpolant(0.0, sigma) == (1.0, 0.0, 0.0) and linear_interpolant(1.0, sigma) == (0.0, 1.0, 0.0)
    # from t = 1 (x_t = x1) the posterior mean is the path's mean and its variance the path's
    for s in (0.1, 0.5):
        coef_x0, coef_xt, v = flow_posterior(1.0, s, sigma)
        a, b, g = linear_interpolant(s, sigma)
        assert close(coef_x0, a) and close(coef_xt, b) and close(v, g ** 2)


@pytest.mark.parametrize("sigma", [0.0, 0.4])
def test_training_draws_follow_the_path(sigma):
    """training_pair's x_t per step: mean (1 - t) x0 + t x1, variance sigma(t)^2; x1 itself at t = 1."""
    flow = Flow(steps=8, sigma=sigma)
    n_samples = 160000
    x0 = torch.full((n_samples, 1, 1), 0.5, dtype=F64)
    x1 = torch.full((n_samples, 1, 1), -0.8, dtype=F64)
    x_t, n, target = flow.training_pair(x0, x1, {}, torch.Generator().manual_seed(4))
    assert torch.equal(target, x0)
    assert sorted(n.unique().tolist()) == list(range(8))
    for k in range(8):
        x, t = x_t[n == k], (k + 1) / 8
        want_mean, want_var = (1 - t) * 0.5 + t * -0.8, sigma ** 2 * t * (1 - t)
        if sigma == 0:
            assert torch.allclose(x, torch.full_like(x, want_mean), atol=1e-12), k
            continue
        assert abs(float(x.mean()) - want_mean) < 5 * math.sqrt(want_var / len(x)) + 1e-12, k
        assert abs(float(x.var()) - want_var) < 5 * math.sqrt(2 / len(x)) * want_var + 1e-12, k
    assert torch.equal(x_t[n == 7], x1[n == 7])


# --- the samplers ------------------------------------------------------------------------------------

def test_sample_steps():
    assert Flow(steps=16).sample_steps(1) == [15]
    assert Flow(steps=16).sample_steps(16) == list(range(15, -1, -1))
    assert Flow(steps=16).sample_steps(4) == [15, 11, 7, 3]
    for nfe in range(1, 17):
        steps = Flow(steps=16).sample_steps(nfe)
        assert len(steps) == nfe and steps[0] == 15 and steps == sorted(set(steps), reverse=True)


@pytest.mark.parametrize("process", [Flow(steps=10), Flow(steps=10, sigma=0.5),
                                     Flow(steps=10, sigma=0.5, sampler="stochastic"),
                                     Flow(steps=1, sigma=0.5, sampler="stochastic")])
def test_oracle_returns_data_exactly_at_every_nfe(process):
    x0 = data()
    cond = conditions_for(x0)
    gen = torch.Generator().manual_seed(1)
    for nfe in range(1, process.max_nfe + 1):
        x_start = torch.randn((B, H, D), generator=gen, dtype=F64)
        out = process.sample(oracle(x0), x_start, cond, nfe, generator=gen)
        assert torch.allclose(out, x0, atol=1e-12), (process, nfe)


def test_euler_without_noise_walks_the_straight_line():
    """sigma = 0: a perfect predictor's Euler chain stays on x_t = (1 - t) x0 + t x1 with the velocity x1 - x0."""
    flow = Flow(steps=12)
    x0, x1 = data(0), data(1)
    seen = []

    def model(x_t, n):
        t = flow_time(int(n[0]), 12)
        seen.append((t, x_t))
        return x0

    flow.sample(model, x1, {}, 5)
    assert [round(t * 12) for t, _ in seen] == [12, 10, 7, 5, 2]
    for t, x_t in seen:
        assert torch.allclose(x_t, (1 - t) * x0 + t * x1, atol=1e-12)
        assert torch.allclose((x_t - x0) / t, x1 - x0, atol=1e-12)


def chain_states(process: Flow, nfe: int, x0_value: float, x1_value: float, n_samples: int) -> dict:
    """The states the real sampler hands a perfect predictor at each call, from the prior sample x1."""
    x0 = torch.full((n_samples, 1, 1), x0_value, dtype=F64)
    seen = {}

    def model(x_t, n):
        seen[int(n[0])] = x_t
        return x0

    process.sample(model, torch.full_like(x0, x1_value), {}, nfe, torch.Generator().manual_seed(3))
    return seen


@pytest.mark.parametrize("nfe", [10, 4, 2])
def test_stochastic_chain_keeps_the_path_marginal(nfe):
    """From x1 the stochastic sampler hands the network x_s with the path's moments at every call."""
    flow = Flow(steps=10, sigma=0.6, sampler="stochastic")
    n_samples, x0, x1 = 20000, 0.5, -0.8
    seen = chain_states(flow, nfe, x0, x1, n_samples)
    assert sorted(seen, reverse=True) == flow.sample_steps(nfe)
    for n, x in seen.items():
        a, b, g = linear_interpolant(flow_time(n, 10), 0.6)
        if n == 9:
            assert torch.equal(x, torch.full_like(x, x1))
            continue
        assert abs(float(x.mean()) - (a * x0 + b * x1)) < 5 * g / math.sqrt(n_samples), n
        assert abs(float(x.var()) - g ** 2) < 5 * math.sqrt(2 / n_samples) * g ** 2, n
    # euler on the same model hands over the path's mean itself, without its spread
    euler = chain_states(Flow(steps=10, sigma=0.6), nfe, x0, x1, 2)
    for n, x in euler.items():
        a, b, _ = linear_interpolant(flow_time(n, 10), 0.6)
        assert torch.allclose(x, torch.full_like(x, a * x0 + b * x1), atol=1e-12), n


def test_stochastic_single_step_has_the_bridge_moments():
    """One step t -> s of the sampler itself, Monte Carlo: from a fixed x_t the moments of the Gaussian
    conditional of x_s on (x0, x_t); from x_t drawn on the path the path's marginal at s."""
    sigma, n_steps, nt, ns = 0.7, 10, 7, 2
    t, s = flow_time(nt, n_steps), flow_time(ns, n_steps)
    n_samples, x0_value, x1_value = 40000, 0.6, -0.5
    x0 = torch.full((n_samples, 1, 1), x0_value, dtype=F64)
    gen = torch.Generator().manual_seed(11)

    def one_step(x_t):
        seen = {}

        def predict(x, k):
            seen[k] = x
            return x0

        flow_sample(predict, x_t, {}, [nt, ns, 0], n_steps, sigma, True, gen)
        return float(seen[ns].mean()), float(seen[ns].var())

    def check(mean, var, want_mean, want_var):
        assert abs(mean - want_mean) < 5 * math.sqrt(want_var / n_samples), (mean, want_mean)
        assert abs(var - want_var) < 5 * math.sqrt(2 / n_samples) * want_var, (var, want_var)

    (c0, c1, ct), v = regress(bridge_rows([s, t], sigma), 2, [0, 1, 3])
    x_t_value = -0.3
    check(*one_step(torch.full_like(x0, x_t_value)), c0 * x0_value + c1 * x1_value + ct * x_t_value, v)
    path = Flow(steps=n_steps, sigma=sigma)
    x_t = path.interpolate(x0, torch.full_like(x0, x1_value), torch.full((n_samples,), nt), gen)
    a, b, g = linear_interpolant(s, sigma)
    check(*one_step(x_t), a * x0_value + b * x1_value, g ** 2)


@pytest.mark.parametrize("process", [Flow(steps=6), Flow(steps=6, sigma=0.5, sampler="stochastic")])
def test_conditions_hold_in_every_sample(process):
    x0 = data()
    cond = conditions_for(x0)
    gen = torch.Generator().manual_seed(0)

    def model(x, n):  # an untrained, arbitrary network
        return torch.tanh(3 * x + n[:, None, None])

    for nfe in (1, 3, process.max_nfe):
        out = process.sample(model, torch.randn((B, H, D), generator=gen, dtype=F64), cond, nfe, gen)
        assert torch.equal(out[:, 0, ACT_DIM:], cond[0]) and torch.equal(out[:, -1, ACT_DIM:], cond[H - 1])


# --- the process as a config -------------------------------------------------------------------------

@pytest.mark.parametrize("process", [Flow(), Flow(steps=8, sigma=0.25, sampler="stochastic")])
def test_round_trip_through_dicts(process):
    d = json.loads(json.dumps(process.to_dict()))
    assert d["name"] == "flow"
    assert process_from_dict(d) == process
    assert make_process("flow", **{k: v for k, v in d.items() if k != "name"}) == process


def test_label_run_tag_and_with_sampler():
    assert Flow().label("line") == "flow (line)"
    assert Flow(sigma=0.1, sampler="stochastic").label("learned") == "flow (learned; sigma=0.1)"
    assert Flow(steps=16, sigma=0.1).run_tag("line") == ["flow", "line", "N16", "sigma0.1"]
    assert Flow(steps=16, sampler="euler").run_tag("gaussian") == ["flow", "gaussian", "N16"]
    trained = Flow(steps=8, sigma=0.3)
    other = trained.with_sampler("stochastic")
    assert other == Flow(steps=8, sigma=0.3, sampler="stochastic") and trained.sampler == "euler"
    assert other.run_tag("line") == trained.run_tag("line")  # the sampler does not change what was trained
    assert Flow.uses_prior and Flow.samplers == ("euler", "stochastic") and Flow.sampling_fields == ("sampler",)
    assert Flow(sigma=0.1).usable_samplers() == ("euler", "stochastic") and Flow().usable_samplers() == ("euler",)
    assert parse_process_params("flow", ["sigma=0.1", "path=linear", "sampler=stochastic", "steps=8"]) == \
        {"sigma": 0.1, "path": "linear", "sampler": "stochastic", "steps": 8}


@pytest.mark.parametrize("make, message", [
    (lambda: Flow(steps=0), "steps must be >= 1"),
    (lambda: Flow(sigma=-0.1), "sigma must be a finite number >= 0"),
    (lambda: Flow(sigma=float("nan")), "sigma must be a finite number >= 0"),
    (lambda: Flow(path="trig"), "unknown flow path 'trig'"),
    (lambda: Flow(sampler="ddim"), "unknown sampler 'ddim'"),
    (lambda: Flow(sampler="stochastic"), "sigma=0"),
    (lambda: Flow(sigma=0.3).with_sampler("heun"), "unknown sampler 'heun'"),
    (lambda: Flow(sigma=0.3).with_sampler("stochastic", eta=0.5), "no eta"),
    (lambda: Flow(steps=8).validate_nfe(0), "nfe must be in 1..8"),
    (lambda: Flow(steps=8).validate_nfe(9), "nfe must be in 1..8"),
    (lambda: Flow(steps=8).sample_steps(9), "nfe must be in 1..8"),
    (lambda: make_process("flow", beta_max=0.3), "bad parameters"),
    (lambda: parse_process_params("flow", ["sigma=much"]), "sigma takes a float"),
])
def test_bad_input(make, message):
    with pytest.raises(BridgeplanError, match=message) as e:
        make()
    assert "\n" not in str(e.value)
    Flow(steps=8).validate_nfe(8)
    assert Flow(steps=8).max_nfe == 8


# --- through the CLI ---------------------------------------------------------------------------------

def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:"), err
    return err[0]


@pytest.mark.parametrize("bad, message", [
    (["--process-param", "sigma=-1"], "sigma must be a finite number >= 0"),
    (["--process-param", "sigma=lots"], "sigma takes a float"),
    (["--process-param", "path=trig"], "unknown flow path"),
    (["--process-param", "sampler=heun"], "unknown sampler"),
    (["--process-param", "sampler=stochastic"], "sigma=0"),
    (["--process-param", "beta_max=0.3"], "field of flow"),
    (["--diffusion-steps", "0"], "flow steps must be >= 1"),
])
def test_train_bad_input(tiny_dataset, tmp_path, capsys, bad, message):
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2, "--process", "flow", "--prior", "line", *bad)) == 2
    assert message in one_error_line(capsys)
    assert not (run / "checkpoint.pt").exists()


@pytest.fixture(scope="module")
def flow_run(tiny_dataset, tmp_path_factory):
    """A flow run from the line prior with path noise (horizon 32, 6 times, 3 optimizer steps)."""
    run = tmp_path_factory.mktemp("flow") / "run"
    assert main(train_args(tiny_dataset, run, 3, "--process", "flow", "--prior", "line",
                           "--process-param", "sigma=0.2")) == 0
    return run


def test_train_and_eval_through_the_cli(flow_run, tmp_path, capsys):
    saved = json.loads((flow_run / "config.json").read_text())["config"]
    assert saved["process"] == {"name": "flow", "steps": 6, "sigma": 0.2, "path": "linear", "sampler": "euler"}
    assert saved["prior"] == "line"
    for extra, nfe in (["--nfe", "1"], 1), (["--nfe", "2", "--sampler", "stochastic"], 2), ([], 6):
        out = tmp_path / f"result{nfe}.json"
        assert main(["eval", str(flow_run), "--episodes", "4", "--device", "cpu", "--out", str(out), "--json",
                     *extra]) == 0
        result = json.loads(capsys.readouterr().out)
        assert result["process"] == "flow" and result["prior"] == "line" and result["nfe"] == nfe
        assert result["process_params"]["sigma"] == 0.2
        assert result["process_params"]["sampler"] == ("stochastic" if "--sampler" in extra else "euler")
        assert result["method"] == "flow (line; sigma=0.2)"
        assert math.isfinite(result["score"]["minari"]["mean"])


@pytest.mark.parametrize("bad, message", [
    (["--nfe", "0"], "nfe must be in 1..6"),
    (["--nfe", "7"], "nfe must be in 1..6"),
    (["--sampler", "ddim"], "unknown sampler"),
    (["--sampler", "stochastic", "--eta", "0.5"], "no eta"),
])
def test_eval_bad_input(flow_run, capsys, bad, message):
    assert main(["eval", str(flow_run), "--episodes", "2", "--device", "cpu", *bad]) == 2
    assert message in one_error_line(capsys)
