"""Closed-loop execution: replanning counts, the warm prior, arrival truncation, candidate selection, the
policy in a real gymnasium env, and the CLI's bad input."""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from bridgeplan.cli import main
from bridgeplan.envs import maze2d
from bridgeplan.envs.maze2d.expert import WaypointExpert
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, get_maze
from bridgeplan.envs.maze2d.reference import normalized_score, score_returns
from bridgeplan.envs.maze2d.sim import BatchedPointMaze
from bridgeplan.envs.maze2d.tasks import MazeTasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import evaluate_planner, execute_plans, make_tasks
from bridgeplan.normalizer import Normalizer
from bridgeplan.planner import Plan, Planner
from bridgeplan.policy import PlannerPolicy
from bridgeplan.priors import PRIORS, WarmPrior, make_prior
from bridgeplan.replan import (
    Execution,
    PlanExecutor,
    PlanSource,
    arrival_index,
    select_candidates,
    truncate_at_arrival,
)
from bridgeplan.runs import load_planner
from bridgeplan.trajectory import MAZE2D

UMAZE = get_maze("umaze")
USAGE = Path(__file__).resolve().parents[1] / "docs" / "usage.md"


def closed_loop(tasks: MazeTasks, plan_fn, replan_every=None, tolerance=None, steps=None, controller="track"):
    """``plan_fn``'s decisions executed in Maze2D's episodes (``replan.PlanExecutor``, at most ``steps`` steps):
    the outcome, and the executor (its plans made and the steps its decisions came at)."""
    if steps is not None:
        tasks = dataclasses.replace(tasks, episode_steps=steps)
    called = []

    def decide(states, goals, idx, t):
        called.append(t)
        return plan_fn(states, goals, idx, t)

    executor = PlanExecutor(lambda n: decide, lambda n: maze2d.FAMILY.follower("umaze", n, controller),
                            replan_every, tolerance)
    outcome = maze2d.FAMILY.run(tasks, executor)
    executor.call_steps = called
    return outcome, executor


# ---------------------------------------------------------------- open loop is unchanged

def test_open_loop_json_scores_are_todays(tiny_runs, tmp_path):
    """Flags absent: the eval JSON's scores are exactly those of today's protocol spelled out here (one plan
    per episode from the tasks' generator, executed open loop)."""
    out = tmp_path / "open.json"
    assert main(["eval", str(tiny_runs["bridge"]), "--episodes", "5", "--nfe", "2", "--device", "cpu",
                 "--out", str(out)]) == 0
    saved = json.loads(out.read_text())
    planner, _ = load_planner(tiny_runs["bridge"], device="cpu")
    tasks = make_tasks("umaze", 5, 0)
    plan = planner.plan(tasks.start_states, tasks.goals_xy, 2, torch.Generator().manual_seed(0))
    today = execute_plans(tasks, plan.states)
    expected = json.loads(json.dumps(score_returns("umaze", today.returns, today.success)))
    assert {k: saved[k] for k in expected} == expected
    assert saved["execution"]["mode"] == "open_loop" and saved["plans_per_episode"]["max"] == 1
    assert saved["calls_per_episode"] == 2 and saved["decision_ms_batch1"]["count"] == 1  # its one decision


def test_pursuit_executes_the_same_plans_and_the_floors_with_its_controller(tiny_runs, tmp_path):
    """`--controller pursuit`: the same one plan per episode, executed by pursuit, scores and floors alike."""
    out = tmp_path / "pursuit.json"
    assert main(["eval", str(tiny_runs["bridge"]), "--episodes", "5", "--nfe", "2", "--device", "cpu",
                 "--controller", "pursuit", "--lookahead", "0.7", "--out", str(out)]) == 0
    saved = json.loads(out.read_text())
    planner, _ = load_planner(tiny_runs["bridge"], device="cpu")
    tasks = make_tasks("umaze", 5, 0)
    plan = planner.plan(tasks.start_states, tasks.goals_xy, 2, torch.Generator().manual_seed(0))
    pursuit = Execution(controller="pursuit", lookahead=0.7)
    pursued = execute_plans(tasks, plan.states, pursuit)
    expected = json.loads(json.dumps(score_returns("umaze", pursued.returns, pursued.success)))
    assert {k: saved[k] for k in expected} == expected
    line = planner.with_prior(make_prior("line", planner.normalizer, planner.layout, stride=planner.stride))
    line_plan = line.plan(tasks.start_states, tasks.goals_xy, 1, torch.Generator().manual_seed(0), prior_only=True)
    line_pursued = execute_plans(tasks, line_plan.states, pursuit)
    assert saved["floor_line"]["return"]["mean"] == pytest.approx(line_pursued.returns.mean())
    assert saved["execution"]["controller"] == "pursuit" and saved["execution"]["lookahead"] == 0.7
    assert saved["plans_per_episode"]["max"] == 1 and saved["calls_per_episode"] == 2


