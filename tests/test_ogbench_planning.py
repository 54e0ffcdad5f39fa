"""Planners on OGBench pointmaze: trained through the real CLI on a tiny generated navigate dataset, executed by
the kinematic point's controllers, evaluated through OGBench's protocol (``bridgeplan eval``, as any family's)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from bridgeplan import config as cfg
from bridgeplan.cli import main
from bridgeplan.device import cpu_model
from bridgeplan.envs.controllers import Follower, tracking_targets
from bridgeplan.envs.ogbench_pointmaze import FAMILY
from bridgeplan.envs.ogbench_pointmaze.controllers import BODY, GAIN, pursuit_action, step_action
from bridgeplan.envs.ogbench_pointmaze.maze import make_env
from bridgeplan.envs.ogbench_pointmaze.plans import plan_shape
from bridgeplan.errors import BridgeplanError
from bridgeplan.policy import PlannerPolicy
from bridgeplan.processes import DDPM
from bridgeplan.replan import Execution, PlanExecutor, PlanSource
from bridgeplan.trajectory import KINEMATIC_POINT, span

NAME = "pointmaze-medium-navigate-v0"
# plans of 8 states 4 steps apart (29 steps): episodes of 60 steps hold windows, and tiny runs train in seconds
SHAPE = ("--horizon", "8", "--stride", "4")
PROCESSES = {"ddpm": ("--process", "ddpm"), "bridge": ("--process", "bridge", "--prior", "line"),
             "flow": ("--process", "flow", "--prior", "line"), "bridge-learned": ("--process", "bridge", "--prior",
                                                                                   "learned", "--prior-run", "{prior}")}


@pytest.fixture(scope="module")
def navigate(tmp_path_factory) -> Path:
    """A tiny navigate dataset (4 episodes of 60 steps) written by the real generator."""
    out = tmp_path_factory.mktemp("ogbench")
    assert main(["data", "generate", "--maze", NAME, "--episodes", "4", "--episode-steps", "60", "--out", str(out),
                 "--no-progress"]) == 0
    return out / f"{NAME}.npz"


@pytest.fixture(scope="module")
def point_runs(navigate, tmp_path_factory) -> dict[str, Path]:
    """One tiny run per process and prior (3 optimizer steps), and the learned prior's, trained through the CLI."""
    root = tmp_path_factory.mktemp("point-runs")
    prior = tmp_path_factory.mktemp("point-prior") / "prior"
    assert main(["train-prior", "--maze", NAME, "--dataset", str(navigate), "--preset", "cpu-small", *SHAPE,
                 "--steps", "3", "--run-dir", str(prior), "--device", "cpu", "--no-progress"]) == 0
    runs = {}
    for name, flags in PROCESSES.items():
        flags = [f.format(prior=prior) for f in flags]
        assert main(["train", "--maze", NAME, "--dataset", str(navigate), "--preset", "cpu-small", *SHAPE,
                     "--steps", "3", "--checkpoint-every", "3", "--runs-root", str(root), "--device", "cpu",
                     "--no-progress", *flags]) == 0
        (runs[name],) = [p for p in root.iterdir() if p not in runs.values()]
    return runs


def expected_plans(steps: int, replan_every: int | None) -> int:
    """Plans an episode of ``steps`` steps gets: 1 open loop, else ``ceil(steps / K)`` (at steps 0, K, 2K, ...)."""
    return 1 if replan_every is None else math.ceil(steps / replan_every)


