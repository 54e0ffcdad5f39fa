"""The code paths behind the headline numbers, each checked against numbers derived by hand: pursuit while
replanning, training-time holds end to end, arrival arithmetic at a stride, and conditions re-applied inside
every sampler's loop (flow's included)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from bridgeplan.cli import main
from bridgeplan.envs.controllers import Follower
from bridgeplan.envs.maze2d.controllers import BODY
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS
from bridgeplan.normalizer import Normalizer
from bridgeplan.planner import Planner
from bridgeplan.priors import GaussianPrior
from bridgeplan.processes import DDPM, Bridge, Flow
from bridgeplan.processes.base import Process
from bridgeplan.replan import Execution, PlanExecutor, PlanSource
from bridgeplan.runs import load_windows
from bridgeplan.trajectory import MAZE2D
from tests.test_train import train_args

# ---------------------------------------------------------------- pursuit while replanning

ACT_DIM = MAZE2D.act_dim


def _line(xs, ys) -> np.ndarray:
    """A plan ``[H, 4]`` through the positions ``(xs, ys)`` at rest."""
    xs, ys = np.broadcast_arrays(np.asarray(xs, np.float64), np.asarray(ys, np.float64))
    return np.stack([xs, ys, np.zeros_like(xs), np.zeros_like(xs)], axis=1)


def test_pursuit_progress_restarts_on_a_new_plan_and_continues_on_a_kept_one():
    """Two episodes pursued (lookahead 1) under the closed-loop controller. Plan A runs along x, 0.25 apart
    (x = 0, 0.25, ..., 3). At step 2 episode 0 alone replans to plan B, up along y from (1, 0): its progress
    starts again at B's index 0, so its waypoint is B's index 4 (y = 1.0, the first 1.0 away from (1, 0)), not
    B's index 7 (where A's progress stood). Episode 1 keeps plan A and its progress (index 7): its waypoint is
    A's index 9 (x = 2.25, the first from index 7 on at least 1.0 from x = 1.2), not A's index 0 (x = 0, 1.2
    behind it), which a progress reset would drive it back to."""
    a = _line(np.arange(13) * 0.25, 0.0)
    b = _line(1.0, np.arange(13) * 0.25)
    calls = []

    def plan_fn(states, goals, episodes, t):
        calls.append((t, episodes.tolist()))
        return np.stack([a if t == 0 else b for _ in episodes])

    follower = Follower(2, BODY, "pursuit", lookahead=1.0)
    controller = PlanExecutor(lambda n: plan_fn, lambda n: follower)
    controller.begin(2)
    goals = np.array([[3.0, 0.0], [3.0, 0.0]])

    def at(*xy_per_episode):
        return np.array([[x, y, 0.0, 0.0] for x, y in xy_per_episode])

    # step 0: both plan A; at the origin the first position 1.0 away is index 4 (x = 1.0); PD: clip(10 * 1) = 1
    act = controller.act(at((0, 0), (0, 0)), goals)
    assert follower.passed.tolist() == [4, 4]
    np.testing.assert_allclose(act, [[1.0, 0.0], [1.0, 0.0]])
    # step 1: at x = 0.6 the first position from index 4 on at least 1.0 away is index 7 (x = 1.75)
    act = controller.act(at((0.6, 0), (0.6, 0)), goals)
    assert follower.passed.tolist() == [7, 7]
    # step 2: episode 0 replans (plan B); episode 1 keeps plan A
    states = np.array([[1.0, 0.0, 0.0, 0.0], [1.2, 0.0, 0.5, 0.0]])
    controller.replan(np.array([0]))
    act = controller.act(states, goals)
    assert calls == [(0, [0, 1]), (2, [0])]
    np.testing.assert_array_equal(controller.plans[0], b)
    np.testing.assert_array_equal(controller.plans[1], a)
    assert controller.made_at.tolist() == [2, 0]
    assert follower.passed.tolist() == [4, 9]
    # the expert's PD law toward (1, 1) from (1, 0) at rest, and toward (2.25, 0) from (1.2, 0) at vx = 0.5
    np.testing.assert_allclose(act, [[0.0, 1.0], [np.clip(10 * 1.05 - 0.5, -1, 1), 0.0]])
    # step 3: both continue from there (B from index 4, A from index 9)
    controller.act(np.array([[1.0, 0.4, 0.0, 1.0], [1.5, 0.0, 1.0, 0.0]]), goals)
    assert follower.passed.tolist() == [6, 10]  # B: y = 1.5 (1.1 from 0.4, 1.25 < 1); A: x = 2.5 (1.0 from 1.5)


# ---------------------------------------------------------------- training-time holds, end to end


def _held_from(w: torch.Tensor, rest: torch.Tensor) -> int | None:
    """The index k from which window ``w [H, 6]`` waits still (every state after k: k's position, the rest
    action and velocity), or None when its tail does not."""
    last = w[-1]
    if not (torch.equal(last[:ACT_DIM], rest[:ACT_DIM]) and torch.equal(last[ACT_DIM + 2:], rest[ACT_DIM + 2:])):
        return None
    same = (w == last).all(dim=1)
    j = len(w) - 1
    while j > 0 and same[j - 1]:
        j -= 1
    k = j - 1  # the state whose position is kept
    return k if k >= 1 and torch.equal(w[k, ACT_DIM:ACT_DIM + 2], last[ACT_DIM:ACT_DIM + 2]) else None


@pytest.mark.parametrize("share", [0.0, 0.5, 1.0])
def test_training_with_a_hold_share_sees_holding_windows(tiny_dataset, tmp_path, monkeypatch, share):
    """A real run (the CLI, 2 steps of 64 windows) trained with ``--hold-share``: the windows its loss gets wait
    still from an index k in 1..H-2 on in the given share (all, about half, none); before k they are the
    dataset's own windows, and the goal condition is the held position at rest."""
    seen = []
    original = Process.training_loss

    def spy(self, model, x0, x1, conditions, generator=None):
        seen.append((x0.detach().clone(), {t: c.detach().clone() for t, c in conditions.items()}))
        return original(self, model, x0, x1, conditions, generator)

    monkeypatch.setattr(Process, "training_loss", spy)
    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2, "--batch-size", "64", "--hold-share", str(share))) == 0
    windows, normalizer = load_windows(tiny_dataset, "umaze", 32)
    rest = torch.as_tensor(normalizer.normalize(np.zeros(6)), dtype=torch.float32)
    assert len(seen) == 2
    x0 = torch.cat([x for x, _ in seen])
    assert x0.shape == (128, 32, 6)
    for x, cond in seen:  # the conditions are the windows' own ends, held ones included
        assert torch.equal(cond[0], x[:, 0, ACT_DIM:]) and torch.equal(cond[31], x[:, -1, ACT_DIM:])
    held = [_held_from(w, rest) for w in x0]
    share_held = sum(k is not None for k in held) / len(held)
    if share == 0.0:
        assert share_held == 0.0
    elif share == 1.0:
        assert share_held == 1.0
    else:
        assert 0.3 < share_held < 0.7, share_held  # 128 draws: 0.5 +- 4.5 standard errors
    first_rows = windows.data[windows.starts]  # [W, 6] the first state of every dataset window
    for w, k in zip(x0, held):
        start = torch.nonzero((first_rows == w[0]).all(dim=1))[:, 0]
        assert len(start) >= 1  # a dataset window
        real = windows[int(start[0])]
        if k is None:
            torch.testing.assert_close(w, real, rtol=0, atol=0)
        else:
            assert 1 <= k <= 30
            torch.testing.assert_close(w[:k + 1], real[:k + 1], rtol=0, atol=0)
            torch.testing.assert_close(w[-1, ACT_DIM:ACT_DIM + 2], real[k, ACT_DIM:ACT_DIM + 2], rtol=0, atol=0)


