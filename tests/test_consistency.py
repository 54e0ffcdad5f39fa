"""Consistency corrections (CDDB) of the x0 predictions: residuals, both forms, samplers, CLI (tiny sizes)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from bridgeplan.cli import main
from bridgeplan.consistency import (
    POINT_MASS,
    Correction,
    corrected,
    dynamics_error,
    kinematics_error,
    residual,
)
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.unet import TemporalUNet, UNetConfig
from bridgeplan.normalizer import Normalizer
from bridgeplan.planner import Planner
from bridgeplan.priors import make_prior
from bridgeplan.processes import DDPM, Bridge, Flow
from bridgeplan.trajectory import MAZE2D, densify
from tests.test_cli_data import _error

B, H, D = 3, 8, 6
ACT_DIM = MAZE2D.act_dim
# a normalizer with ranges of Maze2D's order: actions [-1, 1], positions ~[0.5, 3.5], velocities [-5, 5]
NORM = Normalizer((-1.0, -1.0, 0.4, 0.5, -5.0, -5.0), (1.0, 1.0, 3.6, 2.5, 5.0, 5.0))


def trajectories(seed=0, dtype=torch.float64) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.rand((B, H, D), generator=gen, dtype=dtype) - 0.5


def conditions_of(x: torch.Tensor) -> dict[int, torch.Tensor]:
    """Start and goal conditions near (not at) ``x``'s own, a NaN row for one plan's goal."""
    gen = torch.Generator().manual_seed(9)
    start = x[:, 0, ACT_DIM:] + 0.2 * torch.rand(x[:, 0, ACT_DIM:].shape, generator=gen, dtype=x.dtype)
    goal = x[:, -1, ACT_DIM:] - 0.3
    goal[1] = torch.nan
    return {0: start, H - 1: goal}


# --- the physics --------------------------------------------------------------------------------------------

def test_point_mass_is_point_maze_v3():
    """The constants of the residual are those of the MuJoCo model the simulator steps."""
    import mujoco

    from bridgeplan.envs.maze2d.grids import get_maze
    from bridgeplan.envs.maze2d.sim import MAX_SPEED, point_maze_model

    model = point_maze_model(get_maze("umaze"))
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert model.opt.timestep == POINT_MASS.timestep and POINT_MASS.frame_skip == 1
    assert model.body_mass[1] == pytest.approx(POINT_MASS.mass, rel=1e-12)
    assert list(model.dof_damping) == [POINT_MASS.damping] * 2
    assert list(model.actuator_gear[:, 0]) == [POINT_MASS.gear] * 2
    assert POINT_MASS.max_speed == MAX_SPEED


def _simulate(stride: int, steps: int = 24, seed: int = 0) -> np.ndarray:
    """``[4, steps // stride + 1, 6]`` physical rows of the real simulator from the open maze's centre, random
    actions (some beyond [-1, 1], clipped by the simulator) held ``stride`` steps, starting speeds beyond the
    clip; one row every ``stride`` steps (its state, and the action applied from it)."""
    from bridgeplan.envs.maze2d.grids import get_maze
    from bridgeplan.envs.maze2d.sim import BatchedPointMaze

    rng = np.random.default_rng(seed)
    sim = BatchedPointMaze(get_maze("open"), 4)
    starts = rng.uniform(-0.3, 0.3, (4, 2))
    speeds = np.stack([rng.choice([-5.5, 5.5], 4), np.zeros(4)], axis=1)  # x beyond the clip
    obs = sim.reset(starts, starts + 1.0, velocities=speeds)
    rows = []
    for t in range(steps + 1):
        if t % stride == 0:
            action = rng.uniform(-1.3, 1.3, (4, 2))
            rows.append(np.concatenate([action, obs], axis=1))
        obs, _ = sim.step(action)
    traj = np.stack(rows, axis=1)
    xy = np.abs(traj[..., ACT_DIM:ACT_DIM + 2])
    assert xy[..., 0].max() < 2.3 and xy[..., 1].max() < 1.3  # the open maze's walls are 0.1 further: free space
    return traj


@pytest.mark.parametrize("stride", [1, 3])
def test_dynamics_residual_is_zero_on_simulated_motion_and_positive_when_perturbed(stride):
    traj = torch.as_tensor(_simulate(stride))
    assert dynamics_error(traj, MAZE2D, stride).abs().max() < 1e-10
    if stride == 1:
        assert kinematics_error(traj, MAZE2D, stride).abs().max() < 1e-10
    x0 = NORM.normalize(traj)  # through the normalizer, as a sampler's x0 is
    assert residual("dynamics", x0, NORM, MAZE2D, stride).max() < 1e-18
    for column in range(D):  # an action, a position or a velocity off by a little: a residual
        bad = x0.clone()
        bad[1, 3, column] = bad[1, 3, column] * 0.5 if column < ACT_DIM else bad[1, 3, column] + 0.01  # (clips)
        r = residual("dynamics", bad, NORM, MAZE2D, stride)
        assert r[1] > 1e-6 and r[0] < 1e-18 and r[2] < 1e-18


def test_kinematics_at_a_stride_is_the_mean_of_its_densified_steps():
    """At stride k the kinematics error of a transition is the mean of the stride-1 errors of the plan as
    densified (linear between rows, what the controller tracks): positions integrate the velocities there."""
    k = 4
    x = NORM.unnormalize(trajectories(1))
    dense = torch.as_tensor(densify(x.numpy(), k))
    per_step = kinematics_error(dense, MAZE2D, 1)
    assert torch.allclose(kinematics_error(x, MAZE2D, k), per_step.reshape(B, H - 1, k, 2).mean(2), atol=1e-10)


# --- the correction on closed forms --------------------------------------------------------------------------

def test_x0_step_on_the_conditions_residual_shrinks_it_by_one_minus_alpha_squared():
    """Unit-scale normalizer: R = 1/2 |x - c|^2 on the conditioned states, so x <- x - alpha (x - c) leaves
    (1 - alpha)^2 R; the NaN row stays out of it; the free entries do not move."""
    unit = Normalizer((-1.0,) * D, (1.0,) * D)
    x = trajectories(2)
    cond = conditions_of(x)
    before = residual("conditions", x, unit, MAZE2D, 1, cond)
    for alpha in (0.25, 0.6):
        out = corrected(lambda x_n, n: x_n, lambda z: alpha * residual("conditions", z, unit, MAZE2D, 1, cond),
                        "x0")(x, 0)
        after = residual("conditions", out, unit, MAZE2D, 1, cond)
        assert torch.allclose(after, (1 - alpha) ** 2 * before, rtol=1e-12)
        assert torch.equal(out[1, -1], x[1, -1])  # the NaN goal row of plan 1
        assert torch.equal(out[:, 1:-1], x[:, 1:-1]) and torch.equal(out[:, :, :ACT_DIM], x[:, :, :ACT_DIM])


@pytest.mark.parametrize("name, stride", [("kinematics", 1), ("kinematics", 3), ("dynamics", 1), ("dynamics", 3)])
def test_x0_step_decreases_a_quadratic_residual_by_the_expected_amount(name, stride):
    """Away from the clips each residual is R = 1/2 |J x - y|^2 (J through the normalizer): a step
    x' = x - alpha g, g = J^T (J x - y), gives exactly R(x') = R(x) - alpha |g|^2 + alpha^2 / 2 |J g|^2."""
    x = trajectories(3) * 0.6  # velocities within the clip
    z = x.clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(residual(name, z, NORM, MAZE2D, stride).sum(), z)
    alpha = 0.05 / float(grad.abs().max())  # a step that stays inside [-1, 1] (no clip)
    out = corrected(lambda x_n, n: x_n, lambda z: alpha * residual(name, z, NORM, MAZE2D, stride), "x0")(x, 0)
    assert out.abs().max() < 1
    g = (x - out) / alpha
    err = {"kinematics": kinematics_error, "dynamics": dynamics_error}[name]
    _, jg = torch.autograd.functional.jvp(lambda z: err(NORM.unnormalize(z), MAZE2D, stride), x, g)
    before, after = residual(name, x, NORM, MAZE2D, stride), residual(name, out, NORM, MAZE2D, stride)
    expected = before - alpha * g.pow(2).flatten(1).sum(1) + alpha ** 2 / 2 * jg.pow(2).flatten(1).sum(1)
    assert torch.allclose(after, expected, rtol=1e-10, atol=1e-12)
    assert (after < before).all()


def _tiny_net(seed=0) -> TemporalUNet:
    torch.manual_seed(seed)
    return TemporalUNet.from_config(UNetConfig(dim=8, dim_mults=(1, 2)), D, horizon=H).eval()


class TinyNet(torch.nn.Module):
    """Two temporal convolutions and a time input: a network that runs in float64 (the U-Net's time embedding
    is float32)."""

    def __init__(self):
        super().__init__()
        torch.manual_seed(1)
        self.inner, self.outer = torch.nn.Conv1d(D, 16, 3, padding=1), torch.nn.Conv1d(16, D, 3, padding=1)
        self.time = torch.nn.Linear(1, 16)

    def forward(self, x, t):
        h = torch.tanh(self.inner(x.transpose(1, 2)) + self.time(t[:, None].to(x.dtype) / 6)[:, :, None])
        return 0.3 * self.outer(h).transpose(1, 2)


@pytest.mark.parametrize("process, n", [(Bridge(steps=6), 2), (DDPM(steps=6), 3), (Flow(steps=6), 4)])
def test_deep_gradient_through_the_network_matches_finite_differences(process, n):
    """The deep form moves x0_hat by alpha grad_{x_n} R(x0_hat(x_n)): check it against central differences of
    R(predict_x0(x_n)) along coordinates and a random direction (float64 tiny U-Net)."""
    model = TinyNet().double()
    x_n = trajectories(4) * 0.6
    cond = conditions_of(x_n)

    def objective(z):
        return residual("dynamics", z, NORM, MAZE2D, 2) + 0.5 * residual("conditions", z, NORM, MAZE2D, 2, cond)

    def predict(z, step):
        return process.predict_x0(model, z, step)

    x0 = predict(x_n, n)
    assert x0.abs().max() < 0.999  # no clipped entry: the prediction is differentiable everywhere
    alpha = 1e-6
    out = corrected(predict, lambda z: alpha * objective(z), "deep")(x_n, n)
    grad = (x0 - out) / alpha
    with torch.no_grad():
        def total(z):
            return objective(predict(z, n)).sum()

        eps = 1e-6
        gen = torch.Generator().manual_seed(5)
        direction = torch.randn(x_n.shape, generator=gen, dtype=x_n.dtype)
        probes = [direction] + [torch.zeros_like(x_n).index_put_((torch.tensor(b), torch.tensor(t), torch.tensor(d)),
                                                                   torch.tensor(1.0, dtype=x_n.dtype))
                                for b, t, d in [(0, 0, 2), (1, 3, 0), (2, 5, 4), (0, 7, 5), (1, 2, 3)]]
        for v in probes:
            fd = (total(x_n + eps * v) - total(x_n - eps * v)) / (2 * eps)
            assert float((grad * v).sum()) == pytest.approx(float(fd), rel=1e-5, abs=1e-7)
    # through the network, not in x0 space: the x0 form's gradient differs
    x0_form = (x0 - corrected(predict, lambda z: alpha * objective(z), "x0")(x_n, n)) / alpha
    assert not torch.allclose(grad, x0_form, rtol=1e-3)


# --- every process: zero step is the sampler itself --------------------------------------------------------

PROCESSES = [DDPM(steps=6), DDPM(steps=6, sampler="ddim", eta=0.5), Bridge(steps=6), Bridge(steps=6, sampler="mean"),
             Bridge(steps=6, consistent=True), Flow(steps=6), Flow(steps=6, sigma=0.3, sampler="stochastic")]


def _planner(process, correction=None) -> Planner:
    prior = make_prior("gaussian" if not process.uses_prior else "line", NORM, MAZE2D, stride=2)
    return Planner(_tiny_net(), process, prior, NORM, H, torch.device("cpu"), MAZE2D, stride=2, correction=correction)


def _plan(planner: Planner):
    starts = np.array([[1.0, 1.0, 0.0, 0.0], [2.0, 1.5, 0.5, -0.5], [3.0, 2.0, 0.0, 0.0]])
    goals = np.array([[3.0, 2.0], [1.0, 1.0], [2.0, 1.0]])
    return planner.plan(starts, goals, 3, torch.Generator().manual_seed(11))


@pytest.mark.parametrize("process", PROCESSES, ids=lambda p: f"{p.name}-{p.sampling_tag() or 'default'}")
@pytest.mark.parametrize("form", ["x0", "deep"])
def test_zero_step_is_exactly_the_uncorrected_sampler(process, form):
    plain = _plan(_planner(process))
    names = ("dynamics", "kinematics") + (("conditions",) if form == "deep" else ())
    zero = _plan(_planner(process, Correction(tuple((name, 0.0) for name in names), form)))
    assert np.array_equal(plain.states, zero.states) and np.array_equal(plain.actions, zero.actions)
    moved = _plan(_planner(process, Correction((("dynamics", 1e-3),), form)))  # the correction is applied at all
    assert not np.allclose(plain.states, moved.states)


@pytest.mark.parametrize("form", ["x0", "deep"])
def test_a_small_dynamics_step_lowers_the_plans_dynamics_residual(form):
    """Through the planner (an untrained network, NFE 3): a small step gives plans of a smaller dynamics residual.
    (The position part, divided by k h, makes R stiff: here steps from about 1e-3 on overshoot.)"""
    planner = _planner(Bridge(steps=6))
    plain = _plan(planner)
    fixed = _plan(_planner(Bridge(steps=6), Correction((("dynamics", 1e-5),), form)))
    assert (planner.residuals(fixed)["dynamics_rms"] < planner.residuals(plain)["dynamics_rms"]).all()


def test_a_process_that_does_not_predict_x0_refuses_a_correction():
    @dataclasses.dataclass(frozen=True)
    class NoX0(DDPM):
        predicts_x0 = False

    with pytest.raises(BridgeplanError, match="does not sample through them"):
        _planner(NoX0(steps=6)).with_correction(Correction((("dynamics", 0.1),)))


@pytest.mark.parametrize("steps, form, message", [
    ((("smoothness", 0.1),), "x0", "unknown residual 'smoothness'"),
    ((("dynamics", -1.0),), "deep", "must be a finite number >= 0"),
    ((), "x0", "needs at least one residual"),
    ((("conditions", 0.1),), "x0", "use --correction-form deep"),
])
def test_a_correction_is_checked_when_it_is_made(steps, form, message):
    """Before any run is loaded or plan sampled."""
    with pytest.raises(BridgeplanError, match=message):
        Correction(steps, form)


def test_correction_costs_and_tags():
    deep, cheap = Correction((("kinematics", 1e-3), ("dynamics", 0.01)), "deep"), Correction((("dynamics", 0.01),))
    assert deep.tag() == "cddb-deep dynamics=0.01 kinematics=0.001"
    assert deep.file_tag() == "cddb-deep-dynamics0.01-kinematics0.001"
    assert deep.to_dict(4) | {"tag": ""} == {"form": "deep", "steps": {"dynamics": 0.01, "kinematics": 0.001},
                                             "tag": "", "forward_passes_per_plan": 4, "backward_passes_per_plan": 4,
                                             "network_call_equivalents_per_plan": 12}
    assert cheap.network_call_equivalents(2) == 2 and cheap.backward_passes(2) == 0


def test_a_series_keys_its_rows_by_the_sampler_and_the_correction():
    """``Series.sampling_tag`` (the runner's "missing" key) is the store's ``sampler`` that evaluations write."""
    from bridgeplan.consistency import sampling_tag
    from bridgeplan.experiments.grids import RunSpec, Series

    cheap = Correction((("dynamics", 1e-4),))
    assert sampling_tag("", None) == "" and sampling_tag("mean", cheap) == "mean cddb-x0 dynamics=0.0001"
    run = RunSpec(DDPM(6))
    assert Series("plain", run, 2).sampling_tag() == ""
    assert Series("c", run, 2, correction=cheap).sampling_tag() == "cddb-x0 dynamics=0.0001"
    assert Series("s c", run, 2, sampler="ddim", correction=cheap).sampling_tag() == "ddim cddb-x0 dynamics=0.0001"


# --- CLI --------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad, message", [
    (["--correction", "dynamics=-0.1"], "step size of the dynamics correction must be a finite number >= 0"),
    (["--correction", "dynamics=nan"], "must be a finite number >= 0"),
    (["--correction", "smoothness=0.1"], "unknown residual 'smoothness': choose from conditions, kinematics, dynamics"),
    (["--correction", "dynamics"], "--correction takes RESIDUAL=STEP"),
    (["--correction", "dynamics=fast"], "the step size must be a number"),
    (["--correction", "dynamics=0.1", "--correction", "dynamics=0.2"], "each residual takes one step size"),
    (["--correction", "dynamics=0.1", "--correction-form", "dps"], "unknown correction form 'dps'"),
    (["--correction", "conditions=0.1"], "use --correction-form deep"),
    (["--correction-form", "deep"], "--correction-form needs --correction"),
])
def test_eval_bad_correction(tiny_runs, capsys, bad, message):
    line = _error(capsys, ["eval", str(tiny_runs["bridge"]), "--device", "cpu", "--episodes", "2", *bad])
    assert message in line


def test_eval_with_a_correction_records_it_and_its_cost(tiny_runs, tmp_path, capsys):
    out = tmp_path / "deep.json"
    assert main(["eval", str(tiny_runs["bridge"]), "--episodes", "4", "--nfe", "2", "--device", "cpu",
                 "--correction", "dynamics=0.001", "--correction", "conditions=0.01", "--correction-form", "deep",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "correction:                cddb-deep conditions=0.01 dynamics=0.001: 6 network-call equivalents" in printed
    result = json.loads(out.read_text())
    assert result["nfe"] == 2 and result["network_call_equivalents_per_plan"] == 6
    assert result["correction"] == {"form": "deep", "steps": {"conditions": 0.01, "dynamics": 0.001},
                                    "tag": "cddb-deep conditions=0.01 dynamics=0.001", "forward_passes_per_plan": 2,
                                    "backward_passes_per_plan": 2, "network_call_equivalents_per_plan": 6}
    assert result["plan_ms_per_plan"] > 0
    assert {"kinematics_rms", "dynamics_rms"} <= set(result["plan_residuals"])
    assert main(["eval", str(tiny_runs["bridge"]), "--episodes", "4", "--nfe", "2", "--device", "cpu",
                 "--out", str(tmp_path / "plain.json")]) == 0
    plain = json.loads((tmp_path / "plain.json").read_text())
    assert plain["correction"] is None and plain["network_call_equivalents_per_plan"] == 2
    assert plain["plan_residuals"]["dynamics_rms"]["mean"] > 0


def test_a_store_row_records_the_plans_cost_and_residuals(tiny_runs):
    """The store keeps what a correction costs (network-call equivalents per plan) and what it does to the
    plans (their rms residuals), beside the score: the reports read them from the committed rows."""
    from bridgeplan.evaluate import evaluate_run
    from bridgeplan.experiments.store import row_from_eval_json

    deep = Correction((("dynamics", 1e-3),), form="deep")
    rows = {c: row_from_eval_json(evaluate_run(tiny_runs["bridge"], episodes=4, nfe=2, device="cpu",
                                               correction=c).to_dict()) for c in (None, deep)}
    assert rows[None]["network_calls_per_plan"] == 2 and rows[deep]["network_calls_per_plan"] == 6
    for row in rows.values():
        assert row["plan_kinematics_rms"] > 0 and row["plan_dynamics_rms"] > 0
    assert rows[deep]["sampler"].endswith("cddb-deep dynamics=0.001")