def test_plan_shapes_cover_the_tasks():
    for maze, longest in {"medium": 169, "large": 325, "giant": 511}.items():
        horizon, stride = plan_shape(f"pointmaze-{maze}-navigate-v0", "cpu-small")
        assert horizon % 4 == 0 and span(horizon, stride) >= 1.25 * longest  # the data's pace: see plans.py
    assert cfg.plan_shape(NAME, "cpu-small") == (32, 8)
    assert span(*cfg.plan_shape("pointmaze-large-stitch-v0", "cpu-small")) <= 201  # within a stitch episode
    config = cfg.preset_config(NAME, "cpu-small")
    assert config.layout is KINEMATIC_POINT and config.run_name().startswith(NAME + "-ddpm-")
    assert cfg.preset_config(NAME, "diffuser").process == DDPM(steps=256)
    with pytest.raises(BridgeplanError, match="does not fit pointmaze-medium-stitch-v0"):
        cfg.preset_config("pointmaze-medium-stitch-v0", "cpu-small", horizon=32)  # 249 steps > 201
    with pytest.raises(BridgeplanError, match="unknown OGBench pointmaze dataset"):
        cfg.preset_config("pointmaze-small-navigate-v0", "cpu-small")


def test_training_reads_the_episodes(navigate, point_runs):
    from bridgeplan.envs.ogbench_pointmaze.reading import load_stream

    stream = load_stream(navigate, NAME)
    assert stream.layout is KINEMATIC_POINT and stream.segment_starts.tolist() == [0, 60, 120, 180]
    assert len(stream) == 240  # every row: windows never cross an episode's end
    saved = json.loads((point_runs["flow"] / "config.json").read_text())["config"]
    assert saved["maze"] == NAME and Path(saved["dataset"]).name == f"{NAME}.npz"
    assert (saved["horizon"], saved["stride"], saved["prior"]) == (8, 4, "line")


def test_training_refuses_a_maze2d_dataset(tiny_dataset, tmp_path, capsys):
    assert main(["train", "--maze", NAME, "--dataset", tiny_dataset, "--preset", "cpu-small", *SHAPE, "--steps",
                 "1", "--run-dir", str(tmp_path / "run"), "--no-progress"]) == 2
    assert capsys.readouterr().err.startswith("error: ") and not (tmp_path / "run").exists()


@pytest.mark.parametrize("process", list(PROCESSES))
def test_eval_through_the_protocol(process, point_runs, tmp_path, capsys):
    out = tmp_path / "eval.json"
    extra = ["--controller", "pursuit", "--replan-every", "300"] if process == "flow" else []
    assert main(["eval", str(point_runs[process]), "--episodes", "1", "--nfe", "2",
                 "--out", str(out), "--no-progress", "--device", "cpu", *extra]) == 0
    assert "overall:" in capsys.readouterr().out
    r = json.loads(out.read_text())
    assert sorted(r["tasks"]) == ["1", "2", "3", "4", "5"]
    assert all(0 <= t["success_rate"] <= 1 and t["episodes"] == 1 for t in r["tasks"].values())
    assert 0 <= r["success_rate"] <= 1 and 0 <= r["floor_line"]["success_rate"] <= 1
    assert (r["nfe"], r["episodes_per_task"], r["run"]) == (2, 1, point_runs[process].name)
    assert r["dataset"].startswith(f"{NAME}.npz ({NAME}, 240 transitions")  # the data's identity
    assert r["prior"] == r["config"]["prior"] and "/" not in r["config"]["prior_run"]
    assert r["config"]["dataset"] == f"{NAME}.npz" and r["environment"]["code_version"]
    assert r["environment"]["cpu"] == cpu_model()  # the same seeds give other episodes on another CPU
    steps = [s for t in r["tasks"].values() for s in t["steps"]]
    k = r["execution"]["replan_every"]
    assert r["plans_per_episode"]["max"] == max(expected_plans(s, k) for s in steps)
    assert r["calls_per_episode"] == 2 * r["plans_per_episode"]["mean"] and r["plan_ms_per_plan"] > 0
    assert "/" + "work" not in out.read_text().replace(str(tmp_path), "")  # no absolute path but the output's


def _drive(policy, steps: int) -> None:
    """``policy`` in OGBench's own loop on task 1 for ``steps`` steps: the observation and ``info["goal"]`` in."""
    env = make_env("medium")
    obs, info = env.reset(seed=0, options=dict(task_id=1))
    policy.reset()
    for _ in range(steps):
        action = policy(obs, info["goal"])
        assert action.shape == (2,) and action.dtype == np.float32 and np.abs(action).max() <= 1
        obs, *_ = env.step(action)
    env.close()
    assert policy.steps == steps