def test_closed_loop_without_replanning_is_open_loop():
    """The closed-loop controller with neither K nor D plans once and moves exactly as execute_plans."""
    tasks = dataclasses.replace(make_tasks("umaze", 4, 1), episode_steps=60)
    plans = np.stack([np.linspace(np.r_[s, 0, 0], np.r_[g, 0, 0], 40) for s, g in zip(tasks.starts_xy, tasks.goals_xy)])
    open_loop = execute_plans(tasks, plans)
    closed, executor = closed_loop(tasks, lambda s, g, idx, t: plans[idx])
    np.testing.assert_array_equal(open_loop.states, closed.states)
    np.testing.assert_array_equal(open_loop.returns, closed.returns)
    assert executor.plans_made.tolist() == [1] * 4 and executor.call_steps == [0]


# ---------------------------------------------------------------- replanning counts

@pytest.mark.parametrize("k", [1, 7, 128, 300])
def test_replan_every_makes_ceil_steps_over_k_plans(tiny_runs, monkeypatch, k):
    """--replan-every K: ceil(300 / K) plans per episode, counted at the planner itself, and
    calls_per_episode = that x NFE in the JSON."""
    planner, info = load_planner(tiny_runs["bridge"], device="cpu")
    rows = []
    original = Planner.plan

    def counting(self, starts, goals, nfe, generator, **kwargs):
        rows.append(len(starts))
        return original(self, starts, goals, nfe, generator, **kwargs)

    monkeypatch.setattr(Planner, "plan", counting)
    tasks = make_tasks("umaze", 3, 2)
    result = evaluate_planner(planner, tasks, 2, run=info, precomputed_floors={},
                              execution=Execution(replan_every=k)).to_dict()
    plans = math.ceil(300 / k)
    decided = rows[:plans]  # then the batch-1 latency episode: one warm-up decision and ceil(300/K) more
    assert decided == [3] * plans and rows[plans:] == [1] * (plans + 1)
    assert result["plans_per_episode"] == {"mean": plans, "min": plans, "max": plans}
    assert result["calls_per_episode"] == plans * 2
    assert result["decision_ms_batch1"]["count"] == plans and result["decision_ms_per_batch"]["count"] == plans
    assert result["decision_ms_batch1"]["p50"] > 0 and result["decision_ms_per_batch"]["mean_batch"] == 3
    # every step of the lone episode timed (300: Maze2D runs to its limit), its decisions inside its steps
    steps, decisions = result["step_ms_batch1"], result["decision_ms_batch1"]
    assert steps["count"] == 300 and steps["mean"] * steps["count"] >= decisions["mean"] * decisions["count"]
    assert result["execution"] == {"mode": "closed_loop", "replan_every": k, "replan_tolerance": None,
                                   "candidates": 1, "select": None, "arrival": "truncate",
                                   "first_prior": "learned", "replan_prior": "learned", "controller": "track",
                                   "lookahead": None}


