"""Plans at a temporal stride: windows, priors, the planner's dense plans, configs and the real CLI."""

import json

import numpy as np
import pytest
import torch

from bridgeplan import config as cfg
from bridgeplan.cli import main
from bridgeplan.envs.maze2d.datasets import load_stream
from bridgeplan.errors import BridgeplanError
from bridgeplan.normalizer import Normalizer
from bridgeplan.priors import LinePrior, WarmPrior
from bridgeplan.runs import load_planner, windows_of
from bridgeplan.trajectory import MAZE2D, densify, span
from tests.test_train import train_args


def test_densify_interpolates_between_planned_states():
    x = np.random.default_rng(0).normal(size=(3, 5, 6))
    dense = densify(x, 4)
    assert dense.shape == (3, span(5, 4), 6) == (3, 17, 6)
    np.testing.assert_array_equal(dense[:, ::4], x)  # the planned states themselves
    np.testing.assert_allclose(dense[:, 2], 0.5 * (x[:, 0] + x[:, 1]))  # halfway
    np.testing.assert_allclose(dense[:, 7], 0.25 * x[:, 1] + 0.75 * x[:, 2])
    assert densify(x, 1) is x or np.array_equal(densify(x, 1), x)


def test_windows_take_every_stride_th_transition(tiny_dataset):
    stream = load_stream(tiny_dataset)
    windows, normalizer = windows_of(stream, 8, stride=5)
    data = normalizer.normalize(stream.transitions())
    for i in (0, len(windows) // 2, len(windows) - 1):
        s = int(windows.starts[i])
        np.testing.assert_allclose(windows[i].numpy(), data[s:s + span(8, 5):5], atol=1e-6)
    np.testing.assert_allclose(windows.batch(torch.tensor([0, 3])).numpy()[1], windows[3].numpy())
    # a window spans 36 steps inside one segment: as many as plain windows of horizon 36
    assert len(windows) == len(windows_of(stream, 36)[0])


def _conditions(norm: Normalizer, start: np.ndarray, goal: np.ndarray, horizon: int) -> dict:
    def n(s):
        return torch.as_tensor(norm.normalize(s, slice(2, None)), dtype=torch.float64)
    return {0: n(start), horizon - 1: n(np.c_[goal, np.zeros_like(goal)])}


def _normalizer() -> Normalizer:
    rng = np.random.default_rng(1)
    columns = [rng.uniform(-r, r, (500, 2)) for r in (1, 2, 3)]  # actions, positions, velocities
    return Normalizer.fit(np.concatenate(columns, axis=1))


def test_line_prior_at_a_stride_is_the_dense_line_subsampled():
    """Every stride-th state of the line over S = (H-1)k+1 steps, velocity included (covers the line in S-1 steps)."""
    norm, h, k, b = _normalizer(), 9, 4, 3
    rng = np.random.default_rng(2)
    start, goal = np.c_[rng.uniform(-1, 1, (b, 2)), np.zeros((b, 2))], rng.uniform(-1, 1, (b, 2))
    strided = LinePrior(norm, MAZE2D, k).sample(_conditions(norm, start, goal, h), h, b)
    dense = LinePrior(norm, MAZE2D).sample(_conditions(norm, start, goal, span(h, k)), span(h, k), b)
    torch.testing.assert_close(strided[:, 1:-1], dense[:, k:-1:k])


@pytest.mark.parametrize("elapsed", [0, 3, 8, 13, 40])
def test_warm_prior_at_a_stride_is_the_dense_warm_prior_subsampled(elapsed):
    """Shift, held tail and the line to a moved goal all agree with the stride-1 warm prior at every k-th step,
    for elapsed steps on and off the stride and past the previous plan's end."""
    norm, h, k, b = _normalizer(), 9, 4, 2
    rng = np.random.default_rng(3)
    prev = densify(rng.uniform(-0.9, 0.9, size=(b, h, 6)), k)  # previous plans as executed: every step
    start, goal = np.c_[rng.uniform(-1, 1, (b, 2)), rng.uniform(-1, 1, (b, 2))], rng.uniform(-1, 1, (b, 2))
    strided = WarmPrior(norm, MAZE2D, prev, [elapsed] * b, stride=k).sample(_conditions(norm, start, goal, h), h, b)
    dense = WarmPrior(norm, MAZE2D, prev, [elapsed] * b).sample(_conditions(norm, start, goal, span(h, k)),
                                                                span(h, k), b)
    torch.testing.assert_close(strided[:, 1:-1], dense[:, k:-1:k])


def test_warm_prior_refuses_plans_of_another_span():
    norm = _normalizer()
    prev = np.zeros((2, 9, 6))  # 9 steps: horizon 9 at stride 1, not at stride 4
    cond = _conditions(norm, np.zeros((2, 4)), np.zeros((2, 2)), 9)
    with pytest.raises(BridgeplanError, match="33 steps"):
        WarmPrior(norm, MAZE2D, prev, [1, 1], stride=4).sample(cond, 9, 2)


def test_config_stride_names_and_checks():
    c = cfg.preset_config("umaze", "cpu-small", horizon=32, stride=8)
    assert c.run_name() == "umaze-ddpm-N16-H32k8-cpu-small-s0"
    assert cfg.preset_config("umaze", "cpu-small", horizon=32).run_name() == "umaze-ddpm-N16-H32-cpu-small-s0"
    with pytest.raises(BridgeplanError, match="horizon 40 at stride 8 does not fit umaze"):
        cfg.preset_config("umaze", "cpu-small", horizon=40, stride=8)  # 313 steps > 300
    with pytest.raises(BridgeplanError, match="stride must be >= 1"):
        cfg.preset_config("umaze", "cpu-small", stride=0)
    for maze in ("umaze", "medium", "large"):  # a learned prior for a preset follows the preset's plans
        planner = cfg.preset_config(maze, "cpu-small")
        prior = cfg.PriorTrainConfig(maze=maze, preset="cpu-small")
        assert (prior.horizon, prior.stride) == (planner.horizon, planner.stride)


def test_train_and_eval_at_a_stride(tiny_dataset, tmp_path, capsys):
    """The real commands: a bridge from the learned prior at stride 3, its plans dense, its floors at the stride;
    a prior trained for another stride is refused in one line."""
    prior, run = tmp_path / "prior", tmp_path / "run"
    assert main(["train-prior", "--maze", "umaze", "--dataset", tiny_dataset, "--run-dir", str(prior),
                 "--horizon", "32", "--stride", "3", "--steps", "2", "--no-progress", "--device", "cpu"]) == 0
    bridge = ("--process", "bridge", "--prior", "learned", "--prior-run", str(prior))
    assert main(train_args(tiny_dataset, run, 2, "--stride", "3", *bridge)) == 0
    planner, info = load_planner(run, device="cpu")
    assert (planner.horizon, planner.stride, info.config.stride) == (32, 3, 3)
    starts = np.array([[0.9, 0.9, 0.0, 0.0], [2.9, 0.9, 0.1, 0.0]])
    goals = np.array([[0.9, 2.9], [0.9, 0.9]])
    plan = planner.plan(starts, goals, 1, torch.Generator().manual_seed(0))
    assert plan.states.shape == (2, span(32, 3), 4)
    np.testing.assert_allclose(plan.states[:, 0], starts, atol=1e-5)
    np.testing.assert_allclose(plan.states[:, -1, :2], goals, atol=1e-5)
    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", "4", "--nfe", "1", "--out", str(out), "--device", "cpu"]) == 0
    result = json.loads(out.read_text())
    assert (result["horizon"], result["stride"]) == (32, 3)
    # closed loop with warm replans: the warm prior takes the executed (dense) previous plans
    assert main(["eval", str(run), "--episodes", "4", "--nfe", "1", "--out", str(out), "--device", "cpu",
                 "--replan-every", "20", "--prior", "warm"]) == 0
    assert json.loads(out.read_text())["plans_per_episode"]["mean"] == 15  # ceil(300 / 20)
    capsys.readouterr()
    other = tmp_path / "other"
    assert main(train_args(tiny_dataset, other, 2, "--stride", "2", *bridge)) == 2
    assert "trained for stride 3, not 2" in capsys.readouterr().err and not other.exists()