@pytest.mark.parametrize("every", [None, 7])
def test_a_run_as_a_policy_in_ogbenchs_own_loop(point_runs, every):
    """``PlannerPolicy.from_run`` of an OGBench run plans with its family's goal radius and wall map, a plan every K
    steps (once, open loop)."""
    policy = PlannerPolicy.from_run(point_runs["bridge"], replan_every=every, device="cpu")
    assert (policy.env, policy.maze, policy.execution.controller) == (NAME, None, "track")
    (source,) = policy.executor.sources
    assert source.radius == FAMILY.goal_radius and source.free is not None
    _drive(policy, 20)
    assert policy.plans_made == expected_plans(20, every)


@pytest.mark.parametrize("argv, message", [
    (["eval", "{maze2d}", "--tasks", "1,2"], "Maze2D has no task suite to choose from (--tasks)"),
    (["eval", "{point}", "--multi-task"], "OGBench's protocol has its 5 tasks, no Multi2D"),
    (["hierarchy", "eval", "{point}", "{maze2d}", "--replan-every", "12"], "trained on different environments"),
    (["graph", "--low", "{maze2d}", "--maze", NAME, "--replan-every", "12"], "the low level was trained on umaze"),
    (["graph", "--maze", NAME, "--dataset", "{maze2d_data}"], "is a folder, not an npz file"),
    (["graph", "--maze", "umaze", "--dataset", "{navigate}"], "is an npz file (OGBench's format), not a Maze2D"),
    (["render", "{point}", "--episodes", "1"], "render draws Maze2D's and OGBench manipulation's episodes"),
    (["graph", "--maze", NAME, "--dataset", "{navigate}", "--render"], "--render: OGBench pointmaze episodes cannot"),
    (["oracle", "mars", "--episodes", "1"], "unknown environment 'mars'"),
    (["data", "info", "{navigate}", "--maze", "maze9"], "unknown environment 'maze9'"),
    (["graph", "--maze", "antmaze-medium-navigate-v0", "--dataset", "{navigate}"], "unknown environment"),
])
def test_one_family_on_anothers_tasks_or_data_is_one_error(argv, message, point_runs, tiny_runs, tiny_dataset,
                                                          navigate, tmp_path, capsys):
    """A run of one family on another's tasks, a dataset of another family, an unknown environment: one ``error:``
    line, exit 2, nothing written."""
    paths = {"maze2d": tiny_runs["ddpm"], "point": point_runs["ddpm"], "navigate": navigate,
             "maze2d_data": tiny_dataset}
    before = {p: sorted(q.name for q in Path(p).rglob("*")) for p in (tiny_runs["ddpm"], point_runs["ddpm"])}
    out = tmp_path / "out.json"
    argv = [a.format(**paths) for a in argv]
    code = main([*argv, *(["--out", str(out)] if argv[0] != "data" else []),
                 *(["--device", "cpu"] if argv[0] not in ("data", "oracle") else [])])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
    assert not out.exists() and {p: sorted(q.name for q in Path(p).rglob("*")) for p in before} == before


def test_a_step_of_the_environment_is_gain_times_the_action():
    env = make_env("medium")
    ob, _ = env.reset(seed=0, options=dict(task_id=1))
    a = np.array([0.5, -0.25])
    ob2, *_ = env.step(a)
    np.testing.assert_allclose(ob2 - ob, GAIN * a, atol=1e-6)  # task 1 starts in a free cell, clear of walls


def test_tracking_reproduces_a_straight_constant_speed_plan():
    v = np.array([[0.15, -0.05], [0.0, 0.19]])  # per step, within one step's reach per axis
    p0 = np.array([[1.0, 2.0], [-3.0, 0.5]])
    plans = p0[:, None] + np.arange(20)[None, :, None] * v[:, None]
    follower = Follower(2, BODY, "track")
    p = p0.copy()
    for t in range(19):
        a = follower.actions(p, plans, np.full(2, t))
        np.testing.assert_allclose(a, v / GAIN)
        p = p + GAIN * a  # free space: the environment's step
    np.testing.assert_allclose(p, plans[:, -1])
    # past the plan's end the target is its last position
    np.testing.assert_array_equal(tracking_targets(plans, np.array([40, 18]), KINEMATIC_POINT), plans[:, -1])


