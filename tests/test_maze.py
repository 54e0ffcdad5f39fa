"""Layouts, tasks, the expert, the tracking controller, rollouts and the normalized score."""

from __future__ import annotations

import numpy as np
import pytest

from bridgeplan.envs.controllers import Follower, pursuit_waypoints, tracking_targets
from bridgeplan.envs.maze2d.controllers import (
    BODY,
    tracking_action,
)
from bridgeplan.envs.maze2d.expert import WaypointExpert, shortest_path, waypoints
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, MAZE_NAMES, get_maze
from bridgeplan.envs.maze2d.reference import CONVENTIONS, load_reference_returns, normalized_score, reference_bounds
from bridgeplan.envs.maze2d.rollout import rollout
from bridgeplan.envs.maze2d.sim import make_gym_env
from bridgeplan.envs.maze2d.tasks import MazeTasks, sample_tasks
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import execute_plans
from bridgeplan.replan import Execution
from bridgeplan.trajectory import MAZE2D


def _execute(maze, starts, goals, plans, controller="track"):
    return execute_plans(MazeTasks.of(maze, starts, goals), plans, Execution(controller=controller))


@pytest.mark.parametrize("name", MAZE_NAMES)
def test_layout_and_coordinates_match_gymnasium_robotics(name):
    maze = get_maze(name)
    gym_maze = make_gym_env(maze).unwrapped.maze
    assert [list(r) for r in maze.grid] == [[int(c) for c in r] for r in gym_maze.maze_map]
    for cell in maze.free_cells:
        xy = maze.cell_to_xy(cell)
        np.testing.assert_allclose(xy, gym_maze.cell_rowcol_to_xy(cell), atol=1e-12)
        for offset in ([0.49, 0.49], [-0.49, -0.49], [0.3, -0.2]):
            p = xy + offset
            np.testing.assert_array_equal(maze.xy_to_cell(p), gym_maze.cell_xy_to_rowcol(p))
        assert maze.is_free_xy(xy)
    assert not maze.is_free_xy(maze.cell_to_xy([0, 0]))
    assert not maze.is_free_xy([np.nan, 0.0])
    assert maze.grid[maze.eval_goal_cell[0]][maze.eval_goal_cell[1]] == 0
    assert maze.episode_steps == {"open": 300, "umaze": 300, "medium": 600, "large": 800}[name]


def test_eval_goals_and_unknown_maze():
    assert {n: get_maze(n).eval_goal_cell for n in MAZE_NAMES} == {
        "open": (2, 3), "umaze": (1, 1), "medium": (6, 6), "large": (7, 9)}
    with pytest.raises(BridgeplanError, match="unknown maze 'maze9': choose from open, umaze, medium, large"):
        get_maze("maze9")


@pytest.mark.parametrize("multi_task", [False, True])
def test_sample_tasks(multi_task):
    maze = get_maze("medium")
    starts, goals = sample_tasks(maze, 500, seed=5, multi_task=multi_task)
    again = sample_tasks(maze, 500, seed=5, multi_task=multi_task)
    np.testing.assert_array_equal(starts, again[0])
    np.testing.assert_array_equal(goals, again[1])
    assert not np.array_equal(starts, sample_tasks(maze, 500, seed=6, multi_task=multi_task)[0])
    start_cells, goal_cells = maze.xy_to_cell(starts), maze.xy_to_cell(goals)
    assert maze.is_free_cell(start_cells).all() and maze.is_free_cell(goal_cells).all()
    assert (start_cells != goal_cells).any(axis=1).all()
    for xy, cells in ((starts, start_cells), (goals, goal_cells)):
        assert np.abs(xy - maze.cell_to_xy(cells)).max() <= 0.25
    if multi_task:
        assert len(np.unique(goal_cells, axis=0)) > 10
    else:
        assert (goal_cells == maze.eval_goal_cell).all()
    assert len(np.unique(start_cells, axis=0)) == len(maze.free_cells) - (0 if multi_task else 1)
    with pytest.raises(BridgeplanError):
        sample_tasks(maze, 0, seed=0)


def test_shortest_path_and_waypoints():
    maze = get_maze("umaze")
    path = shortest_path(maze, (1, 1), (3, 1))
    assert path == [(1, 1), (1, 2), (1, 3), (2, 3), (3, 3), (3, 2), (3, 1)]
    assert shortest_path(maze, (1, 1), (1, 1)) == [(1, 1)]
    with pytest.raises(BridgeplanError, match="wall"):
        shortest_path(maze, (0, 0), (1, 1))
    goal = np.array([-1.1, -0.9])
    w = waypoints(maze, maze.cell_to_xy((1, 1)), goal)
    np.testing.assert_allclose(w[:-1], maze.cell_to_xy(np.array(path[1:-1])))
    np.testing.assert_array_equal(w[-1], goal)
    jittered = waypoints(maze, maze.cell_to_xy((1, 1)), goal, jitter=0.2, rng=np.random.default_rng(0))
    shift = jittered - w
    assert (shift[:-1] <= 0).all() and (shift[:-1] >= -0.2).all() and (shift[-1] == 0).all()


