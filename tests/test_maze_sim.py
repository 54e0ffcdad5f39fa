"""The batched simulator against the real gymnasium-robotics environment."""

from __future__ import annotations

import numpy as np
import pytest

from bridgeplan.envs.maze2d.grids import MAZE_NAMES, get_maze
from bridgeplan.envs.maze2d.sim import BatchedPointMaze, make_gym_env
from bridgeplan.envs.maze2d.tasks import sample_tasks
from bridgeplan.errors import BridgeplanError


def test_reset_places_start_and_goal():
    maze = get_maze("umaze")
    starts, goals = sample_tasks(maze, 5, seed=3)
    sim = BatchedPointMaze(maze, 5)
    obs = sim.reset(starts, goals)
    np.testing.assert_array_equal(obs[:, :2], starts)
    np.testing.assert_array_equal(obs[:, 2:], 0.0)
    np.testing.assert_array_equal(sim.goals, goals)
    for d, s in zip(sim.datas, starts):
        np.testing.assert_array_equal(d.qpos, s)
    # starting on the goal earns reward from the first step; far away earns nothing
    obs, reward = sim.step(np.zeros((5, 2)))
    assert reward.tolist() == [0.0] * 5
    sim.reset(goals, goals)
    assert sim.step(np.zeros((5, 2)))[1].tolist() == [1.0] * 5


@pytest.mark.parametrize("name", ["umaze", "large"])
def test_batched_sim_matches_gym_env(name):
    """Same start, same actions (some outside [-1, 1], many wall contacts): same states and rewards."""
    maze = get_maze(name)
    n = 3
    starts, goals = sample_tasks(maze, n, seed=7, multi_task=True)
    sim = BatchedPointMaze(maze, n)
    sim.reset(starts, goals)
    envs = []
    for k in range(n):
        env = make_gym_env(maze, continuing_task=True, reset_target=False)
        env.reset(seed=k)
        env.unwrapped.goal = goals[k].copy()
        env.unwrapped.point_env.set_state(starts[k].copy(), np.zeros(2))
        envs.append(env)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(300):
        actions = rng.uniform(-1.5, 1.5, size=(n, 2))
        obs, reward = sim.step(actions)
        for k, env in enumerate(envs):
            o, r, *_ = env.step(actions[k])
            worst = max(worst, float(np.abs(o["observation"] - obs[k]).max()))
            assert r == reward[k]
    assert worst <= 1e-9
    for env in envs:
        env.close()


def test_batched_sim_matches_env_reset_and_step():
    """The env places start and goal itself (reset options); the sim starts from its observation."""
    maze = get_maze("medium")
    env = make_gym_env(maze, continuing_task=True, reset_target=False)
    obs, _ = env.reset(seed=0, options={"reset_cell": np.array([1, 1]), "goal_cell": np.array([6, 6])})
    sim = BatchedPointMaze(maze, 1)
    np.testing.assert_array_equal(sim.reset(obs["observation"][None, :2], obs["desired_goal"][None])[0],
                                  obs["observation"])
    rng = np.random.default_rng(1)
    for _ in range(300):
        action = rng.uniform(-1.5, 1.5, size=2)
        o, r, *_ = env.step(action)
        so, sr = sim.step(action[None])
        assert np.abs(so[0] - o["observation"]).max() <= 1e-9 and sr[0] == r
    env.close()


def test_velocity_is_clipped_like_point_env():
    maze = get_maze("open")
    sim = BatchedPointMaze(maze, 1)
    sim.reset([[0.0, 0.0]], [[2.0, 0.0]], velocities=[[9.0, -9.0]])
    obs, _ = sim.step(np.zeros((1, 2)))
    # the velocity was clipped to 5 before the step; damping then slows it a little
    assert 4.0 < obs[0, 2] <= 5.0 and -5.0 <= obs[0, 3] < -4.0


@pytest.mark.parametrize("name", MAZE_NAMES)
def test_start_or_goal_in_wall_is_rejected(name):
    maze = get_maze(name)
    wall = maze.cell_to_xy([0, 0])
    free = maze.cell_to_xy(maze.free_cells[0])
    sim = BatchedPointMaze(maze, 1)
    with pytest.raises(BridgeplanError, match="inside a wall"):
        sim.reset([wall], [free])
    with pytest.raises(BridgeplanError, match="goal"):
        sim.reset([free], [wall])
    with pytest.raises(BridgeplanError, match="outside"):
        sim.reset([[100.0, 0.0]], [free])
    with pytest.raises(BridgeplanError, match="shape"):
        sim.reset([free, free], [free, free])
    with pytest.raises(BridgeplanError):
        BatchedPointMaze(maze, 0)