def test_tolerance_replans_only_the_drifted_episode():
    """Episode 0's plan is to stay where it is (no drift); episode 1's plan puts it 1.0 away at once: only
    episode 1 replans, and every replan is a call for it alone."""
    starts = np.array([[1.0, 1.0], [-1.0, 1.0]])
    goals = np.array([[1.0, -1.0], [1.0, -1.0]])
    calls = []

    def plan_fn(states, goals_, idx, t):
        calls.append(idx.tolist())
        plans = np.repeat(np.c_[states[:, :2], np.zeros((len(idx), 2))][:, None], 16, axis=1)
        plans[idx == 1, 1:, 0] += 1.0  # unreachable in one step: the state drifts from it
        return plans

    _, executor = closed_loop(MazeTasks.of(UMAZE, starts, goals), plan_fn, tolerance=0.3, steps=20)
    assert executor.plans_made[0] == 1 and executor.plans_made[1] > 1
    assert calls[0] == [0, 1] and all(c == [1] for c in calls[1:])


def test_after_step_replans_where_a_plans_first_step_ended():
    """A source whose paths are made of steps says where each episode's first step ends (episode 0's at 4, episode
    1's never): with after_step 3 episode 0 plans again 4 + 3 steps after each plan, episode 1 never; a source
    without step ends is refused."""
    class Steps:
        def __init__(self, n):
            self.step_ends, self.calls = np.full(n, np.inf), []

        def __call__(self, states, goals_, idx, t):
            self.calls.append((t, idx.tolist()))
            self.step_ends[idx] = np.where(idx == 0, 4, np.inf)
            return np.repeat(np.c_[states[:, :2], np.zeros((len(idx), 2))][:, None], 16, axis=1)

    tasks = dataclasses.replace(MazeTasks.of(UMAZE, np.array([[1.0, 1.0], [-1.0, 1.0]]),
                                             np.array([[1.0, -1.0], [1.0, -1.0]])), episode_steps=20)
    source = Steps(2)
    executor = PlanExecutor(lambda n: source, lambda n: maze2d.FAMILY.follower("umaze", n, "track"), after_step=3)
    maze2d.FAMILY.run(tasks, executor)
    assert source.calls == [(0, [0, 1]), (7, [0]), (14, [0])]
    assert executor.plans_made.tolist() == [3, 1]
    bare = PlanExecutor(lambda n: lambda *a: None, lambda n: maze2d.FAMILY.follower("umaze", n, "track"),
                        after_step=3)
    with pytest.raises(BridgeplanError, match="only paths made of steps"):
        maze2d.FAMILY.run(tasks, bare)


def test_object_tolerance_replans_where_an_object_left_its_plan():
    """A source that says how far each episode's objects are from its plan (episode 1's 0.6 from step 5 on, episode
    0's never): with object_tolerance 0.5 episode 1 plans again at each step from 5 on, episode 0 never; a source
    that says nothing of objects is refused."""
    class Objects:
        drifts = True

        def __init__(self):
            self.calls, self.t = [], 0

        def __call__(self, states, goals_, idx, t):
            self.calls.append((t, idx.tolist()))
            return np.repeat(np.c_[states[:, :2], np.zeros((len(idx), 2))][:, None], 16, axis=1)

        def drift(self, states, plans, age):  # asked at every step after the first plan's
            self.t += 1
            return np.array([0.0, 0.6 if self.t >= 5 else 0.4])

    tasks = dataclasses.replace(MazeTasks.of(UMAZE, np.array([[1.0, 1.0], [-1.0, 1.0]]),
                                             np.array([[1.0, -1.0], [1.0, -1.0]])), episode_steps=8)
    source = Objects()
    executor = PlanExecutor(lambda n: source, lambda n: maze2d.FAMILY.follower("umaze", n, "track"),
                            object_tolerance=0.5)
    maze2d.FAMILY.run(tasks, executor)
    assert source.calls == [(0, [0, 1]), (5, [1]), (6, [1]), (7, [1])]
    bare = PlanExecutor(lambda n: lambda *a: None, lambda n: maze2d.FAMILY.follower("umaze", n, "track"),
                        object_tolerance=0.5)
    with pytest.raises(BridgeplanError, match="only paths that say where every object should be"):
        maze2d.FAMILY.run(tasks, bare)


# ---------------------------------------------------------------- warm prior

def _normalizer() -> Normalizer:
    return Normalizer((-1.0, -1.0, -1.5, -1.5, -5.0, -5.0), (1.0, 1.0, 1.5, 1.5, 5.0, 5.0))