# ---------------------------------------------------------------- arrival arithmetic at a stride


def _normalizer() -> Normalizer:
    return Normalizer((-1.0, -1.0, -3.0, -3.0, -5.0, -5.0), (1.0, 1.0, 3.0, 3.0, 5.0, 5.0))


class _Ramp(torch.nn.Module):
    """A network that ignores its input: planned row j at x = min(0.5 j, 2), y = 0, at rest (normalized)."""

    def __init__(self, normalizer: Normalizer, horizon: int):
        super().__init__()
        phys = np.zeros((1, horizon, 6))
        phys[0, :, ACT_DIM] = np.minimum(0.5 * np.arange(horizon), 2.0)
        self.out = torch.as_tensor(normalizer.normalize(phys), dtype=torch.float32)

    def forward(self, x, t):
        return self.out.expand(x.shape[0], -1, -1).to(x.dtype)


def test_keep_arrival_at_a_stride_counts_env_steps_and_holds_from_the_next_planned_row():
    """H = 9 planned rows 3 env steps apart (25 dense steps), start (0, 0), goal (2, 0), a network that plans
    row j at x = min(0.5 j, 2). The first plan is dense x = min(s / 6, 2) at env step s: first within 0.45 of
    the goal at s = 10 (x = 1.67; s = 9 is x = 1.5, 0.5 away), so the deadline is env step 10. A replan at
    step t holds the goal from planned row ceil((10 - t) / 3) (at least 1), i.e. from env step t + 3 x row:
    t = 3 -> row 3 (env 12), t = 5 -> row 2 (env 11), t = 8 -> row 1 (env 11), t = 12 (past it) -> row 1
    (env 15). Each returned plan sits at the goal at rest from that dense step on, not before."""
    norm, h, k = _normalizer(), 9, 3
    seen = []

    class Spy(Planner):
        def plan(self, starts, goals, nfe, generator, prior_only=False, arrival=None):
            seen.append(None if arrival is None else np.asarray(arrival).tolist())
            return super().plan(starts, goals, nfe, generator, prior_only, arrival)

    planner = Spy(_Ramp(norm, h), DDPM(steps=6), GaussianPrior(MAZE2D), norm, h, torch.device("cpu"), MAZE2D, stride=k)
    source = PlanSource(planner, Execution(replan_every=4, arrival="keep"), 1, torch.Generator().manual_seed(0), 1,
                        GOAL_RADIUS)
    goal = np.array([[2.0, 0.0]])
    first = source(np.zeros((1, 4)), goal, np.arange(1), 0)
    assert first.shape == (1, 25, 4) and seen == [None]
    np.testing.assert_allclose(first[0, :11, 0], np.arange(11) / 6, atol=1e-6)  # truncated at step 10
    assert _at_goal_from(first, goal) == 11  # held from the step after the arrival on
    assert source.deadline.tolist() == [10]
    for t, row, held_from in ((3, 3, 12), (5, 2, 11), (8, 1, 11), (12, 1, 15)):
        plan = source(np.zeros((1, 4)), goal, np.arange(1), t)  # from the origin each time
        assert seen[-1] == [row]
        assert t + _at_goal_from(plan, goal) == held_from == t + k * row
        assert source.deadline.tolist() == [10]  # the first plan's, in env steps