def test_actions_clip_and_pursuit_keeps_its_direction():
    np.testing.assert_allclose(step_action(np.zeros((1, 2)), np.array([[1.0, 0.1]])), [[1.0, 0.5]])
    np.testing.assert_allclose(step_action(np.zeros((1, 2)), np.array([[-3.0, 3.0]])), [[-1.0, 1.0]])
    far = pursuit_action(np.zeros((1, 2)), np.array([[3.0, 1.0]]))
    np.testing.assert_allclose(far, [[3.0, 1.0]] / np.sqrt(10.0))  # a unit step toward it, not a diagonal
    near = pursuit_action(np.zeros((1, 2)), np.array([[0.1, -0.05]]))
    np.testing.assert_allclose(GAIN * near, [[0.1, -0.05]])  # lands on it
    # the waypoint is the first planned position a lookahead away, and progress along the plan never goes back
    plans = np.stack([np.linspace(0, 4, 21), np.zeros(21)], axis=1)[None]
    f = Follower(1, BODY, "pursuit", lookahead=1.0)
    np.testing.assert_allclose(f.actions(np.zeros((1, 2)), plans, np.zeros(1)), [[1.0, 0.0]])
    assert f.passed.tolist() == [5]
    f.actions(np.array([[-2.0, 0.0]]), plans, np.ones(1))
    assert f.passed.tolist() == [5]
    # a point that does not move (stopped by a wall) follows the plan's schedule: the waypoint moves on
    f.actions(np.array([[-2.0, 0.0]]), plans, np.full(1, 11))
    assert f.passed.tolist() == [12]
    with pytest.raises(BridgeplanError, match="--controller"):
        Follower(1, BODY, "hold")


class _LinePlanner:
    """A stand-in planner: a straight line from start to goal over a fixed span; counts its calls."""

    layout = KINEMATIC_POINT
    process = DDPM(steps=4)
    stride, horizon = 1, 30

    def __init__(self, steps: int = 30):
        self.steps, self.calls, self.planned = steps, 0, 0

    def plan(self, starts, goals, nfe, generator, prior_only=False, arrival=None):
        from bridgeplan.planner import Plan

        self.calls += 1
        self.planned += len(starts)
        frac = np.linspace(0, 1, self.steps)[None, :, None]
        states = starts[:, None] + frac * (goals - starts)[:, None]
        return Plan(states, np.zeros_like(states), 0.0, 1e-3)


def _executor(planner, every):
    execution = Execution(replan_every=every).resolved(FAMILY, NAME)
    return PlanExecutor(lambda n: PlanSource(planner, execution, 4, torch.Generator(), n, FAMILY.goal_radius),
                        lambda n: FAMILY.follower(NAME, n), every)


@pytest.mark.parametrize("every", [None, 1, 7, 50])
def test_replanning_plans_every_k_steps(every):
    planner = _LinePlanner()
    executor = _executor(planner, every)
    executor.begin(3)
    obs, goals = np.zeros((3, 2)), np.full((3, 2), 100.0)  # never reached
    for step in range(100):
        if step == 40:
            executor.end(np.array([2]))  # an episode that ended plans no more
        executor.act(obs, goals)
    assert executor.plans_made.tolist() == [expected_plans(100, every)] * 2 + [expected_plans(40, every)]
    assert planner.calls == expected_plans(100, every)  # the due episodes of a step share one batch
    assert expected_plans(100, 7) == math.ceil(100 / 7) == 15


def test_replanning_through_the_protocol():
    planner = _LinePlanner()
    executor = _executor(planner, 25)
    r = FAMILY.run(FAMILY.tasks(NAME, 2, task_ids=(1, 3)), executor)
    steps = [s for t in r.tasks.values() for s in t.steps]
    assert min(steps) < 1000 == max(steps)  # the line reaches task 1's goal by sliding along walls, not task 3's
    assert executor.plans_made.tolist() == [math.ceil(s / 25) for s in steps]
    assert planner.planned == sum(executor.plans_made)