def test_warm_prior_is_the_previous_plan_shifted():
    """The sample equals the previous plan shifted by K steps, the goal held after the previous plan's end,
    with the current state exact at t = 0 and the goal exact at t = H - 1."""
    norm, h, k, b = _normalizer(), 16, 5, 3
    rng = np.random.default_rng(0)
    prev = rng.uniform(-0.9, 0.9, size=(b, h, 6))
    goal = rng.uniform(-1.2, 1.2, size=(b, 2))
    prev[:, -1, 2:4], prev[:, -1, 4:] = goal, 0.0  # plans end at the goal, at rest
    start = np.c_[rng.uniform(-1.2, 1.2, size=(b, 2)), rng.uniform(-1, 1, size=(b, 2))]
    cond = {0: torch.as_tensor(norm.normalize(start, slice(2, None)), dtype=torch.float32),
            h - 1: torch.as_tensor(norm.normalize(np.c_[goal, np.zeros((b, 2))], slice(2, None)), dtype=torch.float32)}
    x = WarmPrior(norm, MAZE2D, prev, [k] * b).sample(cond, h, b)
    assert torch.equal(x[:, 0, 2:], cond[0]) and torch.equal(x[:, h - 1, 2:], cond[h - 1])
    traj = norm.unnormalize(x.double().numpy())
    np.testing.assert_allclose(traj[:, 1:h - k], prev[:, k + 1:], atol=1e-6)  # shifted
    np.testing.assert_allclose(traj[:, h - k:, 2:4], np.repeat(goal[:, None], k, axis=1), atol=1e-6)  # held
    np.testing.assert_allclose(traj[:, h - k:-1, 4:], 0.0, atol=1e-6)
    # elapsed 0: the previous plan itself; per-row shifts; a moved goal: a straight line to it
    same = norm.unnormalize(WarmPrior(norm, MAZE2D, prev, [0] * b).sample(cond, h, b).double().numpy())
    np.testing.assert_allclose(same[:, 1:-1], prev[:, 1:-1], atol=1e-6)
    moved = dict(cond)
    moved[h - 1] = torch.as_tensor(norm.normalize(np.zeros((b, 4)), slice(2, None)), dtype=torch.float32)
    line = norm.unnormalize(WarmPrior(norm, MAZE2D, prev, [4, 4, 4]).sample(moved, h, b).double().numpy())
    steps = np.diff(line[:, h - 5:, 2:4], axis=1)
    np.testing.assert_allclose(steps, np.repeat(steps[:, :1], 4, axis=1), atol=1e-6)


def test_warm_prior_registry_and_first_plan():
    assert "warm" in PRIORS
    prior = make_prior("warm", _normalizer(), MAZE2D)
    cond = {0: torch.zeros(2, 4), 7: torch.zeros(2, 4)}
    with pytest.raises(BridgeplanError, match="only valid on replans"):
        prior.sample(cond, 8, 2)


def test_warm_prior_cannot_be_trained(tiny_dataset, tmp_path, capsys):
    from tests.test_train import train_args

    run = tmp_path / "run"
    assert main(train_args(tiny_dataset, run, 2, "--process", "bridge", "--prior", "warm")) == 2
    assert "only valid on replans" in capsys.readouterr().err and not run.exists()


def test_warm_replans_start_from_the_previous_plan(tiny_runs):
    """Through PlanSource: a replan with --prior warm samples its prior from the episode's previous plan."""
    planner, _ = load_planner(tiny_runs["bridge"], device="cpu")
    seen = []

    class Spy(Planner):
        def plan(self, starts, goals, nfe, generator, **kwargs):
            seen.append(self.prior)
            return super().plan(starts, goals, nfe, generator, **kwargs)

    spy = Spy(**{f: getattr(planner, f)
                 for f in ("model", "process", "prior", "normalizer", "horizon", "device", "layout")})
    source = PlanSource(spy, Execution(replan_every=4, warm=True), 1, torch.Generator().manual_seed(0), 2, GOAL_RADIUS)
    tasks = make_tasks("umaze", 2, 0)
    first = source(tasks.start_states, tasks.goals_xy, np.arange(2), 0)
    source(np.c_[first[:, 4, :2], first[:, 4, 2:]], tasks.goals_xy, np.arange(2), 4)
    assert seen[0].name == "learned" and isinstance(seen[1], WarmPrior)
    np.testing.assert_array_equal(seen[1].elapsed.numpy(), [4, 4])
    np.testing.assert_array_equal(seen[1].previous[:, :, 2:].numpy(), first)