@pytest.mark.parametrize("name", MAZE_NAMES)
def test_expert_reaches_goal_from_every_free_cell(name):
    """Noise-free, batched: from every free cell to the evaluation goal and to a random other goal."""
    maze = get_maze(name)
    rng = np.random.default_rng(0)
    free = maze.free_cells
    starts = np.concatenate([maze.cell_to_xy(free)] * 2) + rng.uniform(-0.25, 0.25, (2 * len(free), 2))
    eval_goals = np.repeat(maze.eval_goal_xy[None], len(free), axis=0)
    other = free[(np.arange(len(free)) + 1 + rng.integers(len(free) - 1, size=len(free))) % len(free)]
    goals = np.concatenate([eval_goals, maze.cell_to_xy(other)])
    goals += rng.uniform(-0.25, 0.25, (2 * len(free), 2))
    expert = WaypointExpert(maze)
    expert.plan(starts, goals)
    result = rollout(maze, lambda t, obs: expert(obs), starts, goals)
    assert result.success.all()
    # it stays there: the last state is within the goal radius
    assert (np.linalg.norm(result.states[:, -1, :2] - goals, axis=1) <= GOAL_RADIUS).all()
    assert result.states.shape == (2 * len(free), maze.episode_steps + 1, 4)
    assert result.actions.shape == (2 * len(free), maze.episode_steps, 2)
    assert np.abs(result.actions).max() <= 1.0


def test_stale_expert_drives_straight_at_the_goal():
    maze = get_maze("umaze")
    start, goal = maze.cell_to_xy([[3, 1]]), maze.cell_to_xy([[1, 1]])
    expert = WaypointExpert(maze)
    expert.plan(start, goal)
    expert.exhaust()
    obs = np.concatenate([start, [[0.0, 0.0]]], axis=1)
    np.testing.assert_array_equal(expert(obs), [[0.0, 1.0]])  # straight up, into the wall
    assert not rollout(maze, lambda t, o: expert(o), start, goal, steps=300).success[0]


def test_tracking_controller():
    state = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    nxt = np.array([[0.1, 0.2, 1.5, -0.1], [5.0, -5.0, 0.0, 0.0]])
    np.testing.assert_allclose(tracking_action(state, nxt), [[0.6, 0.1], [1.0, -1.0]])
    plans = np.arange(2 * 3 * 4, dtype=float).reshape(2, 3, 4)
    at = lambda t: np.full(2, t)  # noqa: E731
    np.testing.assert_array_equal(tracking_targets(plans, at(0), MAZE2D), plans[:, 1])
    held = tracking_targets(plans, at(2), MAZE2D)
    np.testing.assert_array_equal(held[:, :2], plans[:, -1, :2])
    np.testing.assert_array_equal(held[:, 2:], 0.0)
    np.testing.assert_array_equal(tracking_targets(plans, at(50), MAZE2D), held)
    np.testing.assert_array_equal(Follower(2, BODY).actions(state, plans, at(0)), tracking_action(state, plans[:, 1]))


def test_tracking_controller_follows_a_plan_and_holds_the_end():
    maze = get_maze("open")
    start, goal = np.array([[-2.0, 0.0]]), np.array([[2.0, 0.0]])
    horizon = 100
    x = np.linspace(-2.0, 2.0, horizon)
    speed = 4.0 / (horizon - 1) / 0.01
    plan = np.stack([x, np.zeros(horizon), np.full(horizon, speed), np.zeros(horizon)], axis=1)
    result = _execute(maze, start, goal, plan[None])
    assert result.success[0]
    assert np.linalg.norm(result.states[0, -1, :2] - goal[0]) < 0.1  # held at the plan's end
    np.testing.assert_allclose(Follower(1, BODY).actions(np.zeros((1, 4)), plan[None], np.array([horizon + 5])),
                               np.clip(plan[-1:, :2], -1, 1))


def test_execute_plans_tracks_an_expert_trajectory():
    """Plans made of an expert's own states are tracked to the goal."""
    maze = get_maze("umaze")
    starts, goals = sample_tasks(maze, 8, seed=1)
    expert = WaypointExpert(maze)
    expert.plan(starts, goals)
    demo = rollout(maze, lambda t, obs: expert(obs), starts, goals, steps=250)
    assert demo.success.all()
    result = _execute(maze, starts, goals, demo.states)
    assert result.success.all()
    assert result.returns.min() > 100
    with pytest.raises(BridgeplanError, match="plans"):
        _execute(maze, starts, goals, demo.states[:, :, :2])