def test_eval_settings_are_checked(point_runs, capsys):
    run = str(point_runs["ddpm"])
    for flags in (["--replan-every", "0"], ["--controller", "hold"], ["--lookahead", "1"],
                  ["--controller", "pursuit", "--lookahead", "0"], ["--episodes", "0"], ["--tasks", "1,11"]):
        assert main(["eval", run, "--no-progress", *flags]) == 2
        assert capsys.readouterr().err.startswith("error: ")
    assert not (point_runs["ddpm"] / "eval").exists()


def test_a_hierarchy_on_the_protocol(navigate, tmp_path, capsys):
    """`hierarchy eval` on OGBench: a high level of 4 states 12 steps apart, a low level of 10 states 4 apart through
    every 3rd (one high-level step); the low level replanned every 12 steps, the high level once and every 24."""
    import json

    runs = {"high": ("--process", "ddpm", "--horizon", "4", "--stride", "12"),
            "low": ("--process", "flow", "--prior", "coarse", "--horizon", "10", "--stride", "4",
                    "--subgoal-every", "3")}
    for name, flags in runs.items():
        assert main(["train", "--maze", NAME, "--dataset", str(navigate), "--preset", "cpu-small", "--steps", "2",
                     "--checkpoint-every", "2", "--run-dir", str(tmp_path / name), "--device", "cpu", "--no-progress",
                     "--dim", "8", "--dim-mults", "1,2", *flags]) == 0
    args = ["hierarchy", "eval", str(tmp_path / "high"), str(tmp_path / "low"), "--nfe-high", "2",
            "--nfe-low", "1", "--replan-every", "12", "--episodes", "1", "--tasks", "1,3", "--device", "cpu",
            "--no-progress", "--controller", "pursuit"]
    assert main([*args, "--out", str(tmp_path / "h.json")]) == 0
    r = json.loads((tmp_path / "h.json").read_text())
    assert r["kind"] == "hierarchy" and r["method"].startswith("hierarchy DDPM H4k12 -> flow (coarse) H10k4")
    assert (r["high"]["nfe"], r["low"]["nfe"], r["nfe"], r["episodes"]) == (2, 1, 1, 2)
    assert set(r["tasks"]) == {"1", "3"}
    steps = [sum(t["steps"]) for t in r["tasks"].values()]
    # every episode: one coarse plan (2 calls) and a low-level plan every 12 steps it ran (1 call each)
    assert r["calls_per_episode"] == pytest.approx((2 * 2 + sum(-(-s // 12) for s in steps)) / 2)
    assert r["plans_per_episode"]["mean"] == pytest.approx(sum(-(-s // 12) for s in steps) / 2)
    assert 0 <= r["success_rate"] <= 1 and "floor_line" in r and r["decision_ms_batch1"]["p50"] > 0
    assert main([*args, "--replan-high-every", "24", "--out", str(tmp_path / "h24.json")]) == 0
    r24 = json.loads((tmp_path / "h24.json").read_text())
    assert r24["replan_high_every"] == 24 and r24["calls_per_episode"] > r["calls_per_episode"]
    assert main([*args[:-2], "--controller", "track", "--replan-every", "0"]) == 2  # bad K: one error line
    assert main(["hierarchy", "eval", str(tmp_path / "low"), str(tmp_path / "high"), "--replan-every", "12",
                 "--device", "cpu"]) == 2
    assert "must plan from a start to a goal" in capsys.readouterr().err
    policy = PlannerPolicy.from_hierarchy(tmp_path / "high", tmp_path / "low", nfe_high=2, nfe_low=1,
                                          replan_every=12, controller="pursuit", device="cpu")  # as a policy
    assert (policy.env, policy.maze) == (NAME, None)
    _drive(policy, 30)
    assert policy.plans_made == 3  # low-level plans at steps 0, 12 and 24