@pytest.mark.parametrize("process", ["ddpm", "bridge"])
def test_arrival_holds_the_goal_from_its_index(tiny_runs, process):
    """A plan with an arrival index a sits at the goal (zero velocity) at every t >= a; a row with a = H-1 is
    exactly the plan made without arrival indices (same generator)."""
    planner, _ = load_planner(tiny_runs[process], device="cpu")
    tasks = make_tasks("umaze", 3, 0)
    h = planner.horizon
    arrival = np.array([5, h - 1, 20])
    held = planner.plan(tasks.start_states, tasks.goals_xy, 1, torch.Generator().manual_seed(0), arrival=arrival)
    free = planner.plan(tasks.start_states, tasks.goals_xy, 1, torch.Generator().manual_seed(0))
    for row, a in enumerate(arrival):
        np.testing.assert_allclose(held.states[row, a:, :2], np.repeat(tasks.goals_xy[row][None], h - a, 0), atol=1e-5)
        np.testing.assert_allclose(held.states[row, a:, 2:], 0.0, atol=1e-5)
    np.testing.assert_array_equal(held.states[1], free.states[1])
    assert not np.allclose(held.states[0, 1:5], free.states[0, 1:5])


def test_keep_holds_replans_to_the_first_plans_arrival(tiny_runs):
    """Through PlanSource: the first plan has no arrival index; replans hold the goal from the first plan's
    arrival step less the steps elapsed (at least 1), and arrive by then; the deadline stays the first plan's."""
    planner, _ = load_planner(tiny_runs["ddpm"], device="cpu")
    seen = []

    class Spy(Planner):
        def plan(self, starts, goals, nfe, generator, prior_only=False, arrival=None):
            seen.append(arrival)
            return super().plan(starts, goals, nfe, generator, prior_only, arrival)

    spy = Spy(**{f: getattr(planner, f)
                 for f in ("model", "process", "prior", "normalizer", "horizon", "device", "layout")})
    source = PlanSource(spy, Execution(replan_every=4, arrival="keep"), 1, torch.Generator().manual_seed(0), 3,
                        GOAL_RADIUS)
    tasks = make_tasks("umaze", 3, 0)
    first = source(tasks.start_states, tasks.goals_xy, np.arange(3), 0)
    full = np.c_[np.zeros((3, first.shape[1], 2)), first]
    before = arrival_index(full, tasks.goals_xy, MAZE2D, GOAL_RADIUS)
    second = source(first[:, 4], tasks.goals_xy, np.arange(3), 4)
    assert seen[0] is None
    np.testing.assert_array_equal(seen[1], np.clip(before - 4, 1, planner.horizon - 1))
    after = arrival_index(np.c_[np.zeros((3, second.shape[1], 2)), second], tasks.goals_xy, MAZE2D, GOAL_RADIUS)
    assert (after <= seen[1]).all()
    source(second[:, 6], tasks.goals_xy, np.arange(3), 10)
    np.testing.assert_array_equal(seen[2], np.clip(before - 10, 1, planner.horizon - 1))


# ---------------------------------------------------------------- a perfect plan source beats open loop

def expert_paths(states: np.ndarray, goals: np.ndarray, horizon: int) -> np.ndarray:
    """The shortest-path expert's own motion from ``states`` for ``horizon`` states: a perfect plan."""
    sim = BatchedPointMaze(UMAZE, len(states))
    obs = sim.reset(states[:, :2], goals, velocities=states[:, 2:])
    expert = WaypointExpert(UMAZE)
    expert.plan(obs[:, :2], goals)
    path = [obs]
    for _ in range(horizon - 1):
        obs, _ = sim.step(expert(obs))
        path.append(obs)
    return np.stack(path, axis=1)