def _at_goal_from(plan: np.ndarray, goal: np.ndarray) -> int:
    """The first dense step from which plan ``[1, S, 4]`` sits at ``goal [1, 2]`` at rest to its end."""
    at = (np.abs(plan[0, :, :2] - goal[0]) < 1e-5).all(axis=1) & (np.abs(plan[0, :, 2:]) < 1e-5).all(axis=1)
    s = len(at)
    while s > 0 and at[s - 1]:
        s -= 1
    return s


# ---------------------------------------------------------------- conditions inside the sampling loops

B, H, D = 3, 8, 6


@pytest.mark.parametrize("process", [Flow(steps=6), Flow(steps=6, sigma=0.5, sampler="stochastic"),
                                     DDPM(steps=6), DDPM(steps=6, sampler="ddim", eta=0.5), Bridge(steps=6)],
                         ids=["flow-euler", "flow-stochastic", "ddpm-ancestral", "ddim", "bridge"])
def test_every_network_input_carries_the_conditions(process):
    """A network that ignores the conditions (its output is far from them), spied on: the x it is handed at every
    call of the loop, not only the returned sample, has the start, the goal and a partial (NaN-row) arrival
    condition exactly in its state columns; the NaN rows keep their own (finite) values there."""
    gen = torch.Generator().manual_seed(0)
    start = torch.rand((B, 4), generator=gen, dtype=torch.float64) * 1.8 - 0.9
    goal = torch.rand((B, 4), generator=gen, dtype=torch.float64) * 1.8 - 0.9
    hold = goal.clone()
    hold[1] = torch.nan  # episode 1 is free at index 5
    cond = {0: start, 5: hold, H - 1: goal}
    inputs = []

    def model(x, n):
        inputs.append(x.clone())
        return torch.full_like(x, 0.95) - 0.1 * torch.tanh(x)  # near 1 everywhere, conditions ignored

    x_start = torch.randn((B, H, D), generator=gen, dtype=torch.float64)
    nfe = process.max_nfe
    out = process.sample(model, x_start, cond, nfe, gen)
    assert len(inputs) == nfe >= 5
    for call, x in enumerate([*inputs, out]):
        assert torch.equal(x[:, 0, ACT_DIM:], start), call
        assert torch.equal(x[:, H - 1, ACT_DIM:], goal), call
        assert torch.equal(x[[0, 2], 5, ACT_DIM:], goal[[0, 2]]), call
        assert torch.isfinite(x[1, 5]).all() and not torch.equal(x[1, 5, ACT_DIM:], goal[1]), call
