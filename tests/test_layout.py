"""The trajectory layout as the environment's: Maze2D's columns as ever, and a kinematic point (OGBench pointmaze:
state (x, y), actions position steps) end to end through the pieces that need no environment."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bridgeplan.consistency import KinematicPoint, dynamics_error, kinematics_error, plan_residuals, residual
from bridgeplan.data.stream import Stream
from bridgeplan.data.windows import WindowDataset, hold_tails
from bridgeplan.envs import family_of
from bridgeplan.errors import BridgeplanError
from bridgeplan.nets.prior_mlp import PriorMLP
from bridgeplan.nets.unet import TemporalUNet
from bridgeplan.normalizer import Normalizer
from bridgeplan.planner import Planner
from bridgeplan.priors import GaussianPrior, LearnedPrior, LinePrior, WarmPrior, make_prior, train_prior_loss
from bridgeplan.processes import DDPM, Bridge, Flow
from bridgeplan.replan import arrival_index, truncate_at_arrival
from bridgeplan.trajectory import KINEMATIC_POINT, MAZE2D, apply_conditions, densify, window_conditions

POINT = KINEMATIC_POINT
B, H = 3, 8
# the kinematic point's columns (ax, ay, x, y), limits wide enough for the positions used here
NORM = Normalizer((-1.0, -1.0, -2.0, -3.0), (1.0, 1.0, 2.0, 3.0))
GAIN = 0.2  # OGBench pointmaze's, as its environment would give it


def _conditions(starts: np.ndarray, goals: np.ndarray, horizon: int = H) -> dict[int, torch.Tensor]:
    norm = lambda s: torch.as_tensor(NORM.normalize(s, POINT.state_columns), dtype=torch.float32)  # noqa: E731
    return {0: norm(starts), horizon - 1: norm(goals)}


STARTS = np.array([[-1.5, -2.0], [0.0, 0.5], [1.0, 1.0]])
GOALS = np.array([[1.5, 2.0], [-1.0, 0.5], [1.0, 1.0]])  # the last: start == goal


def test_layouts_name_their_columns():
    assert (MAZE2D.act_dim, MAZE2D.obs_dim, MAZE2D.transition_dim) == (2, 4, 6)
    assert (POINT.act_dim, POINT.obs_dim, POINT.transition_dim) == (2, 2, 4)
    x = np.arange(6.0)[None]  # Diffuser's (ax, ay, x, y, vx, vy)
    assert MAZE2D.actions(x).tolist() == [[0, 1]] and MAZE2D.positions(x).tolist() == [[2, 3]]
    assert MAZE2D.velocities(x).tolist() == [[4, 5]] and MAZE2D.states(x).tolist() == [[2, 3, 4, 5]]
    t = torch.arange(4.0)[None]
    assert POINT.positions(t).tolist() == [[2, 3]] and POINT.states(t).tolist() == [[2, 3]]
    assert not POINT.has_velocity and MAZE2D.has_velocity
    with pytest.raises(BridgeplanError, match="kinematic point layout has no velocity"):
        POINT.velocities(t)
    np.testing.assert_array_equal(MAZE2D.at_rest(np.array([[1.0, 2.0]])), [[1.0, 2.0, 0.0, 0.0]])
    np.testing.assert_array_equal(POINT.at_rest(np.array([[1.0, 2.0]])), [[1.0, 2.0]])
    views = np.zeros((2, 6))
    MAZE2D.positions(views)[...] = 7.0  # the accessors are views: they write the trajectory
    assert views[:, 2:4].tolist() == [[7, 7], [7, 7]] and not views[:, [0, 1, 4, 5]].any()


@pytest.mark.parametrize("name, layout", [("umaze", MAZE2D), ("large", MAZE2D), ("open", MAZE2D),
                                          ("pointmaze-medium-navigate-v0", POINT),
                                          ("pointmaze-giant-stitch-v0", POINT)])
def test_the_family_names_the_environments_layout(name, layout):
    assert family_of(name).layout(name) is layout


@pytest.mark.parametrize("name", ["", "antmaze-medium-navigate-v0", "Umaze", "pointmaze"])
def test_no_family_owns_an_unknown_environment(name):
    with pytest.raises(BridgeplanError, match="unknown environment") as e:
        family_of(name)
    assert "umaze" in str(e.value) and "pointmaze-" in str(e.value)


def test_a_unet_and_a_prior_net_of_the_kinematic_point():
    net = TemporalUNet(POINT.transition_dim, dim=8, dim_mults=(1, 2), horizon=H)
    x = torch.randn(B, H, 4)
    assert net(x, torch.zeros(B)).shape == (B, H, 4)
    prior_net = PriorMLP(POINT.obs_dim, H, POINT.transition_dim)
    x0 = torch.rand(B, H, 4) * 2 - 1
    assert LearnedPrior(prior_net).sample(window_conditions(x0, POINT), H, B).shape == (B, H, 4)
    assert torch.isfinite(train_prior_loss(prior_net, x0, POINT))


def test_gaussian_and_line_priors_of_the_kinematic_point():
    cond = _conditions(STARTS, GOALS)
    for prior in (GaussianPrior(POINT), LinePrior(NORM, POINT, stride=3), make_prior("line", NORM, POINT)):
        x = prior.sample(cond, H, B, torch.Generator().manual_seed(0))
        assert x.shape == (B, H, 4)
        assert torch.equal(x[:, 0, 2:], cond[0]) and torch.equal(x[:, -1, 2:], cond[H - 1])
    traj = NORM.unnormalize(LinePrior(NORM, POINT).sample(cond, H, B).double())
    frac = torch.linspace(0, 1, H, dtype=torch.float64)[None, :, None]
    start, goal = torch.as_tensor(STARTS)[:, None], torch.as_tensor(GOALS)[:, None]
    torch.testing.assert_close(POINT.positions(traj), start + frac * (goal - start), rtol=0, atol=1e-6)
    direction = (GOALS - STARTS) / np.maximum(np.linalg.norm(GOALS - STARTS, axis=1, keepdims=True), 1e-9)
    np.testing.assert_allclose(POINT.actions(traj)[:, 1:-1].numpy(), np.repeat(direction[:, None], H - 2, 1),
                               atol=1e-6)


def test_the_warm_prior_of_the_kinematic_point_holds_the_previous_plan():
    k = 2
    steps = (H - 1) * k + 1
    prev = np.zeros((B, steps, 4))
    POINT.positions(prev)[...] = np.linspace(STARTS, GOALS, steps, axis=1)
    POINT.actions(prev)[...] = 0.5
    cond = _conditions(STARTS, GOALS)
    x = NORM.unnormalize(WarmPrior(NORM, POINT, prev, [0] * B, stride=k).sample(cond, H, B).double()).numpy()
    np.testing.assert_allclose(x[:, 1:-1], prev[:, k:-k:k], atol=1e-6)  # the previous plan at every k-th step
    with pytest.raises(BridgeplanError, match=r"\[B, S, 4\]"):
        WarmPrior(NORM, POINT, np.zeros((B, steps, 6)), [0] * B)


def test_conditions_cover_the_state_columns_of_any_layout():
    x = torch.zeros(2, 5, 4)
    state = torch.tensor([[1.0, 2.0], [float("nan"), float("nan")]])
    out = apply_conditions(x, {3: state})
    assert out[0, 3].tolist() == [0, 0, 1, 2] and not out[1].any() and not x.any()


@pytest.mark.parametrize("process", [DDPM(steps=6), Bridge(steps=6), Flow(steps=6)])
def test_a_training_step_and_a_plan_of_each_process_on_kinematic_point_windows(process):
    torch.manual_seed(0)
    net = TemporalUNet(POINT.transition_dim, dim=8, dim_mults=(1, 2), horizon=H)
    prior = LinePrior(NORM, POINT, stride=2) if process.uses_prior else GaussianPrior(POINT)
    x0 = torch.rand(4, H, POINT.transition_dim, generator=torch.Generator().manual_seed(1)) * 2 - 1
    gen = torch.Generator().manual_seed(2)
    cond = window_conditions(x0, POINT)
    loss = process.training_loss(net, x0, prior.sample(cond, H, 4, gen), cond, gen)
    before = [p.detach().clone() for p in net.parameters()]
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    loss.backward()
    opt.step()
    assert torch.isfinite(loss) and any(not torch.equal(a, p) for a, p in zip(before, net.parameters()))

    planner = Planner(net.eval(), process, prior, NORM, H, torch.device("cpu"), POINT, stride=2)
    plan = planner.plan(STARTS, GOALS, process.max_nfe, torch.Generator().manual_seed(3))
    span = (H - 1) * 2 + 1
    assert plan.states.shape == (B, span, 2) and plan.actions.shape == (B, span, 2)
    want = planner.conditions(STARTS, GOALS)
    assert torch.equal(plan.sampled[:, 0, 2:], want[0]) and torch.equal(plan.sampled[:, -1, 2:], want[H - 1])
    np.testing.assert_allclose(plan.states[:, 0], STARTS, atol=1e-6)
    np.testing.assert_allclose(plan.states[:, -1], GOALS, atol=1e-6)
    held = planner.plan(STARTS, GOALS, 1, torch.Generator().manual_seed(3), arrival=np.array([2, 7, 4])).sampled
    assert torch.equal(held[0, 2:, 2:], want[H - 1][0].expand(H - 2, 2))  # the goal held from the arrival on
    assert torch.equal(held[2, 4:, 2:], want[H - 1][2].expand(H - 4, 2))


def _obeying(gain: float, stride: int) -> torch.Tensor:
    """Physical kinematic-point trajectories ``[B, H, 4]`` whose rows are ``stride`` steps apart and whose every step
    moves the position by ``gain`` times the action, linear between rows."""
    actions = torch.rand(B, H, 2, generator=torch.Generator().manual_seed(4), dtype=torch.float64) * 2 - 1
    k = stride
    mean = ((k + 1) * actions[:, :-1] + (k - 1) * actions[:, 1:]) / (2 * k)
    pos = torch.cat([torch.zeros(B, 1, 2, dtype=torch.float64), torch.cumsum(gain * k * mean, dim=1)], dim=1)
    return torch.cat([actions, pos], dim=-1)


@pytest.mark.parametrize("gain", [GAIN, 0.05])
def test_kinematics_of_a_kinematic_point_follow_its_actions(gain):
    body = KinematicPoint(gain)
    traj = _obeying(gain, 1)
    # stride 1: pos[t + 1] = pos[t] + gain * action[t], step by step
    torch.testing.assert_close(POINT.positions(traj)[:, 1:] - POINT.positions(traj)[:, :-1],
                               gain * POINT.actions(traj)[:, :-1], rtol=0, atol=1e-12)
    assert kinematics_error(traj, POINT, 1, body).abs().max() < 1e-12
    bad = traj.clone()
    bad[1, 3, 0] += 0.1  # one action off: its transition's error is that, in action units
    err = kinematics_error(bad, POINT, 1, body)
    assert abs(float(err[1, 3, 0]) + 0.1) < 1e-12 and float(err.abs().sum()) == pytest.approx(0.1, abs=1e-12)
    assert float(kinematics_error(traj, POINT, 1, KinematicPoint(2 * gain)).abs().max()) > 0.1  # another gain


@pytest.mark.parametrize("stride", [2, 5])
def test_strided_kinematics_of_a_kinematic_point_are_the_mean_of_its_steps(stride):
    body = KinematicPoint(GAIN)
    traj = _obeying(GAIN, stride)
    assert kinematics_error(traj, POINT, stride, body).abs().max() < 1e-12
    x = torch.rand(B, H, 4, generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    per_step = kinematics_error(torch.as_tensor(densify(x.numpy(), stride)), POINT, 1, body)
    torch.testing.assert_close(kinematics_error(x, POINT, stride, body),
                               per_step.reshape(B, H - 1, stride, 2).mean(2), rtol=0, atol=1e-12)
    x0 = NORM.normalize(traj)  # the same through the normalized residual R = 1/2 sum e^2
    assert float(residual("kinematics", x0, NORM, POINT, stride, body=body).max()) < 1e-20


def test_point_mass_residuals_refuse_a_layout_without_velocities():
    traj = _obeying(GAIN, 1)
    with pytest.raises(BridgeplanError, match="dynamics residual .* needs velocities, and the kinematic point"):
        dynamics_error(traj, POINT, 1)
    with pytest.raises(BridgeplanError, match="kinematics residual .* needs velocities"):
        kinematics_error(traj, POINT, 1)  # the point mass's kinematics: the kinematic point's need its body
    with pytest.raises(BridgeplanError, match="dynamics residual"):
        residual("dynamics", NORM.normalize(traj), NORM, POINT, 1, body=KinematicPoint(GAIN))
    with pytest.raises(BridgeplanError, match="needs velocities"):
        plan_residuals(NORM.normalize(traj).float(), NORM, POINT, 1)


def test_windows_and_holds_of_a_kinematic_point_stream():
    rng = np.random.default_rng(0)
    states, actions = rng.uniform(-1, 1, (40, 2)), rng.uniform(-1, 1, (40, 2))
    stream = Stream("pointmaze-medium-navigate-v0", states, actions, np.array([0, 25]), episodes=2, layout=POINT)
    assert stream.layout is POINT and stream.transitions().shape == (40, 4)
    windows = WindowDataset(stream, 6, Normalizer.fit(stream.transitions()), stride=2)
    assert windows.layout is POINT and windows.batch(torch.arange(len(windows))).shape == (len(windows), 6, 4)
    with pytest.raises(ValueError, match=r"\[T, 2\] / \[T, 2\]"):
        Stream("pointmaze-medium-navigate-v0", rng.uniform(size=(40, 4)), actions, np.array([0]), episodes=1,
               layout=POINT)
    with pytest.raises(ValueError, match=r"\[T, 4\] / \[T, 2\]"):
        Stream("umaze", states, actions, np.array([0]), episodes=1, layout=MAZE2D)
    with pytest.raises(BridgeplanError, match="normalizer has 6 columns"):
        WindowDataset(stream, 6, Normalizer((0.0,) * 6, (1.0,) * 6))

    x = torch.rand(4, 6, 4, generator=torch.Generator().manual_seed(0))
    rest = torch.tensor([-0.5, -0.5, 9.0, 9.0])  # a rest transition's action columns; its positions are unused
    out = hold_tails(x, 1.0, rest, POINT, torch.Generator().manual_seed(1))
    for i in range(4):
        k = int((out[i] != x[i]).any(dim=1).float().argmax()) - 1  # the last state still as in the window
        assert 1 <= k <= 4
        assert torch.equal(out[i, k + 1:, 2:], x[i, k, 2:].expand(5 - k, 2))  # position of state k
        assert torch.equal(out[i, k + 1:, :2], rest[:2].expand(5 - k, 2))  # no action


def test_arrival_of_a_kinematic_point_plan():
    traj = np.zeros((1, 5, 4))
    POINT.positions(traj)[0] = [[0, 0], [0.5, 0], [1.0, 0], [1.2, 0], [2.0, 0]]
    POINT.actions(traj)[...] = 1.0
    assert arrival_index(traj, np.array([[1.1, 0.0]]), POINT, radius=0.15).tolist() == [2]
    out, arrival = truncate_at_arrival(traj, np.array([[1.1, 0.0]]), POINT, radius=0.15)
    assert arrival.tolist() == [2]
    np.testing.assert_array_equal(out[0, 3:], [[0, 0, 1.1, 0]] * 2)  # the goal held, no action