def test_replanning_a_perfect_plan_source_beats_open_loop():
    """Plans that are the expert's own path, but only H = 32 steps long: open loop the point mass stops where
    the first plan ends, short of the goal (late forever); replanning every 8 steps follows the expert all
    the way and scores far higher."""
    tasks = make_tasks("umaze", 6, 0)
    plan_fn = lambda s, g, idx, t: expert_paths(s, g, 32)  # noqa: E731
    open_loop = execute_plans(tasks, plan_fn(tasks.start_states, tasks.goals_xy, None, 0))
    closed, _ = closed_loop(tasks, plan_fn, replan_every=8)
    far = np.linalg.norm(tasks.starts_xy - tasks.goals_xy, axis=1) > 1.5
    assert far.any()
    assert (closed.returns[far] > open_loop.returns[far] + 50).all()
    assert closed.success.all() and not open_loop.success[far].any()
    score = score_returns("umaze", closed.returns, closed.success)["score"]["minari"]["mean"]
    assert score > score_returns("umaze", open_loop.returns, open_loop.success)["score"]["minari"]["mean"] + 30


# ---------------------------------------------------------------- arrival and candidates

def test_truncate_at_arrival_holds_the_goal():
    h = 10
    traj = np.zeros((2, h, 6))
    traj[:, :, 2] = np.linspace(0, 2, h)  # along x toward the goal at x = 2
    traj[:, :, 4] = 1.0
    goals = np.array([[2.0, 0.0], [0.9, 0.0]])
    out, arrival = truncate_at_arrival(traj, goals, MAZE2D, GOAL_RADIUS)
    assert arrival.tolist() == [7, 3]  # first x within 0.45 of the goal: 1.56 (index 7); 0.67 (index 3)
    np.testing.assert_array_equal(out[1, :4], traj[1, :4])
    np.testing.assert_array_equal(out[1, 4:, 2:4], np.repeat(goals[1:], h - 4, axis=0))
    assert not out[1, 4:, 4:].any() and not out[1, 4:, :2].any()


class KnownCandidates:
    """A fake planner: every episode's candidate j is a straight walk that reaches the goal at step ARRIVE[j]
    and holds it; candidate 3 cuts through the wall of the U."""

    ARRIVE = (20, 9, 14, 5)

    def __init__(self, horizon=24):
        self.horizon, self.prior, self.normalizer, self.device = (horizon, make_prior("gaussian", None, MAZE2D),
                                                                  None, "cpu")
        self.layout = MAZE2D

    def with_prior(self, prior):
        return self

    def plan(self, starts, goals, nfe, generator, prior_only=False, arrival=None):
        m = len(self.ARRIVE)
        states = np.zeros((len(starts), self.horizon, 4))
        for r in range(len(starts)):
            a = self.ARRIVE[r % m]
            frac = np.minimum(np.arange(self.horizon) / a, 1.0)[:, None]
            if r % m == 3:  # straight through the wall
                states[r, :, :2] = starts[r, :2] + frac * (goals[r] - starts[r, :2])
            else:  # around the U: along the bottom row to the right column, up it, then along the top row
                corner1, corner2 = np.array([1.0, starts[r, 1]]), np.array([1.0, goals[r, 1]])
                pts = np.array([starts[r, :2], corner1, corner2, goals[r]])
                seg = np.interp(frac[:, 0] * 3, np.arange(4), np.arange(4))
                i = np.minimum(seg.astype(int), 2)
                w = (seg - i)[:, None]
                states[r, :, :2] = pts[i] * (1 - w) + pts[i + 1] * w
        return Plan(states, np.zeros((len(starts), self.horizon, 2)), 0.0, 0.0)