def test_pursuit_waypoint_is_the_first_unpassed_position_a_lookahead_away():
    xs = np.arange(13) * 0.25  # a straight plan along x, 0.25 apart
    plan = np.stack([xs, np.zeros(13), np.zeros(13), np.zeros(13)], axis=1)[None]
    at = lambda x: np.array([[x, 0.0]])  # noqa: E731
    xy = plan[..., :2]
    np.testing.assert_array_equal(pursuit_waypoints(xy, at(0.0), np.array([0]), 1.0), [4])  # x = 1.0
    np.testing.assert_array_equal(pursuit_waypoints(xy, at(0.6), np.array([4]), 1.0), [7])  # x = 1.75 >= 1.6
    # a passed position is never taken again, even when the point mass falls back behind it
    np.testing.assert_array_equal(pursuit_waypoints(xy, at(0.0), np.array([9]), 1.0), [9])
    # nothing far enough ahead: the plan's last position (the goal)
    np.testing.assert_array_equal(pursuit_waypoints(xy, at(2.5), np.array([10]), 1.0), [12])
    follower = Follower(1, BODY, "pursuit", lookahead=1.0)
    # the expert's PD law toward x = 1.0 from rest at the origin: clip(10 * 1.0 - 0) = 1
    np.testing.assert_allclose(follower.actions(np.zeros((1, 4)), plan, np.zeros(1, dtype=int)), [[1.0, 0.0]])
    np.testing.assert_allclose(follower.drift(np.array([[1.0, 0.3, 0, 0]]), plan, np.zeros(1, dtype=int)), [0.3])


def test_pursuit_runs_a_slowed_expert_path_at_the_expert_pace():
    """A plan that follows the expert's path at a third of its pace: tracked, it arrives late; pursued, it scores
    within a few steps of the expert itself (the path is the expert's, the pace the PD law's)."""
    maze = get_maze("umaze")
    starts, goals = sample_tasks(maze, 8, seed=1)
    expert = WaypointExpert(maze)
    expert.plan(starts, goals)
    demo = rollout(maze, lambda t, obs: expert(obs), starts, goals, steps=300)
    slow = np.repeat(demo.states, 3, axis=1)  # each state held for 3 steps
    slow[..., 2:] /= 3
    tracked = _execute(maze, starts, goals, slow)
    pursued = _execute(maze, starts, goals, slow, "pursuit")
    assert pursued.success.all()
    assert (pursued.returns >= demo.returns - 5).all()
    assert pursued.returns.mean() > tracked.returns.mean() + 50


def test_normalized_score():
    ref = load_reference_returns()
    assert set(ref) == set(MAZE_NAMES)
    for name in MAZE_NAMES:
        assert ref[name]["episodes"] == 100 and ref[name]["seed"] == 123
        assert ref[name]["expert"] > ref[name]["random"] and ref[name]["expert_stale"] > ref[name]["random"]
        for convention in CONVENTIONS:
            low, high = reference_bounds(name, convention)
            mean, se = normalized_score(name, [low, high], convention)
            assert mean == pytest.approx(50.0) and se == pytest.approx(50.0)
    returns = np.array([100.0, 150.0, 200.0, 250.0])
    low, high = reference_bounds("umaze", "minari")
    scores = 100 * (returns - low) / (high - low)
    mean, se = normalized_score("umaze", returns, "minari")
    assert mean == pytest.approx(scores.mean()) and se == pytest.approx(scores.std(ddof=1) / 2)
    assert np.isnan(normalized_score("umaze", [100.0], "d4rl")[1])
    with pytest.raises(BridgeplanError, match="unknown score convention 'd5rl'"):
        normalized_score("umaze", returns, "d5rl")
    with pytest.raises(BridgeplanError, match="unknown maze"):
        normalized_score("nomaze", returns, "minari")
    with pytest.raises(BridgeplanError):
        normalized_score("umaze", [], "minari")


def test_the_oracle_scores_the_evaluation_episodes(tmp_path, capsys):
    """``bridgeplan oracle``: Maze2D's expert, planning afresh, on evaluation tasks themselves: its score is the
    normalized mean return of those very episodes, one row per task set and seed, as the reports read them."""
    import json

    from bridgeplan.cli import main

    out = tmp_path / "expert.json"
    assert main(["oracle", "umaze", "--episodes", "6", "--seeds", "0,3", "--task-sets", "single,multi",
                 "--out", str(out), "--no-progress"]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [(r["maze"], r["multi_task"], r["seed"], r["episodes"]) for r in rows] == [
        ("umaze", False, 0, 6), ("umaze", False, 3, 6), ("umaze", True, 0, 6), ("umaze", True, 3, 6)]
    maze = get_maze("umaze")
    starts, goals = sample_tasks(maze, 6, 3)
    expert = WaypointExpert(maze)
    expert.plan(starts, goals)
    returns = rollout(maze, lambda t, obs: expert(obs), starts, goals).returns
    assert rows[1]["score"]["minari"]["mean"] == pytest.approx(normalized_score("umaze", returns, "minari")[0])
    assert rows[1]["success_rate"]["mean"] == 1.0 and rows[1]["policy"] == "oracle"
    assert "umaze single seed 3:" in capsys.readouterr().out
