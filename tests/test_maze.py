"""The Maze2D world: layouts, the batched simulator against gymnasium-robotics, expert, scores."""

from __future__ import annotations

import numpy as np
import pytest

from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.expert import WaypointExpert, shortest_path, tracking_actions
from bridgeplan.maze.layouts import MAZE_NAMES, get_maze
from bridgeplan.maze.reference import CONVENTIONS, load_reference_returns, normalized_score
from bridgeplan.maze.rollout import execute_plans, rollout
from bridgeplan.maze.sim import BatchedPointMaze, _gym_env
from bridgeplan.maze.tasks import sample_tasks


@pytest.mark.parametrize("name", MAZE_NAMES)
def test_layout_matches_gymnasium_robotics(name):
    maze = get_maze(name)
    env = _gym_env(maze.gym_id)
    assert [list(r) for r in maze.grid] == env.maze.maze_map
    for cell in maze.free_cells:
        assert np.allclose(maze.cell_to_xy(cell), env.maze.cell_rowcol_to_xy(cell))
        assert tuple(maze.xy_to_cell(maze.cell_to_xy(cell))) == tuple(cell)
    assert maze.is_free_cell(maze.eval_goal_cell)


def test_batched_sim_matches_env_step_exactly():
    import gymnasium as gym

    maze = get_maze("medium")
    env = gym.make(maze.gym_id, continuing_task=True, reset_target=False)
    obs, _ = env.reset(seed=0, options={"reset_cell": np.array([1, 1]), "goal_cell": np.array([6, 6])})
    sim = BatchedPointMaze(maze, 1)
    sim.reset(obs["observation"][None, :2], obs["desired_goal"][None])
    rng = np.random.default_rng(0)
    for _ in range(300):
        action = rng.uniform(-1.5, 1.5, size=2)  # out-of-range actions are clipped by both
        o, r, *_ = env.step(action)
        so, sr = sim.step(action[None])
        assert np.allclose(so[0], o["observation"], atol=1e-9, rtol=0) and sr[0] == r


def test_reset_to_given_start_and_goal():
    maze = get_maze("umaze")
    sim = BatchedPointMaze(maze, 2)
    starts, goals = np.array([[0.9, -0.9], [-1.0, 1.1]]), np.array([[-1.0, 1.0], [1.0, 1.0]])
    obs = sim.reset(starts, goals)
    assert np.array_equal(obs, np.concatenate([starts, np.zeros((2, 2))], axis=1))
    assert np.array_equal(sim.goals, goals)
    obs, reward = sim.step(np.zeros((2, 2)))
    assert np.allclose(obs[:, :2], starts) and np.array_equal(reward, [0.0, 0.0])
    with pytest.raises(BridgeplanError, match="inside a wall"):
        sim.reset(np.array([[0.0, 0.0], [-1.0, 1.0]]), goals)  # (0, 0) is the U's middle wall
    with pytest.raises(BridgeplanError, match="goal"):
        sim.reset(starts, np.array([[5.0, 5.0], [1.0, 1.0]]))


def test_tasks_single_and_multi():
    maze = get_maze("large")
    starts, goals = sample_tasks(maze, 300, seed=4)
    assert np.all(maze.xy_to_cell(goals) == maze.eval_goal_cell)
    assert np.all(np.abs(goals - maze.cell_to_xy(maze.eval_goal_cell)) <= 0.25)
    assert not np.any(np.all(maze.xy_to_cell(starts) == maze.eval_goal_cell, axis=1))
    assert len({tuple(c) for c in maze.xy_to_cell(starts)}) == len(maze.free_cells) - 1
    again = sample_tasks(maze, 300, seed=4)
    assert np.array_equal(again[0], starts) and np.array_equal(again[1], goals)
    ms, mg = sample_tasks(maze, 300, seed=4, multi_task=True)
    assert len({tuple(c) for c in maze.xy_to_cell(mg)}) > 10
    assert not np.any(np.all(maze.xy_to_cell(ms) == maze.xy_to_cell(mg), axis=1))


def test_shortest_path():
    maze = get_maze("umaze")
    assert shortest_path(maze, (1, 1), (3, 1)) == [(1, 1), (1, 2), (1, 3), (2, 3), (3, 3), (3, 2), (3, 1)]


@pytest.mark.parametrize("name", MAZE_NAMES)
def test_expert_reaches_goal_from_every_free_cell(name):
    maze = get_maze(name)
    free = maze.free_cells
    starts = maze.cell_to_xy(free)
    goals = np.repeat(maze.cell_to_xy(np.array(maze.eval_goal_cell))[None], len(free), axis=0)
    expert = WaypointExpert(maze)
    expert.reset(starts, goals)
    result = rollout(maze, lambda t, obs: expert(obs), starts, goals)
    assert result.success.all()
    # it stays at the goal once there: most of the episode earns reward from nearby cells
    assert result.returns.max() > 0.8 * maze.episode_steps


def test_tracking_controller_follows_a_plan_and_holds_the_end():
    maze = get_maze("open")
    start, goal = np.array([[-2.0, 0.0]]), np.array([[2.0, 0.0]])
    horizon = 100
    x = np.linspace(-2.0, 2.0, horizon)
    plan = np.stack([x, np.zeros(horizon), np.full(horizon, 4.0 / (horizon - 1) / 0.01), np.zeros(horizon)], axis=1)
    result = execute_plans(maze, start, goal, plan[None])
    assert result.success[0] == 1.0
    assert np.linalg.norm(result.states[0, -1, :2] - goal[0]) < 0.1  # held at the plan's end
    a = tracking_actions(np.zeros((1, 4)), plan[None], horizon + 5)
    assert np.allclose(a, np.clip(plan[-1, :2], -1, 1))


def test_normalized_score_conventions():
    ref = load_reference_returns()
    for name in MAZE_NAMES:
        r = ref[name]
        assert r["episodes"] >= 100 and r["random"] < r["expert"] and r["random"] < r["expert_stale"]
        for conv in CONVENTIONS:
            high = r["expert"] if conv == "minari" else r["expert_stale"]
            mean, se = normalized_score(name, [r["random"], high], conv)
            assert mean == pytest.approx(50.0) and se == pytest.approx(50.0)
    with pytest.raises(BridgeplanError, match="convention"):
        normalized_score("umaze", [1.0, 2.0], "atari")
    with pytest.raises(BridgeplanError, match="unknown maze"):
        get_maze("maze9")