@pytest.mark.parametrize("how, expected", [("arrival", 3), ("walls", 1)])
def test_candidates_pick_by_the_criterion(how, expected):
    """M = 4 known candidates per episode in one batch: ``arrival`` picks the earliest (candidate 3, through
    the wall), ``walls`` the earliest of those that stay out of walls (candidate 1)."""
    planner = KnownCandidates()
    batches = []
    original = planner.plan
    planner.plan = lambda s, g, nfe, gen, **kw: batches.append(len(s)) or original(s, g, nfe, gen, **kw)
    starts = np.array([[-1.0, -1.0, 0, 0], [-1.2, -0.9, 0, 0]])  # bottom left; goals top left, over the wall
    goals = np.array([[-1.0, 1.0], [-1.1, 1.1]])
    source = PlanSource(planner, Execution(replan_every=8, candidates=4, select=how), 1, None, 2, GOAL_RADIUS,
                        UMAZE.is_free_xy)
    chosen = source(starts, goals, np.arange(2), 0)
    assert batches == [8]  # 2 episodes x 4 candidates, one batch
    want = planner.plan(np.repeat(starts, 4, axis=0), np.repeat(goals, 4, axis=0), 1, None).states
    want, _ = truncate_at_arrival(np.concatenate([np.zeros((8, 24, 2)), want], axis=2), np.repeat(goals, 4, axis=0),
                                  MAZE2D, GOAL_RADIUS)
    np.testing.assert_array_equal(chosen, want.reshape(2, 4, 24, 6)[:, expected, :, 2:])


def test_agreement_picks_the_medoid():
    traj = np.zeros((1, 3, 5, 6))
    traj[0, 0, :, 2], traj[0, 1, :, 2], traj[0, 2, :, 2] = 0.0, 0.1, 1.0  # 1 sits between 0 and the outlier 2
    assert select_candidates(traj, np.zeros((1, 2)), "agreement", MAZE2D, GOAL_RADIUS).tolist() == [1]


def test_candidates_through_the_cli(tiny_runs, tmp_path):
    out = tmp_path / "cand.json"
    assert main(["eval", str(tiny_runs["bridge"]), "--episodes", "3", "--nfe", "2", "--device", "cpu",
                 "--candidates", "3", "--select", "walls", "--replan-every", "100", "--prior", "warm",
                 "--out", str(out)]) == 0
    saved = json.loads(out.read_text())
    assert saved["execution"]["candidates"] == 3 and saved["execution"]["select"] == "walls"
    assert saved["execution"]["replan_prior"] == "warm" and saved["plans_per_episode"]["mean"] == 3
    assert saved["calls_per_episode"] == 6 and saved["candidate_plans_per_episode"] == 9
    assert saved["decision_ms_per_batch"]["mean_batch"] == 9


# ------------------------------------------------------------ the policy, as docs/usage.md shows it

