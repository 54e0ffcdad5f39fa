"""OGBench pointmaze evaluation protocol: tasks, batching, seeds, errors, the oracle policy, the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bridgeplan.cli import main
from bridgeplan.envs.ogbench_data import legacy_rng
from bridgeplan.envs.ogbench_pointmaze.maze import Oracle, make_env
from bridgeplan.envs.ogbench_pointmaze.protocol import (
    EVAL_EPISODES_PER_TASK,
    TASK_IDS,
    OracleAgent,
    episode_seed,
    evaluate_policy,
)
from bridgeplan.errors import BridgeplanError


def test_protocol_constants():
    assert EVAL_EPISODES_PER_TASK == 50 and TASK_IDS == (1, 2, 3, 4, 5)
    assert make_env("giant").spec.max_episode_steps == 1000


def test_oracle_one_episode_per_task():
    r = evaluate_policy("medium", OracleAgent("medium").act, episodes_per_task=1, seed=0)
    assert list(r.tasks) == [1, 2, 3, 4, 5]
    assert r.tasks[1].init_cell == (1, 1) and r.tasks[1].goal_cell == (6, 6)
    for t in r.tasks.values():
        assert t.episodes == 1 and 0 <= t.success_rate <= 1 and t.successes in (0, 1)
        assert 0 < t.steps[0] <= 1000
        assert t.successes == (t.steps[0] < 1000)  # the env terminates at the goal
    assert 0 <= r.success_rate <= 1 and r.episodes == 5
    assert r.success_rate == np.mean([t.success_rate for t in r.tasks.values()])
    d = r.to_dict()
    assert json.loads(json.dumps(d))["tasks"]["1"]["episodes"] == 1


def _plain_episode(maze: str, task: int, seed: int, act) -> tuple[bool, int]:
    """One episode as OGBench's evaluate() runs it, with env.step one at a time."""
    env = make_env(maze)
    with legacy_rng(seed):
        ob, info = env.reset(seed=seed, options=dict(task_id=task))
        goal, done, steps = info["goal"], False, 0
        while not done:
            action = np.clip(act(ob[None], goal[None])[0], -1, 1)
            ob, _, terminated, truncated, info = env.step(action)
            done, steps = terminated or truncated, steps + 1
    return info["success"] == 1.0, steps


def test_batched_equals_one_env_at_a_time():
    # teleport: its env draws from the global RNG inside step(), so interleaved episodes must not share it
    act = OracleAgent("teleport").act
    r = evaluate_policy("teleport", act, episodes_per_task=2, seed=3, task_ids=[1, 3], batch_size=3)
    for t in (1, 3):
        plain = [_plain_episode("teleport", t, episode_seed(3, t, k), act) for k in range(2)]
        assert r.tasks[t].steps == [s for _, s in plain]
        assert r.tasks[t].successes == sum(ok for ok, _ in plain)
    one = evaluate_policy("teleport", act, episodes_per_task=2, seed=3, task_ids=[1, 3], batch_size=1)
    assert [t.steps for t in one.tasks.values()] == [t.steps for t in r.tasks.values()]
    other = evaluate_policy("teleport", act, episodes_per_task=2, seed=4, task_ids=[1, 3])
    assert [t.steps for t in other.tasks.values()] != [t.steps for t in r.tasks.values()]


def test_actions_are_clipped():
    oracle = OracleAgent("medium").act

    def act(obs, goals):
        return 10 * oracle(obs, goals)

    r = evaluate_policy("medium", act, episodes_per_task=1, seed=2, task_ids=[4])
    assert r.tasks[4].steps == [_plain_episode("medium", 4, episode_seed(2, 4, 0), act)[1]]


def test_policy_sees_goals_and_a_standing_policy_fails():
    seen = []

    def stand(obs, goals):
        seen.append((obs.copy(), goals.copy()))
        return np.zeros_like(obs)

    r = evaluate_policy("large", stand, episodes_per_task=1, seed=0, task_ids=[1, 2])
    assert r.success_rate == 0 and all(t.steps == [1000] for t in r.tasks.values())
    obs, goals = seen[0]
    assert obs.shape == goals.shape == (2, 2)
    env = make_env("large").unwrapped
    for row, task in enumerate((1, 2)):
        info = env.task_infos[task - 1]
        assert np.all(np.abs(goals[row] - np.array(info["goal_xy"])) <= 1.0)  # +-1 goal noise
        assert np.all(np.abs(obs[row] - np.array(info["init_xy"])) <= 1.0)