def _usage_loop() -> str:
    section = USAGE.read_text().split("## Closed loop, controllers and your own loop", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.mark.parametrize("name", ["umaze", "medium", "large"])
def test_the_usage_loop_runs_every_shipped_planner_to_the_episodes_end(name):
    """docs/usage.md's loop, as written (one episode instead of twenty, the shipped planner's name substituted), in the
    real environment: each episode runs to its time limit, success is read from ``info``, the return is scored."""
    from bridgeplan import shipped

    code = _usage_loop()
    assert {e.name for e in shipped.manifest().values() if e.kind == "planner"} == {"umaze", "medium", "large"}
    assert 'from_run("medium", ' in code and "device" not in code  # the device chosen as every command does
    for make in (PlannerPolicy.from_run, PlannerPolicy.from_hierarchy, PlannerPolicy.from_graph):
        assert inspect.signature(make).parameters["device"].default == "auto"
    scope: dict = {}
    one = code.replace('"medium"', f'"{name}"').replace("range(20)", "range(1)")
    exec(compile(one, "docs/usage.md", "exec"), scope)
    env, policy, returns, successes = scope["env"], scope["policy"], scope["returns"], scope["successes"]
    assert env.spec.id == policy.maze.gym_id and policy.maze.name == name
    assert policy.steps == env.spec.max_episode_steps == policy.maze.episode_steps  # to the episode's end
    # the single-task episodes: the goal in the maze's own goal cell (within the environment's position noise)
    assert np.abs(env.unwrapped.goal - policy.maze.eval_goal_xy).max() <= 0.25
    # success from info, as the return says it: a step within 0.45 of the goal earns 1
    assert len(returns) == len(successes) == 1 and successes[0] == (returns[0] > 0)
    assert scope["score"] == pytest.approx(normalized_score(name, returns, "minari")[0])
    if name == "umaze":  # success 1.00 over its 200 test episodes (docs/results/shipped.md)
        assert successes == [True]
    env.close()


def test_policy_replans_when_the_goal_moves(tiny_runs):
    from bridgeplan.policy import PlannerPolicy

    policy = PlannerPolicy.from_run(tiny_runs["bridge"], replan_every=None, device="cpu")
    obs = {"observation": np.array([1.0, 1.0, 0, 0]), "desired_goal": np.array([1.0, -1.0])}
    policy(obs)
    policy(obs)
    assert policy.plans_made == 1
    policy({**obs, "desired_goal": np.array([-1.0, 1.0])})
    assert policy.plans_made == 2
    with pytest.raises(BridgeplanError, match="observation dict"):
        policy(np.zeros(4))


def test_a_policy_through_the_frozen_network_acts_as_the_eager_one(tiny_runs):
    """``frozen=True``: the network traced and frozen, the same actions step by step."""
    from bridgeplan.nets.unet import FrozenUNet
    from bridgeplan.policy import PlannerPolicy

    policies = [PlannerPolicy.from_run(tiny_runs["bridge"], replan_every=4, device="cpu", frozen=frozen)
                for frozen in (False, True)]
    assert [isinstance(p.executor.sources[0].planner.model, FrozenUNet) for p in policies] == [False, True]
    obs = {"observation": np.array([1.0, 1.0, 0.0, 0.0]), "desired_goal": np.array([1.0, -1.0])}
    for _ in range(10):
        eager, frozen = (p(obs) for p in policies)
        assert np.array_equal(eager, frozen)
        obs = {**obs, "observation": obs["observation"] + np.r_[0.05 * eager, 0.0, 0.0]}


# ---------------------------------------------------------------- render and bad input

def test_render_closed_loop(tiny_runs, tmp_path):
    out = tmp_path / "closed.png"
    assert main(["render", str(tiny_runs["bridge"]), "--episodes", "2", "--device", "cpu", "--out", str(out),
                 "--replan-every", "50", "--candidates", "2"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("process, bad, message", [
    ("bridge", ["--replan-every", "0"], "--replan-every must be in 1..300"),
    ("bridge", ["--replan-every", "301"], "--replan-every must be in 1..300"),
    ("bridge", ["--candidates", "0"], "--candidates must be >= 1"),
    ("bridge", ["--prior", "warm"], "--prior warm is only valid on replans"),
    ("ddpm", ["--prior", "warm", "--replan-every", "8"], "--prior warm needs a process that starts from a prior"),
    ("bridge", ["--replan-tolerance", "-0.1"], "--replan-tolerance must be >= 0"),
    ("bridge", ["--prior", "line", "--replan-every", "8"], "--prior takes warm"),
    ("bridge", ["--select", "best", "--candidates", "2"], "unknown --select"),
    ("bridge", ["--arrival", "soon"], "unknown --arrival"),
    ("bridge", ["--arrival", "keep"], "--arrival keep holds replans"),
    ("bridge", ["--controller", "fast"], "unknown --controller"),
    ("bridge", ["--controller", "pursuit", "--lookahead", "0"], "--lookahead must be a finite distance > 0"),
    ("ddpm", ["--lookahead", "0.5"], "--lookahead is the pursuit controller's"),
])
@pytest.mark.parametrize("command", ["eval", "render"])
def test_bad_closed_loop_input(tiny_runs, tmp_path, capsys, process, bad, message, command):
    run = tiny_runs[process]
    before = sorted(p.name for p in run.rglob("*"))
    out = tmp_path / ("r.json" if command == "eval" else "r.png")
    assert main([command, str(run), "--episodes", "2", "--device", "cpu", "--out", str(out), *bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0]
    assert not out.exists() and sorted(p.name for p in run.rglob("*")) == before