def test_errors():
    act = OracleAgent("medium").act
    for bad in ([0], [11], [1, 12], []):
        with pytest.raises(BridgeplanError, match="task ids"):
            evaluate_policy("medium", act, episodes_per_task=1, task_ids=bad)
    with pytest.raises(BridgeplanError, match="shape"):
        evaluate_policy("medium", lambda o, g: np.zeros(2), episodes_per_task=1, task_ids=[1])
    with pytest.raises(BridgeplanError, match="non-finite"):
        evaluate_policy("medium", lambda o, g: np.full_like(o, np.nan), episodes_per_task=1, task_ids=[1])
    with pytest.raises(BridgeplanError, match="unknown"):
        OracleAgent("umaze").act


def test_oracle_policy_is_the_unit_direction():
    act, oracle = OracleAgent("giant").act, Oracle("giant")
    obs = np.array([[0.3, 0.1], [9.0, 12.2]])
    goals = np.array([[52.0, 36.0], [0.0, 0.0]])
    a = act(obs, goals)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1, atol=1e-5)
    np.testing.assert_array_equal(a[1], oracle.direction(obs[1], goals[1]))


def test_cli_oracle(capsys):
    assert main(["oracle", "pointmaze-medium-navigate-v0", "--episodes", "1", "--tasks", "4", "--json",
                 "--no-progress"]) == 0
    (out,) = json.loads(capsys.readouterr().out)["rows"]
    assert list(out["tasks"]) == ["4"] and out["episodes"] == 1 and out["policy"] == "oracle"
    assert main(["oracle", "pointmaze-medium-navigate-v0", "--tasks", "11"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: task ids must be in 1..5") and err.count("\n") == 1


def test_validation_tasks_are_other_cells_than_the_test_tasks():
    """Five start-goal pairs per maze, drawn once (the same every time), none on a test task's cells, each at least as
    long (in cells, the oracle's walk) as the shortest test task."""
    from bridgeplan.envs.ogbench_pointmaze.maze import bfs
    from bridgeplan.envs.ogbench_pointmaze.protocol import VALIDATION_TASK_IDS, validation_tasks

    for maze in ("medium", "large", "giant"):
        env = make_env(maze).unwrapped
        tests = env.task_infos
        tasks = validation_tasks(env.maze_map, tests)
        assert [t["task_name"] for t in tasks] == [f"validation_task{i}" for i in VALIDATION_TASK_IDS]
        pairs = [(tuple(t["init_ij"]), tuple(t["goal_ij"])) for t in tasks]
        assert len(set(pairs)) == 5 and pairs == [(tuple(t["init_ij"]), tuple(t["goal_ij"]))
                                                  for t in validation_tasks(env.maze_map, tests)]
        test_cells = {tuple(t[k]) for t in tests for k in ("init_ij", "goal_ij")}
        assert not test_cells & {c for pair in pairs for c in pair}
        shortest = min(bfs(env.maze_map, tuple(t["init_ij"]))[0][tuple(t["goal_ij"])] for t in tests)
        assert all(env.maze_map[c] == 0 for pair in pairs for c in pair)
        assert all(bfs(env.maze_map, a)[0][b] >= shortest for a, b in pairs)


def test_the_protocol_runs_the_validation_tasks_by_their_ids():
    from bridgeplan.envs.ogbench_pointmaze.protocol import validation_tasks

    env = make_env("medium").unwrapped
    expected = validation_tasks(env.maze_map, env.task_infos)
    r = evaluate_policy("medium", OracleAgent("medium").act, episodes_per_task=1, seed=0, task_ids=[6, 10])
    assert list(r.tasks) == [6, 10]
    for task_id, task in ((6, expected[0]), (10, expected[4])):
        assert (r.tasks[task_id].init_cell, r.tasks[task_id].goal_cell) == (tuple(task["init_ij"]),
                                                                            tuple(task["goal_ij"]))
        assert r.tasks[task_id].task_name == task["task_name"]
    assert r.success_rate == 1.0  # the oracle reaches other goals as well as the test tasks'
    with pytest.raises(BridgeplanError, match="6..10 .the validation tasks"):
        evaluate_policy("medium", OracleAgent("medium").act, episodes_per_task=1, task_ids=[11])
