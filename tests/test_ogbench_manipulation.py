"""The OGBench manipulation family: names and columns, OGBench's play recipe at a tiny size, the protocol, bad input."""

from __future__ import annotations

import importlib.metadata
import json
import math
import warnings

import numpy as np
import pytest

pytest.importorskip("ogbench")

from bridgeplan.cli import main  # noqa: E402
from bridgeplan.envs import family_of  # noqa: E402
from bridgeplan.envs.ogbench_manipulation import FAMILY, protocol  # noqa: E402
from bridgeplan.envs.ogbench_manipulation.generate import generate_dataset, make_env  # noqa: E402
from bridgeplan.envs.ogbench_manipulation.names import parse_dataset_name  # noqa: E402
from bridgeplan.errors import BridgeplanError  # noqa: E402

NAMES = {"cube-single-play-v0": (28, 200), "cube-double-play-v0": (37, 500), "scene-play-v0": (40, 750),
         "puzzle-3x3-play-v0": (55, 500)}


@pytest.fixture(autouse=True)
def _headless(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "egl")


@pytest.mark.parametrize("name", NAMES)
def test_layout_and_goal_columns_are_the_environments(name):
    """Observation width and action width from the real environment; the goal's columns are exactly what ogbench's
    success reads (``compute_oracle_observation``), after some random steps."""
    assert family_of(name) is FAMILY
    layout = FAMILY.layout(name)
    env = make_env(parse_dataset_name(name).scene.env_id, mode="data_collection")
    ob, _ = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(20):
        ob, *_ = env.step(rng.uniform(-1, 1, 5))
    assert (layout.obs_dim, env.spec.max_episode_steps) == NAMES[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ogbench builds its action space anew at each access, casting float64 bounds
        space = env.action_space
    assert layout.act_dim == space.shape[0] == 5 and (space.low == -1).all() and (space.high == 1).all()
    np.testing.assert_allclose(ob[list(layout.goal)], env.unwrapped.compute_oracle_observation(), atol=1e-6)
    assert FAMILY.tasks(name).episode_steps == NAMES[name][1]


def test_the_recipe_at_a_tiny_size(tmp_path):
    """Sizes, OGBench's loader reads it back, the actions are the noisy oracle's (not constant, within [-1, 1], the
    gripper mostly at its bounds), the oracle reaches its targets, and the same identity is the cache."""
    from ogbench.utils import load_dataset

    made = generate_dataset("cube-single-play-v0", tmp_path, seed=3, episodes=4, episode_steps=201, progress=False)
    assert not made.cached
    train = load_dataset(str(made.train_path))  # drops each episode's last step (no next observation)
    val = load_dataset(str(made.val_path))
    assert train["observations"].shape == (4 * 200, 28) and val["observations"].shape == (1 * 200, 28)
    with np.load(made.train_path) as f:
        assert sorted(f.files) == ["actions", "observations", "qpos", "qvel", "terminals"]
        actions, terminals = f["actions"], f["terminals"]
    assert actions.shape == (804, 5) and np.flatnonzero(terminals).tolist() == [200, 401, 602, 803]
    # the oracle's actions (differences to its noisy plan, normalized): every axis used, centred, within [-1, 1]
    assert np.abs(actions).max() <= 1
    assert (0.1 < actions.std(axis=0)).all() and (actions.std(axis=0) < 0.9).all()
    assert (np.abs(actions.mean(axis=0)) < 0.25).all()
    t = made.record["targets"]
    assert t["done"] >= 8 and t["reached"] >= 0.8 * t["done"]
    again = generate_dataset("cube-single-play-v0", tmp_path, seed=3, episodes=4, episode_steps=201, progress=False)
    assert again.cached and again.record == made.record
    with pytest.raises(BridgeplanError, match="another identity"):
        generate_dataset("cube-single-play-v0", tmp_path, seed=4, episodes=4, episode_steps=201, progress=False)
    record = json.loads((tmp_path / "cube-single-play-v0.json").read_text())
    assert record["identity"]["noise"] == 0.1 and record["identity"]["noise_smoothing"] == 0.5
    assert record["made_with"]["mujoco"] == importlib.metadata.version("mujoco") and "mujoco" not in record["identity"]
    info, text = FAMILY.dataset_info(str(made.train_path), "cube-single-play-v0")
    assert info["episodes"] == 4 and info["sha256"] == record["files"]["cube-single-play-v0.npz"]
    with np.load(made.val_path) as f:  # a file changed since: not the dataset its record names, nor the cache
        changed = {k: f[k] for k in f.files}
    changed["actions"] = changed["actions"] * 0.5
    np.savez(made.val_path, **changed)
    with pytest.raises(BridgeplanError, match="is not the file its identity record cube-single-play-v0.json names"):
        FAMILY.dataset_info(str(made.val_path), "cube-single-play-v0")
    with pytest.raises(BridgeplanError, match="not this dataset"):
        generate_dataset("cube-single-play-v0", tmp_path, seed=3, episodes=4, episode_steps=201, progress=False)


def test_scene_health_check():
    from bridgeplan.envs.ogbench_manipulation.generate import healthy

    qpos = np.zeros((5, 20))
    qpos[:, 14:17] = [0.4, 0.0, 0.02]
    assert healthy(qpos)
    qpos[2, 15] = 0.3  # too far right
    assert not healthy(qpos)
    qpos[2, 15:17] = [-0.31, 0.07]  # far left, in the drawer
    assert healthy(qpos)
    qpos[2, 16] = 0.02  # far left on the table
    assert not healthy(qpos)


class _Zero:
    def __init__(self):
        self.ended = []

    def begin(self, n):
        pass

    def act(self, states, goals):
        assert goals.shape == states.shape  # the goal's whole observation; the layout names its task columns
        return np.zeros((len(states), 5))

    def end(self, rows):
        self.ended += list(rows)


def test_protocol_success_comes_from_the_environment(monkeypatch):
    """A task whose goal is its start succeeds at once (the environment ends the episode there); a real task is not
    done by standing still and runs to its limit."""
    env = make_env("cube-single-v0")
    trivial = dict(task_name="trivial", init_xyzs=np.array([[0.425, 0.1, 0.02]]),
                   goal_xyzs=np.array([[0.425, 0.1, 0.02]]))
    real = env.unwrapped.task_infos[0]
    monkeypatch.setattr(protocol, "validation_tasks", lambda spec, env: [trivial, real, real, real, real])
    tasks = FAMILY.tasks("cube-single-play-v0", episodes=1, task_ids=(6, 1))
    agent = _Zero()
    out = FAMILY.run(tasks, agent)
    assert out.tasks[6].successes == 1 and out.tasks[6].steps[0] < 5
    assert out.tasks[1].successes == 0 and out.tasks[1].steps == [200]
    assert sorted(agent.ended) == [0, 1]
    assert FAMILY.score(tasks, out)["success_rate"] == 0.5


class _Recorder:
    """A deterministic agent that moves as its states say and keeps every episode's states and goals (episodes in
    order)."""

    def __init__(self):
        self.batches, self.episodes, self.goals = [], [], []

    def begin(self, n):
        self.batches.append(n)
        self.rows = list(range(len(self.episodes), len(self.episodes) + n))
        self.episodes += [[] for _ in range(n)]
        self.goals += [None] * n
        self.active = np.ones(n, dtype=bool)

    def act(self, states, goals):
        for row, state, goal, active in zip(self.rows, states, goals, self.active):
            if active:
                self.episodes[row].append(state.copy())
                self.goals[row] = goal.copy()
        return np.tanh(3 * (states[:, 19:24] - states[:, 12:17]))

    def end(self, rows):
        self.active[rows] = False


def test_an_episode_does_not_depend_on_its_batch(monkeypatch):
    """The same episodes in batches of 3 and 1 (an environment reused by the next batch) and all 4 side by side: the
    same states, goals (the arm's part too: the random actions of ogbench's reset seeded), steps and successes
    episode by episode; at most BATCH environments are made."""
    env = make_env("cube-single-v0")
    trivial = dict(task_name="trivial", init_xyzs=np.array([[0.425, 0.1, 0.02]]),
                   goal_xyzs=np.array([[0.425, 0.1, 0.02]]))
    real = env.unwrapped.task_infos[0]
    monkeypatch.setattr(protocol, "validation_tasks", lambda spec, env: [trivial, real, real, real, real])
    made = []
    monkeypatch.setattr(protocol, "make_env", lambda env_id: made.append(env_id) or make_env(env_id))
    tasks = FAMILY.tasks("cube-single-play-v0", episodes=2, task_ids=(6, 1))
    runs = {}
    for batch in (3, 4):
        monkeypatch.setattr(protocol, "BATCH", batch)
        made.clear()
        agent = _Recorder()
        runs[batch] = FAMILY.run(tasks, agent), agent
        assert agent.batches == {3: [3, 1], 4: [4]}[batch] and len(made) == batch
    (chunked, small), (whole, large) = runs[3], runs[4]
    for t in (6, 1):
        assert chunked.tasks[t].successes == whole.tasks[t].successes
        assert chunked.tasks[t].steps == whole.tasks[t].steps
    assert whole.tasks[6].successes == 2 and whole.tasks[1].steps == [200] * 2
    for a, b in zip(small.episodes, large.episodes):
        np.testing.assert_array_equal(np.array(a), np.array(b))
    np.testing.assert_array_equal(np.array(small.goals), np.array(large.goals))
    starts = np.array([e[0] for e in large.episodes[2:]])  # task 1's episodes: each reset by its own seed
    assert len({s.tobytes() for s in starts}) == 2


def test_validation_tasks_are_fixed_and_not_the_test_tasks():
    for name in ("cube-double-play-v0", "puzzle-3x3-play-v0", "scene-play-v0"):
        spec = parse_dataset_name(name)
        env = make_env(spec.scene.env_id)
        a, b = protocol.validation_tasks(spec, env), protocol.validation_tasks(spec, env)
        assert [t["task_name"] for t in a] == [f"validation_task{i}" for i in range(6, 11)]
        assert repr(a) == repr(b)
        tests = {repr(t) for t in env.unwrapped.task_infos}
        assert not tests & {repr(t) for t in a}
    cubes = protocol.validation_tasks(parse_dataset_name("cube-double-play-v0"), make_env("cube-double-v0"))
    for t in cubes:
        assert np.linalg.norm(t["goal_xyzs"] - t["init_xyzs"], axis=1).min() >= protocol.MIN_MOVE
        assert np.linalg.norm(t["init_xyzs"][0] - t["init_xyzs"][1]) >= protocol.MIN_APART


def _error(capsys, argv) -> str:
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_bad_input(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    line = _error(capsys, ["data", "generate", "--maze", "cube-triple-play-v0", "--no-progress"])
    assert line == ("error: unknown OGBench manipulation dataset 'cube-triple-play-v0'; expected "
                    "{cube-single,cube-double,scene,puzzle-3x3,puzzle-4x4}-play-v0")
    assert list(tmp_path.iterdir()) == []
    other = tmp_path / "other.npz"  # a puzzle file given as cube-single
    np.savez(other, observations=np.zeros((3, 55), np.float32), actions=np.zeros((3, 5), np.float32),
             terminals=np.array([0, 0, 1], bool))
    line = _error(capsys, ["data", "info", str(other), "--maze", "cube-single-play-v0"])
    assert "is not a cube-single-play-v0 dataset: observations have shape [3, 55]" in line
    keyless = tmp_path / "keyless.npz"
    np.savez(keyless, observations=np.zeros((3, 28), np.float32))
    line = _error(capsys, ["data", "info", str(keyless), "--maze", "cube-single-play-v0"])
    assert "no actions, terminals array" in line
    with pytest.raises(BridgeplanError, match="task ids must be in 1..5"):
        FAMILY.tasks("cube-single-play-v0", task_ids=(11,))
    with pytest.raises(BridgeplanError, match="no noise-free oracle"):
        FAMILY.oracle("cube-single-play-v0")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keyless.npz", "other.npz"]


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    """A generated cube-single dataset of 3 episodes of 201 steps (and its validation file of one)."""
    folder = tmp_path_factory.mktemp("manip-data")
    generate_dataset("cube-single-play-v0", folder, seed=0, episodes=3, episode_steps=201, progress=False)
    return folder / "cube-single-play-v0.npz"


def test_inverse_dynamics_matches_the_data(tiny_data):
    """The arm's inverse dynamics from one state to the next gives back the data's actions: correlated per axis of the
    effector's motion, with the response the module states (least squares per axis within 25%)."""
    from bridgeplan.envs.ogbench_manipulation import controllers

    with np.load(tiny_data) as f:
        obs, actions, ends = f["observations"], f["actions"], f["terminals"]
    keep = ~ends[:-1]
    states, following, done = obs[:-1][keep], obs[1:][keep], actions[:-1][keep]
    predicted = controllers.inverse_dynamics(states, following)
    for axis in range(4):  # x, y, z, yaw (the gripper's opening lags its command by several steps)
        assert np.corrcoef(predicted[:, axis], done[:, axis])[0, 1] > 0.85
        raw = predicted[:, axis] / controllers.RESPONSE[axis]  # unclipped where the prediction is inside [-1, 1]
        inside = np.abs(predicted[:, axis]) < 1
        fitted = (raw[inside] @ done[inside, axis]) / (raw[inside] @ raw[inside])
        assert fitted == pytest.approx(controllers.RESPONSE[axis], rel=0.25)


def test_the_learned_prior_learns_from_the_goals_columns():
    """``train_prior_loss`` gives the net the window's first state and, as a goal, its last state's goal columns with
    every other column (the arm's pose, which a planner's goal leaves free) the first's: what ``LearnedPrior`` gives
    it when planning."""
    import torch

    from bridgeplan.priors import train_prior_loss

    layout = FAMILY.layout("cube-single-play-v0")
    seen = []

    def net(start, goal):
        seen.append((start, goal))
        return torch.zeros(len(start), 4, layout.transition_dim)

    x0 = torch.randn(2, 4, layout.transition_dim)
    train_prior_loss(net, x0, layout)
    (start, goal), = seen
    g = list(layout.goal)
    torch.testing.assert_close(start, layout.states(x0[:, 0]))
    torch.testing.assert_close(goal[:, g], layout.states(x0[:, -1])[:, g])
    free = layout.free_columns()
    assert len(free) == 25 and set(free).isdisjoint(g)
    torch.testing.assert_close(goal[:, free], start[:, free])


def _manipulation_conditions(layout, normalizer, start, goal, horizon):
    import torch

    def norm(s):
        return torch.as_tensor(normalizer.normalize(s, layout.state_columns))

    return {0: norm(start), horizon - 1: norm(layout.goal_states(goal))}


def test_the_line_in_state_space():
    """The line prior on an arm's states: the goal's columns evenly from the start's to the goal's, every other column
    (the arm's pose, which the goal does not give) held at the start's, the actions zero; the coarse prior alike."""
    import torch

    from bridgeplan.normalizer import Normalizer
    from bridgeplan.priors import make_prior

    layout = FAMILY.layout("cube-single-play-v0")
    rng = np.random.default_rng(0)
    normalizer = Normalizer.fit(rng.normal(size=(50, layout.transition_dim)))
    start, goal = rng.normal(size=(2, 28)), rng.normal(size=(2, 28))
    conditions = _manipulation_conditions(layout, normalizer, start, goal, 5)
    x = make_prior("line", normalizer, layout, stride=4).sample(conditions, 5, 2, torch.Generator().manual_seed(0))
    traj = normalizer.unnormalize(x.double().numpy())
    states, g = layout.states(traj), list(layout.goal)
    frac = np.linspace(0, 1, 5)[None, :, None]
    np.testing.assert_allclose(states[:, :, g], start[:, None, g] + frac * (goal - start)[:, None, g], atol=1e-6)
    other = [c for c in range(28) if c not in g]
    np.testing.assert_allclose(states[:, :, other], np.repeat(start[:, None, other], 5, axis=1), atol=1e-6)
    np.testing.assert_allclose(layout.actions(traj), 0, atol=1e-6)
    # the coarse prior through the start and the goal alone (the goal a knot by its columns) is the line
    coarse = make_prior("coarse", normalizer, layout, stride=4).sample(conditions, 5, 2)
    np.testing.assert_allclose(coarse.numpy(), x.numpy(), atol=1e-6)


def test_the_warm_prior_in_state_space():
    """The previous plan shifted by the steps executed (at stride 2, 4 steps: 2 planned states), its tail the line in
    state space from its last state toward the goal's columns (the others held at that state's)."""

    from bridgeplan.normalizer import Normalizer
    from bridgeplan.priors import WarmPrior

    layout = FAMILY.layout("cube-single-play-v0")
    rng = np.random.default_rng(1)
    normalizer = Normalizer.fit(rng.normal(size=(50, layout.transition_dim)))
    horizon, stride = 5, 2
    previous = rng.normal(size=(1, 9, layout.transition_dim))  # S = (H - 1) * stride + 1 steps
    start, goal = rng.normal(size=(1, 28)), rng.normal(size=(1, 28))
    warm = WarmPrior(normalizer, layout, previous, [4], stride=stride)
    conditions = _manipulation_conditions(layout, normalizer, start, goal, horizon)
    traj = normalizer.unnormalize(warm.sample(conditions, horizon, 1).double().numpy())[0]
    np.testing.assert_allclose(layout.states(traj[0]), start[0], atol=1e-6)  # the current state inpainted
    np.testing.assert_allclose(traj[1:3], previous[0, [6, 8]], atol=1e-6)  # t * stride + elapsed, inside the plan
    last, g = layout.states(previous[0, -1]), list(layout.goal)
    # the tail: from the previous plan's end (planned index 2) to the goal at index 4
    np.testing.assert_allclose(layout.states(traj[3])[g], last[g] + 0.5 * (goal[0, g] - last[g]), atol=1e-6)
    np.testing.assert_allclose(layout.states(traj[4])[g], goal[0, g], atol=1e-6)
    other = [c for c in range(28) if c not in g]
    np.testing.assert_allclose(layout.states(traj[3:])[:, other], np.repeat(last[None, other], 2, axis=0),
                               atol=1e-6)
    np.testing.assert_allclose(layout.actions(traj[3:]), 0, atol=1e-6)


def test_goal_states_are_the_goal_columns():
    layout = FAMILY.layout("cube-single-play-v0")
    goal = np.arange(28.0)[None]
    states = layout.goal_states(goal)
    assert np.isnan(states).sum() == 25 and (states[0, [19, 20, 21]] == [19, 20, 21]).all()
    with pytest.raises(BridgeplanError, match="goal is a 28-D goal observation"):
        layout.goal_states(np.zeros((1, 3)))


@pytest.mark.slow
def test_a_planner_trains_and_plans_on_cube_single(tiny_data, tmp_path, capsys):
    """Through ``bridgeplan train`` and ``eval``: DDPM's cpu-small shape, 4 steps; state-only plans executed by the
    arm's inverse dynamics, replanned every 8 steps, on one episode of test task 1 (an untrained planner does not
    finish it), with the line in state space as its floor."""
    run = tmp_path / "planner"
    assert main(["train", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--preset", "cpu-small",
                 "--steps", "4", "--batch-size", "4", "--dim", "8", "--checkpoint-every", "4", "--log-every", "2",
                 "--run-dir", str(run), "--device", "cpu", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "1", "--tasks", "1", "--nfe", "1", "--replan-every", "8",
                 "--no-progress", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["env_id"] == "cube-single-v0" and row["horizon"] == 32 and row["stride"] == 4
    assert row["tasks"]["1"]["steps"] == [200] and row["plans_per_episode"]["mean"] == 25
    assert row["floor_line"]["success_rate"] == 0.0
    assert _error(capsys, ["eval", str(run), "--controller", "pursuit", "--no-floor", "--episodes", "1",
                           "--no-progress"]).startswith("error: --controller pursuit steers a point")
    # Diffuser's own form: the plans' actions executed, replanned every 4 steps
    assert main(["eval", str(run), "--episodes", "1", "--tasks", "1", "--nfe", "1", "--replan-every", "4",
                 "--controller", "actions", "--no-floor", "--no-progress", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["execution"]["controller"] == "actions" and row["plans_per_episode"]["mean"] == 50
    # its first episode of validation task 7 drawn (the 5 test tasks' episodes are not run)
    picture = tmp_path / "episode.png"
    assert main(["render", str(run), "--tasks", "7,1", "--nfe", "1", "--replan-every", "8", "--size", "16",
                 "--device", "cpu", "--out", str(picture)]) == 0
    assert capsys.readouterr().out.split() == ["wrote", str(picture)]
    from PIL import Image

    from bridgeplan.render import CAPTION

    with Image.open(picture) as png:
        assert png.size == (3 * 16, 16 + 2 * CAPTION)


@pytest.mark.parametrize("process,prior", [pytest.param("bridge", "gaussian", marks=pytest.mark.slow),
                                           ("bridge", "line"), pytest.param("flow", "gaussian", marks=pytest.mark.slow),
                                           ("flow", "line"), ("bridge", "learned")])
def test_bridges_and_flows_train_and_plan_on_cube_single(tiny_data, tmp_path, capsys, process, prior):
    """The I2SB bridge and flow matching, from noise, from the line in state space and (the bridge) from the learned
    prior (``train-prior``, 4 steps), through the commands DDPM's test takes (2 steps; one episode of test task 1,
    replanned every 50 steps, NFE 2); the loaded planner's plans start at the state and end at the goal's columns; from
    the line, replans from the previous plan (``warm``). From noise, marked slow: the line's runs take the same paths
    (the default suite stays fast)."""
    import torch

    from bridgeplan.runs import load_planner

    run, prior_run = tmp_path / "run", []
    if prior == "learned":
        assert main(["train-prior", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--preset",
                     "cpu-small", "--steps", "4", "--batch-size", "4", "--checkpoint-every", "4", "--log-every", "2",
                     "--run-dir", str(tmp_path / "prior"), "--device", "cpu", "--no-progress"]) == 0
        prior_run = ["--prior-run", str(tmp_path / "prior")]
    assert main(["train", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--preset", "cpu-small",
                 "--process", process, "--prior", prior, *prior_run, "--steps", "2", "--batch-size", "4", "--dim", "8",
                 "--checkpoint-every", "2", "--log-every", "1", "--run-dir", str(run), "--device", "cpu",
                 "--no-progress"]) == 0
    capsys.readouterr()
    evaluate = ["eval", str(run), "--episodes", "1", "--tasks", "1", "--nfe", "2", "--replan-every", "50", "--no-floor",
                "--no-progress", "--json"]
    assert main(evaluate) == 0
    row = json.loads(capsys.readouterr().out)
    assert (row["process"], row["prior"], row["execution"]["first_prior"]) == (process, prior, prior)
    assert row["tasks"]["1"]["steps"] == [200] and row["plans_per_episode"]["mean"] == 4
    assert row["calls_per_episode"] == 8
    planner, _ = load_planner(run, device="cpu")
    layout = planner.layout
    with np.load(tiny_data) as f:
        start, goal = f["observations"][[0, 150]].astype(np.float64)
    plan = planner.plan(start[None], goal[None], 2, torch.Generator().manual_seed(0))
    assert plan.states.shape == (1, 125, 28) and np.isfinite(plan.states).all()
    np.testing.assert_allclose(plan.states[0, 0], start, atol=1e-5)
    np.testing.assert_allclose(plan.states[0, -1, list(layout.goal)], goal[list(layout.goal)], atol=1e-5)
    if prior == "line":
        assert main([*evaluate, "--prior", "warm"]) == 0
        row = json.loads(capsys.readouterr().out)
        assert (row["execution"]["first_prior"], row["execution"]["replan_prior"]) == ("line", "warm")
        assert row["tasks"]["1"]["steps"] == [200] and row["plans_per_episode"]["mean"] == 4


def test_the_dataset_graph_over_an_arms_states(tiny_data):
    """The graph's space is the effector's position and the cube's, standardized over the data, the cube's distances
    weighted: a jump moves the arm by at most the radius and the cube by at most the radius over the weight (no
    carrying a cube by jumps); a goal joins the nodes whose cube is at the goal's, wherever their arm is; the path
    starts at the state and ends at the goal's columns, the arm's as the last node's."""
    from bridgeplan.envs.ogbench_manipulation import GRAPH, GRAPH_GOAL_WEIGHT
    from bridgeplan.graph import DatasetGraph, GraphSpace, for_stream

    stream = FAMILY.load_stream(str(tiny_data), "cube-single-play-v0")
    radius = 6.0  # the tiny data's 3 episodes pass one another rarely
    graph, settings = for_stream(stream, FAMILY, {"keep": 2, "radius": radius})
    assert settings == {**GRAPH, "keep": 2, "radius": radius} and len(graph.nodes) == 3 * 101
    columns, cube = [12, 13, 14, 19, 20, 21], [3, 4, 5]
    std = stream.states[:, columns].std(axis=0)
    weight = np.array([1, 1, 1, GRAPH_GOAL_WEIGHT, GRAPH_GOAL_WEIGHT, GRAPH_GOAL_WEIGHT])
    assert graph.space.columns == tuple(columns) and np.allclose(graph.space.scale, std / weight)
    moves = np.linalg.norm(np.diff(stream.states[:, columns] / std * weight, axis=0), axis=1)
    assert graph.step == pytest.approx(np.median(np.delete(moves, [200, 401])))  # within episodes
    c = graph.costs.tocoo()
    jump = (graph.episode[c.row] != graph.episode[c.col]) | (np.abs(c.row - c.col) > 1)
    assert graph.jumps > 0 and jump.sum() == 2 * graph.jumps
    gap = (stream.states[graph.nodes[c.row[jump]]][:, columns] - stream.states[graph.nodes[c.col[jump]]][:, columns])
    assert np.linalg.norm(gap / std * weight, axis=1).max() <= radius + 1e-9
    assert np.linalg.norm(gap[:, cube] / std[cube], axis=1).max() <= radius / GRAPH_GOAL_WEIGHT + 1e-9
    plain = GraphSpace.standardized(stream.states, columns, goal=(19, 20, 21))
    unweighted = DatasetGraph.build(stream.states, stream.segment_starts, **settings, layout=stream.layout,
                                    step=graph.step, space=plain)
    assert unweighted.jumps > graph.jumps  # unweighted, jumps would move the cube as far as the arm
    start, goal = stream.states[0], stream.states[150].copy()
    goal[:19] = 1e3  # the arm's columns: no goal's
    nodes = graph.path_nodes(graph.space.point(start), graph.space.goal_point(goal))
    last = stream.states[graph.nodes[nodes[-1]]]  # a node whose cube is at the goal's, its arm wherever it was
    assert np.linalg.norm((last - goal)[[19, 20, 21]] / std[cube] * GRAPH_GOAL_WEIGHT) <= graph.reach
    path = graph.path(start, goal)
    np.testing.assert_allclose(path[0], start)
    goal_columns = list(FAMILY.layout("cube-single-play-v0").goal)
    np.testing.assert_allclose(path[-1, goal_columns], goal[goal_columns])
    np.testing.assert_allclose(path[-1, :19], last[:19])
    assert len(path) > 100 and (np.abs(np.diff(path[:, 19:22], axis=0)) > 1e-3).any()  # the data carries the cube


def test_the_dataset_graph_plans_alone_and_as_a_high_level(tiny_data, tmp_path, capsys):
    """``bridgeplan graph`` on cube-single: its paths executed by the arm's inverse dynamics (the family's path
    controller, track, where none is given; pursuit refused); then as the high level of a bridge low level trained with
    ``--subgoal-every`` from the coarse prior (the path's subgoals, joined by lines in state space), which plans
    through them every 20 steps."""
    graph = ["graph", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--episodes", "1", "--tasks", "1",
             "--keep", "2", "--no-progress", "--json"]
    assert _error(capsys, [*graph, "--controller", "pursuit", "--out", str(tmp_path / "pursued.json")]).startswith(
        "error: --controller pursuit steers a point toward a waypoint in the plane")
    assert not (tmp_path / "pursued.json").exists()
    assert main([*graph, "--out", str(tmp_path / "alone.json")]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["execution"]["controller"] == "track"
    assert row["tasks"]["1"]["steps"] == [200] and row["plans_per_episode"]["mean"] == 1
    assert row["graph"]["nodes"] == 3 * 101 and row["graph"]["paths_found"] == 1.0
    assert row["graph"]["path_steps"]["mean"] > 20  # the data's own states, not a straight line to the goal
    low = tmp_path / "low"
    assert main(["train", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--preset", "cpu-small",
                 "--horizon", "16", "--subgoal-every", "5", "--process", "bridge", "--prior", "coarse", "--steps", "2",
                 "--batch-size", "4", "--dim", "8", "--checkpoint-every", "2", "--log-every", "1", "--run-dir",
                 str(low), "--device", "cpu", "--no-progress"]) == 0
    capsys.readouterr()
    assert main([*graph, "--low", str(low), "--nfe-low", "2", "--out", str(tmp_path / "low.json")]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["low"]["prior"] == "coarse" and row["execution"]["replan_every"] == 20
    assert row["execution"]["controller"] == "track"
    assert row["tasks"]["1"]["steps"] == [200] and row["plans_per_episode"]["mean"] == 10
    assert row["coarse_plans"]["arrival_step"] < 200  # the path reaches the goal's cube position


def test_gcbc_trains_and_evaluates_on_cube_single(tiny_data, tmp_path, capsys):
    """GCBC through its one trainer and the family's evaluation: a tiny generated cube-single dataset, 4 steps, then
    ``bridgeplan eval RUN`` on a test task and a validation task, one episode each; the
    mistakes are one error line each and write nothing."""
    data = tiny_data
    run = tmp_path / "run"
    train = ["gcbc", "train", str(data), "--run-dir", str(run), "--maze", "cube-single-play-v0", "--steps", "4",
             "--batch-size", "8", "--hidden-dims", "8,8", "--checkpoint-every", "4", "--log-every", "2",
             "--device", "cpu", "--no-progress"]
    assert main(train) == 0
    capsys.readouterr()
    assert main(["eval", str(run), "--episodes", "1", "--tasks", "1,6", "--no-progress", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["env_id"] == "cube-single-v0" and row["maze"] == "cube-single-play-v0" and row["step"] == 4
    assert set(row["tasks"]) == {"1", "6"} and row["episodes"] == 2
    assert row["tasks"]["1"]["steps"] == [200]  # an untrained policy does not end the episode early
    assert row["tasks"]["6"]["task_name"] == "validation_task6"
    saved = json.loads((run / "eval" / "gcbc-step4-ep1-seed0-tasks16.json").read_text())
    assert saved == row
    # mistakes
    before = sorted(p.name for p in (run / "eval").iterdir())
    assert _error(capsys, ["eval", str(run), "--tasks", "11", "--no-progress"]).startswith(
        "error: task ids must be in 1..5")
    assert _error(capsys, ["eval", str(run), "--nfe", "4"]) == (
        f"error: {run} is a GCBC run (a policy, no plans): --nfe do not apply")
    assert _error(capsys, ["eval", str(run), "--controller", "pursuit", "--candidates", "2", "--no-floor"]) == (
        f"error: {run} is a GCBC run (a policy, no plans): --no-floor, --candidates, --controller do not apply")
    assert _error(capsys, ["graph", "--maze", "puzzle-3x3-play-v0", "--dataset", str(data), "--low", str(run),
                           "--no-progress"]) == (
        f"error: {run} was trained on 28-D observations, puzzle-3x3-play-v0's are 55-D")
    assert sorted(p.name for p in (run / "eval").iterdir()) == before
    assert _error(capsys, ["gcbc", "train", str(data), "--run-dir", str(tmp_path / "r2"), "--maze",
                           "cube-double-play-v0"]).startswith(f"error: {data} is not a cube-double-play-v0 dataset")
    assert not (tmp_path / "r2").exists()


def test_a_killed_generation_resumes_to_the_same_data(tmp_path, monkeypatch):
    """Pieces of 2 episodes: a generation stopped after its first piece resumes from it (the random state it had
    there) and makes the arrays an uninterrupted one makes; the pieces go once the dataset is written."""
    from bridgeplan.envs.ogbench_manipulation import generate

    monkeypatch.setattr(generate, "CHUNK_EPISODES", 2)
    whole = generate.generate_dataset("puzzle-3x3-play-v0", tmp_path / "a", seed=5, episodes=4, episode_steps=40,
                                      progress=False)
    assert not (tmp_path / "a" / "puzzle-3x3-play-v0.partial").exists()

    class Killed(Exception):
        pass

    def kill_after_first_piece(self, *args, **kwargs):
        saved(self, *args, **kwargs)
        raise Killed

    saved = generate.Pieces.save
    monkeypatch.setattr(generate.Pieces, "save", kill_after_first_piece)
    with pytest.raises(Killed):
        generate.generate_dataset("puzzle-3x3-play-v0", tmp_path / "b", seed=5, episodes=4, episode_steps=40,
                                  progress=False)
    assert json.loads((tmp_path / "b" / "puzzle-3x3-play-v0.partial" / "state.json").read_text())["episodes"] == 2
    monkeypatch.setattr(generate.Pieces, "save", saved)
    resumed = generate.generate_dataset("puzzle-3x3-play-v0", tmp_path / "b", seed=5, episodes=4, episode_steps=40,
                                        progress=False)
    assert resumed.record["content_sha256"] == whole.record["content_sha256"]
    assert resumed.record["targets"] == whole.record["targets"]


def test_the_actions_controller_executes_planned_actions():
    """Diffuser's form: the plan's own action at the step it is at; from its last state on, tracking that state;
    decisions of states alone refused."""
    from bridgeplan.envs.controllers import Follower

    layout = FAMILY.layout("cube-single-play-v0")
    follower = Follower(2, FAMILY.body("cube-single-play-v0"), "actions")
    plans = np.zeros((2, 3, layout.transition_dim))
    plans[:, :, :5] = np.arange(3)[None, :, None] * 0.1 + np.array([[[0.0]], [[0.5]]])  # action = 0.1 t (+ 0.5)
    states = np.zeros((2, 28))
    np.testing.assert_allclose(follower.actions(states, plans, np.array([1, 0])), [[0.1] * 5, [0.5] * 5])
    plans[1, 2, 5 + 12] = 0.01  # the last planned state's effector 1 mm further in x: tracked, not its action
    done = follower.actions(states, plans, np.array([0, 2]))
    tracked = FAMILY.body("cube-single-play-v0").track(states[1:], layout.states(plans[1:, 2]))
    np.testing.assert_allclose(done[1], tracked[0])
    assert done[1, 0] != 0.5 + 0.2
    with pytest.raises(BridgeplanError, match="plan states alone"):
        follower.actions(states, layout.states(plans), np.array([0, 0]))


def test_a_policy_executes_a_plan_toward_its_state_ahead():
    """A policy low level: at step t of a plan its goal is the plan's state ``ahead`` steps on (the last past the
    plan's end), of a joint plan its state columns; a goal behind the policy refused."""
    from bridgeplan.envs.controllers import PolicyFollower

    layout = FAMILY.layout("cube-single-play-v0")
    heard = []

    def act(states, goals):
        heard.append(goals.copy())
        return np.zeros((len(states), 5))

    follower = PolicyFollower(2, FAMILY.body("cube-single-play-v0"), act, ahead=3)
    plans = np.arange(2 * 6, dtype=np.float64)[:, None].repeat(28, axis=1).reshape(2, 6, 28)  # state k: all k
    states = np.zeros((2, 28))
    assert follower.actions(states, plans, np.array([0, 4])).shape == (2, 5)
    np.testing.assert_array_equal(heard[-1][:, 0], [plans[0, 3, 0], plans[1, 5, 0]])  # 0 + 3; 4 + 3 past the end
    joint = np.concatenate([np.full((2, 6, layout.act_dim), -7.0), plans], axis=2)
    follower.actions(states, joint, np.array([1, 1]))
    np.testing.assert_array_equal(heard[-1], plans[:, 4])
    with pytest.raises(BridgeplanError, match="at least 1 step ahead"):
        PolicyFollower(2, FAMILY.body("cube-single-play-v0"), act, ahead=0)


def test_the_graph_with_a_policy_low_level(tiny_data, tmp_path, capsys, monkeypatch):
    """``bridgeplan graph --low`` a GCBC run: the graph's path executed by the policy, every step, toward the path's
    state --policy-ahead steps on (not the task's goal); the row names the policy and its settings; the options of a
    planner low level, and --policy-ahead without a policy, refused."""
    import bridgeplan.gcbc

    run = tmp_path / "gcbc"
    assert main(["gcbc", "train", str(tiny_data), "--run-dir", str(run), "--maze", "cube-single-play-v0", "--steps",
                 "4", "--batch-size", "8", "--hidden-dims", "8,8", "--checkpoint-every", "4", "--log-every", "2",
                 "--device", "cpu", "--no-progress"]) == 0
    capsys.readouterr()
    goals, real = [], bridgeplan.gcbc.GCBCPolicy.act
    monkeypatch.setattr(bridgeplan.gcbc.GCBCPolicy, "act",
                        lambda self, observations, g: goals.append(np.array(g)) or real(self, observations, g))
    graph = ["graph", "--dataset", str(tiny_data), "--episodes", "1", "--tasks", "1", "--keep", "2", "--no-progress",
             "--json", "--low", str(run), "--replan-every", "50"]
    assert main([*graph, "--policy-ahead", "3", "--out", str(tmp_path / "policy.json")]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["method"] == "dataset graph, GCBC low level" and row["maze"] == "cube-single-play-v0"
    assert row["low"] == {"run": "gcbc", "agent": "gcbc", "step": 4, "ahead": 3}
    assert row["config"]["low"]["dataset"] == "cube-single-play-v0" and row["config"]["graph"]["keep"] == 2
    assert row["graph"]["paths_found"] == 1.0 and row["plans_per_episode"]["mean"] == 4  # searched every 50 steps
    acted = sum(len(g) for g in goals)
    assert acted == 2 * row["tasks"]["1"]["steps"][0]  # at every step of the episode, and of the latency's again
    assert row["execution"]["controller"] == "policy" and row["calls_per_episode"] == row["tasks"]["1"]["steps"][0]
    task_goal = goals[0][0]
    assert any(not np.allclose(g[0], task_goal) for g in goals[1:])  # toward the path, not the task's goal alone
    default = main([*graph, "--out", str(tmp_path / "default.json")])
    assert default == 0 and json.loads(capsys.readouterr().out)["low"]["ahead"] == 25
    before = sum(len(g) for g in goals)  # drawn: the episode run again, executed by the policy as evaluated
    assert main([*graph, "--render", "--size", "24", "--out", str(tmp_path / "drawn.json")]) == 0
    steps = json.loads(capsys.readouterr().out)["tasks"]["1"]["steps"][0]
    assert (tmp_path / "drawn.png").exists() and sum(len(g) for g in goals) - before == 3 * steps
    for flags, message in ((["--nfe-low", "2"], "error: --nfe-low and --replan-high-every are a planner low level's"),
                           (["--policy-ahead", "0"], "error: --policy-ahead must be"),
                           (["--low-snapshot", "3"], f"error: {run} has no snapshot at step 3 (it has: 4)")):
        assert _error(capsys, [*graph, *flags, "--out", str(tmp_path / "bad.json")]).startswith(message)
    assert _error(capsys, ["graph", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--policy-ahead", "5",
                           "--out", str(tmp_path / "bad.json")]).startswith("error: --policy-ahead is a policy low")
    assert not (tmp_path / "bad.json").exists()


def test_the_graph_over_a_policy_in_your_own_loop_acts_as_evaluated(tiny_data, tmp_path, capsys, monkeypatch):
    """``PlannerPolicy.from_graph(RUN)`` over a GCBC run, in a loop over ogbench's own environment (``info["goal"]``
    given): the same episode as ``bridgeplan graph --low RUN`` evaluates, the policy asked the same observations and
    goals at every step, the same steps and success; the graph alone (``env``, ``dataset``) the same way, and the
    objects apart searched again where each path's first step ends; a goal of another width refused."""
    import ogbench

    import bridgeplan.gcbc
    from bridgeplan.envs.ogbench_common import episode_seed
    from bridgeplan.policy import PlannerPolicy

    run = tmp_path / "gcbc"
    assert main(["gcbc", "train", str(tiny_data), "--run-dir", str(run), "--maze", "cube-single-play-v0", "--steps",
                 "4", "--batch-size", "8", "--hidden-dims", "8,8", "--checkpoint-every", "4", "--device", "cpu",
                 "--no-progress"]) == 0
    asked, real = [], bridgeplan.gcbc.GCBCPolicy.act
    monkeypatch.setattr(bridgeplan.gcbc.GCBCPolicy, "act",
                        lambda self, o, g: asked.append((np.array(o), np.array(g))) or real(self, o, g))
    graph = ["graph", "--episodes", "1", "--tasks", "1", "--keep", "2", "--replan-every", "50", "--no-progress",
             "--json", "--low", str(run), "--policy-ahead", "3"]
    capsys.readouterr()
    assert main([*graph, "--out", str(tmp_path / "row.json")]) == 0
    row = json.loads(capsys.readouterr().out)
    steps, evaluated = row["tasks"]["1"]["steps"][0], asked[:]

    def own_loop(policy):
        env = ogbench.make_env_and_datasets("cube-single-play-v0", env_only=True)
        obs, info = env.reset(seed=episode_seed(0, 1, 0), options={"task_id": 1})  # the evaluation's episode 0
        goal = info["goal"]  # the reset's info holds it
        policy.reset()
        done, n = False, 0
        while not done:
            action = policy(obs, goal)
            assert action.shape == (5,) and action.dtype == np.float32 and np.abs(action).max() <= 1
            obs, _, terminated, truncated, info = env.step(action)
            done, n = terminated or truncated, n + 1
        env.close()
        return n, bool(info["success"])

    asked.clear()
    policy = PlannerPolicy.from_graph(run, replan_every=50, graph={"keep": 2}, policy_ahead=3, device="cpu")
    assert policy.env == "cube-single-play-v0" and policy.maze is None
    assert own_loop(policy) == (steps, row["tasks"]["1"]["successes"] == 1)
    assert len(asked) == steps and policy.plans_made == row["plans_per_episode"]["mean"]
    np.testing.assert_array_equal(asked[0][0], evaluated[0][0])  # the same first state
    for (o, g), (o_eval, g_eval) in zip(asked, evaluated):  # the evaluation's first pass over its episode: the same
        np.testing.assert_allclose(o, o_eval, rtol=0, atol=1e-6)  # but for the float32 actions a policy returns
        np.testing.assert_allclose(g, g_eval, rtol=0, atol=1e-6)
    alone = PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, replan_every=50, graph={"keep": 2})
    assert own_loop(alone)[0] == 200 and alone.plans_made == 4 and alone.execution.controller == "track"
    with pytest.raises(BridgeplanError, match="an observation of 28 numbers and its goal of 28"):
        alone(np.zeros(28), np.zeros(3))
    # the objects apart, searched again only where a path's first step ends (--replan-after-step)
    apart = PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, graph={"keep": 2}, objects=True,
                                     replan_after_step=0)
    assert own_loop(apart)[0] == 200 and apart.execution.after_step == 0 and apart.plans_made > 1
    with pytest.raises(BridgeplanError, match="only paths made of steps"):
        PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, graph={"keep": 2}, replan_after_step=0)
    drifting = PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, graph={"keep": 2}, objects=True,
                                        replan_object_tolerance=0.5)
    assert drifting.execution.object_tolerance == 0.5 and own_loop(drifting)[0] == 200
    with pytest.raises(BridgeplanError, match="only paths that say where every object should be"):
        PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, graph={"keep": 2},
                                 replan_object_tolerance=0.5)
    with pytest.raises(BridgeplanError, match="cube-single-play-v0 is no scene"):  # --hand is scene's
        PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, objects=True, hand=True)
    with pytest.raises(BridgeplanError, match="give env and dataset"):
        PlannerPolicy.from_graph(env="cube-single-play-v0")
    with pytest.raises(BridgeplanError, match="--policy-ahead is a policy low level's"):
        PlannerPolicy.from_graph(env="cube-single-play-v0", dataset=tiny_data, policy_ahead=3)


@pytest.mark.slow
def test_the_graph_draws_its_episode(tiny_data, tmp_path, capsys, monkeypatch):
    """``bridgeplan graph --render --video`` on cube-single: the first episode executed again and drawn by ogbench's
    camera: a PNG of its start, middle and end side by side, and a GIF of every 4th of its 201 states (and the last),
    frames of the size asked (the GIF 40 ms a state); the arm moves, so the first and last frames differ. Refused
    before anything is written: a video without --render, --render with --low, a MuJoCo that cannot render
    offscreen."""
    from PIL import Image

    from bridgeplan import render

    size = 24
    graph = ["graph", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--episodes", "1", "--tasks", "1",
             "--controller", "track", "--keep", "2", "--no-progress", "--json", "--size", str(size)]
    out = tmp_path / "graph.json"
    assert main([*graph, "--render", "--video", "--out", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["tasks"]["1"]["steps"] == [200]  # stdout: the JSON alone
    with Image.open(out.with_suffix(".png")) as png:
        assert png.size == (3 * size, size + 2 * render.CAPTION)
        strip = np.asarray(png.convert("RGB"))[2 * render.CAPTION:]
    first, last = strip[:, :size], strip[:, 2 * size:]
    assert np.abs(first.astype(int) - last).mean() > 1
    with Image.open(out.with_suffix(".gif")) as gif:  # a frame as the one before it lengthens that one
        durations, frames = [], []
        for k in range(gif.n_frames):
            gif.seek(k)
            durations.append(gif.info["duration"])
            frames.append(np.asarray(gif.convert("RGB")))
        start, end = frames[0], frames[-1]
        assert gif.size == (size, size) and sum(durations) == 40 * len(range(0, 201, 4)) == 40 * 51
    assert np.abs(start.astype(int) - end).mean() > 1
    # the objects apart searched again where each step ends: drawn as evaluated
    apart = tmp_path / "apart.json"
    assert main([*graph, "--objects", "--replan-after-step", "0", "--render", "--out", str(apart)]) == 0
    assert json.loads(capsys.readouterr().out)["execution"]["replan_after_step"] == 0
    assert apart.with_suffix(".png").exists()

    def refused(argv, message):
        assert message in _error(capsys, [*graph, *argv, "--out", str(tmp_path / "bad.json")])
        assert not list(tmp_path.glob("bad*"))

    refused(["--video"], "error: --video goes with --render")
    refused(["--render", "--low", str(tmp_path / "graph.json")], "--render draws the graph's own paths")

    class NoGL:
        def __init__(self, *args):
            raise AttributeError("'NoneType' object has no attribute 'glGetError'")

    import mujoco

    monkeypatch.setattr(mujoco, "Renderer", NoGL)
    refused(["--render"], "error: MuJoCo cannot render offscreen with MUJOCO_GL='egl' (AttributeError")


def test_a_plans_marks_are_where_its_effector_would_be():
    """The picture's marks of a plan: the effector's world position read back from the observation's scaled columns,
    as the environment reports it (``proprio/effector_pos``), after random steps; a plan's repeated end once."""
    env = make_env("cube-single-v0")
    env.reset(seed=3, options=dict(task_id=2))
    obs, where = [], []
    for _ in range(30):
        ob, *_, info = env.step(env.action_space.sample())
        obs.append(ob)
        where.append(info["proprio/effector_pos"])
    marks = protocol.planned_effector(np.asarray(obs + [obs[-1]] * 20))  # a path held at its end: not drawn again
    assert len(marks) == protocol.PLAN_MARKS and np.abs(np.ptp(np.asarray(where), axis=0)).max() > 0.01
    rows = np.linspace(0, 29, protocol.PLAN_MARKS).round().astype(int)
    assert np.allclose(marks, np.asarray(where)[rows], atol=1e-6)


def test_the_graphs_radius_is_the_scenes_where_it_has_one():
    """scene's states meet rarely at the family's radius (chosen on cube-single): its own, chosen on its validation
    tasks, is the default there; the other scenes keep the family's."""
    from types import SimpleNamespace

    from bridgeplan.envs.ogbench_manipulation import GRAPH

    def radius(name, objects=False):
        return FAMILY.graph_pace(SimpleNamespace(maze=name), objects=objects)[0]["radius"]

    assert radius("scene-play-v0") == 12.0
    assert radius("scene-play-v0", objects=True) == GRAPH["radius"]  # each part's graph: the family's
    others = {radius(name) for name in ("cube-single-play-v0", "cube-double-play-v0", "puzzle-3x3-play-v0")}
    assert others == {GRAPH["radius"]}


def test_the_objects_apart_move_one_cube_at_a_time():
    """Of the cubes not yet within the task's 0.4 (0.04 m) of their goal, the next moved is one whose goal no other cube
    occupies, the lowest goal first (a stack's bottom); when all are placed, the first."""
    from bridgeplan.graph import ObjectGraphs

    graphs = ObjectGraphs([], ((0, 1, 2), (3, 4, 5)), tolerance=0.4)

    def state(a, b):
        return np.array([*a, *b], np.float64)

    done = state((0, 0, 0), (2, 0, 0))
    assert graphs.next_object(state((0, 0, 0), (1, 1, 0)), done) == 1  # cube 0 is placed (0.3 < 0.4 would be too)
    assert graphs.next_object(state((0.3, 0, 0), (1, 1, 0)), done) == 1
    assert graphs.next_object(state((1, 0, 0), (1, 1, 0)), done) == 0
    assert graphs.next_object(state((1, 1, 0), (0, 0.2, 0)), done) == 1  # cube 0's goal is taken by cube 1
    stack = state((0, 0, 0.4), (0, 0, 0))  # cube 1 below cube 0
    assert graphs.next_object(state((1, 1, 0), (2, 2, 0)), stack) == 1
    assert graphs.next_object(state((0, 0, 0), (2, 0, 0)), state((2, 0, 0), (0, 0, 0))) == 0  # a swap: the first
    assert graphs.next_object(done, done) == 0


def test_a_swap_sets_one_cube_aside_first():
    """Each cube on the other's goal: the cube moved first is set down where the data rested it at the goal's height,
    the nearest such place clear of both cubes and goals (3 tolerances), the path chaining the other cube to its goal,
    then the first to its own; a stack's top, whose goal is held by a cube already at its own goal, and a free goal go
    straight to the goal."""
    from types import SimpleNamespace

    from bridgeplan.graph import ObjectGraphs

    class Searched:  # a graph whose path goes straight to the goal it was asked for
        layout = SimpleNamespace(goal=(0, 1, 2, 3, 4, 5))

        def __init__(self, places):
            self.observations = np.array([[*p, 0, 0, 0] for p in places], np.float64)
            self.nodes = np.arange(len(places))
            self.queries = []

        def path(self, start, goal):
            self.queries.append((2, True, 1))
            return np.stack([start, goal])

    places = [(1, 0, 0.2), (0, 3, 0.2), (0, 1.5, 0.5), (0, 5, 0.2), (0, -1.1, 0.2)]
    graphs = ObjectGraphs([Searched(places), Searched(places)], ((0, 1, 2), (3, 4, 5)), tolerance=0.4)

    def state(a, b):
        return np.array([*a, *b], np.float64)

    swap_start, swap_goal = state((0, 0, 0.2), (2, 0, 0.2)), state((2, 0, 0.2), (0, 0, 0.2))
    # (1, 0) is 1 from both cubes, (0, 1.5) rests higher, (0, -1.1) is nearer than (0, 3) but within 1.2 of (0, 0)
    np.testing.assert_allclose(graphs.aside(swap_start, swap_goal, 0), (0, 3, 0.2))
    path = graphs.path(swap_start, swap_goal)  # cube 0 aside, cube 1 to its goal, cube 0 to its own
    np.testing.assert_allclose(path[1], state((0, 3, 0.2), (2, 0, 0.2)))  # the cube not moved held where it is
    np.testing.assert_allclose([path[2, 3:], path[3, :3]], [(0, 0, 0.2), (2, 0, 0.2)])
    assert graphs.chosen == [0, 1, 0] and graphs.set_aside == 1
    # set aside: cube 1's goal is free now, and it goes there
    aside = state((0, 3, 0.2), (2, 0, 0.2))
    assert graphs.next_object(aside, swap_goal) == 1 and graphs.aside(aside, swap_goal, 1) is None
    stack = state((0, 0, 0.6), (0, 0, 0.2))  # cube 0 onto cube 1, which is at its goal
    assert graphs.aside(state((2, 0, 0.2), (0, 0, 0.2)), stack, 0) is None
    assert graphs.aside(state((2, 0, 0.2), (4, 4, 0.2)), swap_goal, 1) is None  # cube 1's goal is free
    crowded = ObjectGraphs([Searched(places[:1]), Searched(places[:1])], graphs.objects, tolerance=0.4)
    assert crowded.aside(swap_start, swap_goal, 0) is None
    np.testing.assert_allclose(crowded.path(swap_start, swap_goal)[-1], swap_goal)


def test_the_objects_apart_over_two_cubes(tmp_path):
    """On cube-double the objects' graphs are the arm's and one cube's columns each (the cube's weighted as the
    family's one graph weighs the goal's), the other cube left out; a query moves the cube not at its goal: its path
    ends at that cube's goal, carried by the data's own states. cube-double only: a puzzle's buttons and scene's locks
    are not objects apart."""

    from bridgeplan.envs.ogbench_manipulation import GRAPH_GOAL_WEIGHT
    from bridgeplan.graph import ObjectGraphs, for_stream

    for name in ("puzzle-3x3-play-v0", "scene-play-v0"):
        assert FAMILY.graph_objects(name) is None
    generate_dataset("cube-double-play-v0", tmp_path, seed=0, episodes=3, episode_steps=301, progress=False)
    stream = FAMILY.load_stream(str(tmp_path / "cube-double-play-v0.npz"), "cube-double-play-v0")
    graphs, settings = for_stream(stream, FAMILY, {"keep": 2, "radius": 6.0}, objects=True)
    assert isinstance(graphs, ObjectGraphs) and graphs.tolerance == pytest.approx(0.4)
    assert graphs.objects == ((19, 20, 21), (28, 29, 30))
    for graph, cube in zip(graphs.graphs, graphs.objects):
        assert graph.space.columns == (12, 13, 14, *cube) and graph.space.goal == cube
        std = stream.states[:, list(cube)].std(axis=0)
        np.testing.assert_allclose(graph.space.scale[3:], std / GRAPH_GOAL_WEIGHT)
    # a goal that moves cube 1 only: where the data put it later in the first episode
    start, goal = stream.states[0], stream.states[0].copy()
    moved = np.flatnonzero(np.linalg.norm(stream.states[:301, 28:31] - start[28:31], axis=1) > 1.0)
    assert len(moved), "the tiny data never moves cube 1 far"
    goal[28:31] = stream.states[moved[0], 28:31]
    path = graphs.path(start, goal)
    assert graphs.chosen == [1]
    np.testing.assert_allclose(path[-1, 28:31], goal[28:31])
    assert (np.abs(np.diff(path[:, 28:31], axis=0)) > 1e-3).any()  # the data carries the cube
    np.testing.assert_array_equal(path[:, 19:22], np.repeat(start[None, 19:22], len(path), axis=0))  # cube 0 stays
    # the objects' drift from a plan: none along it (each state at its own age), the larger of the two cubes' gaps
    # where one is dropped or pushed, the nearest of the planned positions within DRIFT_WINDOW steps of the age
    from bridgeplan.graph import DRIFT_WINDOW

    k = int(np.argmax(np.linalg.norm(path[:, 28:31] - start[28:31], axis=1) > 0.5))  # cube 1 on its way
    plans = np.repeat(path[None], 3, axis=0)
    pushed, dropped = path[k].copy(), path[k].copy()
    pushed[19] += 0.7
    dropped[28:31] = start[28:31]
    ages = np.array([k, k, k])
    drift = graphs.drift(np.stack([path[k], pushed, dropped]), plans, ages)
    window = path[max(0, k - DRIFT_WINDOW):k + DRIFT_WINDOW + 1, 28:31]
    np.testing.assert_allclose(drift, [0.0, 0.7, np.linalg.norm(window - start[28:31], axis=1).min()], atol=1e-9)
    assert drift[2] > 0  # the dropped cube is away from every planned position near its age
    lag = graphs.drift(path[[max(0, k - DRIFT_WINDOW)]], plans[:1], ages[:1])  # a cube as far behind as the window
    assert lag[0] == pytest.approx(0.0)
    summary = graphs.summary()
    assert summary["objects"] == 2 and summary["paths_per_object"] == [0, 1] and summary["paths_found"] == 1.0
    assert summary["nodes"] == sum(len(g.nodes) for g in graphs.graphs)


def test_bridgeplan_graph_objects_names_its_rows(tiny_data, tmp_path, capsys):
    """``bridgeplan graph --objects``: its JSON says so (its name, its method, its config) and counts the searches per
    object; with a planner low level (a directory that is no GCBC run) it is refused before anything is read."""
    graph = ["graph", "--maze", "cube-single-play-v0", "--dataset", str(tiny_data), "--episodes", "1", "--tasks", "1",
             "--keep", "2", "--no-progress", "--objects"]
    assert _error(capsys, [*graph, "--low", str(tmp_path)]).startswith("error: --objects: ")
    maze = ["graph", "--maze", "pointmaze-medium-navigate-v0", "--dataset", str(tiny_data), "--objects", "--out",
            str(tmp_path / "maze.json")]
    assert _error(capsys, maze).startswith("error: --objects: pointmaze-medium-navigate-v0's goals move no objects")
    assert not (tmp_path / "maze.json").exists()
    assert main([*graph, "--out", str(tmp_path / "objects.json")]) == 0
    row = json.loads((tmp_path / "objects.json").read_text())
    assert row["method"] == "dataset graph, objects apart" and row["config"]["graph"]["objects"] is True
    assert row["graph"]["objects"] == 1 and row["graph"]["paths_per_object"] == [1]
    assert main([*graph[:-1], "--out", str(tmp_path / "one.json")]) == 0  # one cube: the one graph's own paths
    one = json.loads((tmp_path / "one.json").read_text())
    assert one["graph"]["path_steps"] == row["graph"]["path_steps"] and "objects" not in one["config"]["graph"]
    # searched again where a path's first step ends: paths made of steps only, a step count in 0..episode length
    assert _error(capsys, [*graph[:-1], "--replan-after-step", "5"]).startswith("error: --replan-after-step plans ")
    # searched again where a cube left its plan: the cubes' paths only, a distance >= 0
    assert _error(capsys, [*graph[:-1], "--replan-object-tolerance", "0.5"]).startswith(
        "error: --replan-object-tolerance plans again where an object left its plan: give --objects on a cube")
    puzzle = ["graph", "--maze", "puzzle-3x3-play-v0", "--dataset", str(tiny_data), "--objects"]
    assert _error(capsys, [*puzzle, "--replan-object-tolerance", "0.5"]).startswith(
        "error: --replan-object-tolerance plans again where an object left its plan: give --objects on a cube or "
        "scene dataset")
    assert _error(capsys, [*graph, "--replan-object-tolerance", "-1", "--out", str(tmp_path / "bad.json")]
                  ).startswith("error: --replan-object-tolerance must be >= 0")
    assert _error(capsys, [*graph, "--replan-after-step", "-1", "--out", str(tmp_path / "bad.json")]).startswith(
        "error: --replan-after-step must be in 0..200")
    assert not (tmp_path / "bad.json").exists()
    # the hand in some parts' graphs: a scene's only, with --objects
    assert _error(capsys, [*graph, "--hand", "--out", str(tmp_path / "bad.json")]).startswith(
        "error: --hand measures the hand in some of a scene's part graphs: cube-single-play-v0 is no scene")
    assert not (tmp_path / "bad.json").exists()
    capsys.readouterr()
    assert main([*graph, "--replan-after-step", "5", "--out", str(tmp_path / "after.json")]) == 0
    assert "track, replan 5 steps after a first step ends" in capsys.readouterr().out
    after = json.loads((tmp_path / "after.json").read_text())
    assert after["execution"]["replan_after_step"] == 5 and after["execution"]["mode"] == "closed_loop"
    assert main([*graph, "--replan-object-tolerance", "0.5", "--out", str(tmp_path / "drift.json")]) == 0
    assert "track, replan past 0.5 of an object from the plan" in capsys.readouterr().out
    drift = json.loads((tmp_path / "drift.json").read_text())
    assert drift["execution"]["replan_object_tolerance"] == 0.5 and drift["execution"]["mode"] == "closed_loop"


@pytest.fixture(scope="module")
def tiny_puzzle(tmp_path_factory):
    """A generated puzzle-3x3 dataset of 4 episodes of 301 steps: 36 presses, every button but button 1 pressed."""
    folder = tmp_path_factory.mktemp("puzzle-data")
    generate_dataset("puzzle-3x3-play-v0", folder, seed=0, episodes=4, episode_steps=301, progress=False)
    return folder / "puzzle-3x3-play-v0.npz"


def lights_out(rows: int, cols: int) -> np.ndarray:
    """``[B, B]`` what a press of each button toggles: itself and its 4 neighbours (OGBench's puzzle_env)."""
    toggles = np.zeros((rows * cols, rows * cols), dtype=bool)
    for i in range(rows * cols):
        r, c = divmod(i, cols)
        for dr, dc in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            if 0 <= r + dr < rows and 0 <= c + dc < cols:
                toggles[i, (r + dr) * cols + c + dc] = True
    return toggles


def test_a_puzzles_presses_are_learned_from_the_data_and_end_its_path(tiny_puzzle):
    """``graph --objects`` on a puzzle: what each press toggles is read from the data's presses (Lights Out's cross,
    for every button the data presses; nothing for the one it never does); a goal one press away is solved as that
    press, and its path is the arm's way clear of the buttons, then the data's own descent onto that button. Below the
    clearance the arm goes on as the data did: down a press under way, up from a press made."""
    from bridgeplan.envs.ogbench_manipulation import BUTTON_UP
    from bridgeplan.graph import ButtonPresses, for_stream

    stream = FAMILY.load_stream(str(tiny_puzzle), "puzzle-3x3-play-v0")
    presses, _ = for_stream(stream, FAMILY, {"keep": 2}, objects=True)
    assert isinstance(presses, ButtonPresses)
    pressed = np.bincount(presses.pressed, minlength=9)
    assert pressed[1] == 0 and (np.delete(pressed, 1) > 0).all()
    expected = lights_out(3, 3)
    expected[1] = False
    np.testing.assert_array_equal(presses.toggles, expected)
    assert presses.graph.space.columns == (12, 13, 14) and presses.height == 14 and presses.up == BUTTON_UP
    pushed = (stream.states[:, 21::4] <= BUTTON_UP).any(axis=1)
    assert presses.clearance == stream.states[pushed, 14].max()
    clear = presses.graph.observations
    assert (clear[:, 21::4] > BUTTON_UP).all() and (clear[:, 14] > presses.clearance).all()

    def one_press(state, k):
        goal = state.copy()
        goal[20::4] = (state[20::4] > 0.5) ^ expected[k]  # the buttons' "on" columns
        return goal

    def toggles_of(k):
        return stream.states[presses.press_rows[presses.pressed == k, 1]]  # the data's states as k toggled

    start = stream.states[0]
    for k in (4, 8):
        assert presses.presses(start, one_press(start, k)) == [k]
        path = presses.path(start, one_press(start, k))
        high = path[:, 14] > presses.clearance
        down = int(np.argmin(high))
        assert high[:down].all() and not high[down:].any()  # clear of the buttons, then the descent
        assert (path[:down, 21::4] > BUTTON_UP).all()
        assert np.argmin(path[-1, 21::4]) == k and path[-1, 21 + 4 * k] < -2.4  # the press toggled (-0.02 m x 120)
        assert np.isclose(toggles_of(k), path[-1]).all(axis=1).any()
        space = presses.graph.space  # the arm is at the path's first node: the path goes on from the next
        np.testing.assert_array_equal(presses.graph.observations[presses.graph.nodes[0]], start)
        assert np.linalg.norm(space.point(path[1]) - space.point(start)) > presses.graph.step
    assert presses.chosen == [4, 8] and presses.presses(start, start) == []
    assert len(presses.path(start, start)) == 1 and presses.summary()["queries_pressing_none"] == 1
    # pushing button 4, not yet toggled: on down to where a press of it toggled
    a, b, _ = next(rows for rows, k in zip(presses.press_rows, presses.pressed) if k == 4)
    halfway = next(stream.states[r] for r in range(a + 1, b) if presses.toggled_at < stream.states[r, 37] <= BUTTON_UP)
    path = presses.path(halfway, one_press(halfway, 4))
    assert presses.chosen[-1] == 4 and np.isclose(toggles_of(4), path[-1]).all(axis=1).any()
    assert (np.diff(path[:, 14]) <= 1e-9).all()  # down, never up
    # just toggled button 4, button 8 to press: up first (as the data rose from 4), then to 8
    path = presses.path(stream.states[b], one_press(stream.states[b], 8))
    assert presses.chosen[-1] == 8 and np.isclose(toggles_of(8), path[-1]).all(axis=1).any()
    assert path[1, 14] > path[0, 14] and (path[:, 14] > presses.clearance).any()


def test_the_fewest_presses_solve_lights_out():
    """The presses solved are the fewest that make the change (checked against every combination of 4x4 Lights Out,
    whose 16 presses make only 4096 of the 65 536 changes); a change none makes is None."""
    from bridgeplan.graph import ButtonPresses

    toggles = lights_out(4, 4)
    solver = ButtonPresses(None, None, tuple(range(16)), (), toggles, None, None, None, -2.4)
    combinations = (np.arange(1 << 16)[:, None] >> np.arange(16)) & 1
    made = (combinations @ toggles.astype(np.int64)) % 2
    change = (made << np.arange(16)).sum(axis=1)
    fewest = np.full(1 << 16, 99)
    np.minimum.at(fewest, change, combinations.sum(axis=1))
    assert (fewest < 99).sum() == 4096
    rng = np.random.default_rng(0)
    for goal in rng.integers(0, 2, (200, 16)).astype(np.float64):
        start = rng.integers(0, 2, 16).astype(np.float64)
        bits = int(((start > 0.5) != (goal > 0.5)).astype(np.int64) @ (1 << np.arange(16)))
        solved = solver.presses(start, goal)
        if fewest[bits] == 99:
            assert solved is None
            continue
        assert len(solved) == fewest[bits]
        flips = np.bitwise_xor.reduce(toggles[solved], axis=0) if solved else np.zeros(16, dtype=bool)
        np.testing.assert_array_equal(flips, (start > 0.5) != (goal > 0.5))


def test_a_press_toggles_what_the_datas_presses_of_it_toggled_most_often():
    """Hand-made data: button 0 pressed four times, once in a slip that toggled itself alone. What a press of it
    toggles is its cross (3 of 4); each press's descent starts where the arm was last clear of the buttons (every
    button up, higher than the data ever had one pushed), its toggle is where the buttons changed, its rise ends clear
    again; the graph holds only the clear states."""
    from bridgeplan.graph import ButtonPresses

    bits = np.zeros(9, dtype=bool)

    def state(x, z, depth=None):
        s = np.zeros(55)
        s[12], s[14], s[20::4], s[21::4] = x, z, bits, 0.055
        if depth is not None:
            s[21] = depth  # button 0 pushed
        return s

    cross = lights_out(3, 3)[0]
    rows = []
    for i, flips in enumerate([cross, np.eye(9, dtype=bool)[0], cross, cross]):
        rows += [state(i, 2.0), state(i + 0.5, 2.0), state(i + 0.5, 1.05), state(i + 0.5, 1.1, -1.0)]
        bits ^= flips
        rows += [state(i + 0.5, 1.0, -3.0), state(i + 0.5, 1.1, -1.0)]
    presses = ButtonPresses.build(np.array(rows), np.array([0]), tuple((20 + 4 * k, 21 + 4 * k) for k in range(9)),
                                  14, -0.1, {"keep": 1, "radius": 1.0, "neighbours": 2, "reach": 1.0},
                                  FAMILY.layout("puzzle-3x3-play-v0"), (12, 13, 14))
    np.testing.assert_array_equal(presses.toggles[0], cross)
    assert not presses.toggles[1:].any()
    assert presses.clearance == 1.1 and presses.toggled_at == -3.0
    # the descent's start, the toggle, the rise's end (the last press's episode ends pushed: its toggle)
    np.testing.assert_array_equal(presses.press_rows, [[6 * i + 1, 6 * i + 4, 6 * i + 6] for i in range(3)] +
                                  [[19, 22, 22]])
    np.testing.assert_array_equal(presses.graph.observations, np.array(rows)[[6 * i + j for i in range(4)
                                                                               for j in (0, 1)]])
    np.testing.assert_array_equal(presses.approach, [2 * i + 1 for i in range(4)])
    np.testing.assert_array_equal(presses.pressed, [0, 0, 0, 0])


def test_a_puzzles_validation_goals_are_pressable():
    """:func:`protocol.pressable` is Lights Out's reach: every change on 3x3, exactly those some combination of
    presses makes on 4x4 (4096 of 65 536; checked on 300 drawn against every combination); so every puzzle validation
    task can be solved."""
    combinations = (np.arange(1 << 16)[:, None] >> np.arange(16)) & 1
    made = set(((combinations @ lights_out(4, 4).astype(np.int64)) % 2 @ (1 << np.arange(16))).tolist())
    assert len(made) == 4096
    rng = np.random.default_rng(0)
    for _ in range(300):
        init, goal = rng.integers(0, 2, (2, 16))
        assert protocol.pressable(init, goal, 4, 4) == (int((init ^ goal) @ (1 << np.arange(16))) in made)
    assert all(protocol.pressable(np.zeros(9, int), (c >> np.arange(9)) & 1, 3, 3) for c in range(512))
    for name in ("puzzle-3x3-play-v0", "puzzle-4x4-play-v0"):
        spec = parse_dataset_name(name)
        env = make_env(spec.scene.env_id)
        rows = env.unwrapped._num_rows
        for task in protocol.validation_tasks(spec, env):
            assert protocol.pressable(task["init_button_states"], task["goal_button_states"], rows, rows)
        env.close()


def test_a_scenes_parts_are_the_environments():
    """scene's parts as ``graph --objects`` reads them: the slides' columns (the drawer open at its ``opened``), and
    the drawer's box the environment's own (``SceneEnv._is_in_drawer``) at any drawer position, the cube carried."""
    import mujoco

    parts = FAMILY.graph_scene("scene-play-v0")
    assert FAMILY.graph_scene("cube-double-play-v0") is None and FAMILY.graph_scene("puzzle-3x3-play-v0") is None
    env = make_env("scene-v0")
    ob, _ = env.reset(seed=0, options={"task_id": 1})
    u = env.unwrapped
    assert [ob[c] for c in parts.buttons] == [1.0, 1.0]  # task 1's buttons are on
    rng = np.random.default_rng(0)
    agree = 0
    for q in (0.0, -0.08, -0.16):
        u._data.joint("drawer_slide").qpos[0] = q
        mujoco.mj_forward(u._model, u._data)
        ob = u.compute_observation()
        assert ob[parts.slides[0]] == pytest.approx(q * 18.0)
        for _ in range(200):
            world = rng.uniform([0.15, -0.6, -0.05], [0.5, -0.05, 0.2])
            cube = (world - [0.425, 0.0, 0.0]) * 10.0
            inside = parts.in_container(cube, ob[parts.slides[0]])
            assert inside == u._is_in_drawer(world), (q, world)
            agree += inside
    assert agree > 50  # both sides seen
    assert parts.opened == pytest.approx(-0.16 * 18.0)


def test_a_scene_is_reached_one_part_at_a_time():
    """Toward task 4's goal (the cube put in the closed drawer, button 0 on at the end): button 0 pressed (the drawer
    is locked), the drawer opened, the cube put where the goal has it, as the open drawer holds it, the drawer closed;
    then nothing. Toward task 2's (the drawer and the window closed, both locked again): each slide unlocked then
    moved, then each button pressed back."""
    from bridgeplan.graph import SceneSteps

    parts = FAMILY.graph_scene("scene-play-v0")
    steps = SceneSteps([], parts)

    def state(cube, buttons, drawer, window):
        s = np.zeros(40)
        s[list(parts.cube)] = (np.asarray(cube) - [0.425, 0.0, 0.0]) * 10.0
        s[list(parts.buttons)] = buttons
        s[list(parts.slides)] = drawer * 18.0, window * 15.0
        return s

    table, drawer = (0.35, 0.05, 0.02), (0.33, -0.356, 0.066)
    goal = state(drawer, (1, 0), 0.0, 0.0)
    assert steps.next_step(state(table, (0, 0), 0.0, 0.0), goal) == (1, {29: 1.0})
    assert steps.next_step(state(table, (1, 0), 0.0, 0.0), goal) == (3, {36: pytest.approx(-2.88)})
    graph, target = steps.next_step(state(table, (1, 0), -0.16, 0.0), goal)
    opened = (np.asarray(drawer) + [0.0, 0.16, 0.0] - [0.425, 0.0, 0.0]) * 10.0  # the drawer slid 0.16 m toward +y
    assert graph == 0 and list(target) == list(parts.cube)
    np.testing.assert_allclose(list(target.values()), opened)
    in_open = state(np.asarray(drawer) + [0.0, 0.16, 0.0], (1, 0), -0.16, 0.0)
    assert steps.next_step(in_open, goal) == (3, {36: 0.0})
    assert steps.next_step(state(drawer, (1, 0), 0.0, 0.0), goal) is None
    assert steps.next_step(state(table, (1, 0), -0.005, 0.0), goal) == (3, {36: pytest.approx(-2.88)})  # closed
    # the cube out of the drawer: the drawer opened first, whatever the cube's goal
    out = state(table, (1, 0), 0.0, 0.0)
    assert steps.next_step(state(drawer, (1, 0), 0.0, 0.0), out) == (3, {36: pytest.approx(-2.88)})
    # task 2
    goal = state(table, (0, 0), 0.0, 0.0)
    assert steps.next_step(state(table, (0, 0), -0.16, 0.2), goal) == (1, {29: 1.0})
    assert steps.next_step(state(table, (1, 0), -0.16, 0.2), goal) == (3, {36: 0.0})
    assert steps.next_step(state(table, (1, 0), 0.0, 0.2), goal) == (2, {33: 1.0})
    assert steps.next_step(state(table, (1, 1), 0.0, 0.2), goal) == (4, {38: 0.0})
    assert steps.next_step(state(table, (1, 1), 0.0, 0.0), goal) == (1, {29: 0.0})
    assert steps.next_step(state(table, (0, 1), 0.0, 0.0), goal) == (2, {33: 0.0})
    assert steps.next_step(goal, goal) is None
    assert steps.path(goal, goal).shape == (1, 40) and steps.chosen == [-1]


def test_a_scenes_path_chains_its_steps():
    """A path takes the steps one after another, each from where the last left the arm and the parts: toward task 4's
    goal, button 0, the drawer opened, the cube put in, the drawer closed (the cube carried with it: done); a step
    whose search finds no path ends the chain."""
    from bridgeplan.graph import GraphDecisions, SceneSteps

    class Straight:  # a graph whose path goes straight to the goal asked for
        layout = FAMILY.layout("scene-play-v0")

        def __init__(self, found=True, long=2):
            self.queries, self.found, self.long = [], found, long

        def path(self, start, goal):
            self.queries.append((2, self.found, 1))
            return np.stack([start] * (self.long - 1) + [goal])

    parts = FAMILY.graph_scene("scene-play-v0")
    start, goal = np.zeros(40), np.zeros(40)
    start[list(parts.cube)] = (0.35 - 0.425) * 10, 0.5, 0.2
    goal[list(parts.cube)] = (0.33 - 0.425) * 10, -3.56, 0.66
    goal[parts.buttons[0]] = 1.0
    goal[12:15] = 9.0  # the arm's columns of a goal: no part's
    steps = SceneSteps([Straight() for _ in range(5)], parts)
    path = steps.path(start, goal)
    assert steps.chosen == [1, 3, 0, 3] and len(path) == 5
    np.testing.assert_allclose(path[2, parts.slides[0]], -2.88)
    np.testing.assert_allclose(path[3, list(parts.cube)], goal[list(parts.cube)] + [0.0, 1.6, 0.0])
    placed = path[3].copy()
    placed[parts.slides[0]] = -2.88  # as the chain had it: the drawer open, the cube in it
    ended = steps.after(placed, path[4], {parts.slides[0]: 0.0})
    np.testing.assert_allclose(ended[list(parts.cube)], goal[list(parts.cube)])  # carried in by the drawer
    lost = SceneSteps([Straight(), Straight(found=False), *(Straight() for _ in range(3))], parts)
    assert len(lost.path(start, goal)) == 2 and lost.chosen == [1]
    # where each episode's first step ends (its path's index), for a replan there (--replan-after-step)
    source = GraphDecisions(steps, 8).source(2)
    source(np.stack([start, goal]), np.stack([goal, goal]), np.array([1, 0]), 0)
    assert source.step_ends.tolist() == [math.inf, 1]
    steps.graphs[1] = Straight(long=4)  # the press three steps long
    source(start[None], goal[None], np.array([0]), 1)
    assert source.step_ends.tolist() == [3, 1]


def test_a_scenes_plan_says_where_its_cube_should_be():
    """A step's path holds the parts it does not move where they are (its graph's states are another episode's), the
    cube in the drawer carried with the drawer it slides; the plan's drift is the cube's distance from it
    (``--replan-object-tolerance``)."""
    from bridgeplan.graph import GraphSource, SceneSteps

    parts = FAMILY.graph_scene("scene-play-v0")

    class Graph:  # what held asks of a part's graph: its layout
        layout = FAMILY.layout("scene-play-v0")

    steps = SceneSteps([Graph()], parts)
    box = parts.slides[parts.container]
    state = np.zeros(40)
    state[list(parts.cube)] = (0.33 - 0.425) * 10, -3.56 + 1.6, 0.66  # in the drawer, opened 0.16 m
    state[box], state[list(parts.buttons)] = -2.88, (1.0, 0.0)
    piece = np.random.default_rng(0).normal(size=(3, 40))  # another episode's states
    piece[:, box] = -2.88, -1.44, 0.0  # the drawer closing
    plan = steps.held(piece.copy(), state, {box: 0.0})
    others = [c for c in FAMILY.layout("scene-play-v0").goal if c not in (box, *parts.cube)]
    np.testing.assert_array_equal(plan[:, others], np.repeat(state[None, others], 3, axis=0))
    closing = np.outer([0.0, 0.5, 1.0], [0.0, 1.6, 0.0])  # the cube carried in as the drawer closes
    np.testing.assert_allclose(plan[:, list(parts.cube)], state[list(parts.cube)] - closing)
    np.testing.assert_array_equal(plan[:, 12:15], piece[:, 12:15])  # the arm as the graph's path has it
    assert steps.drifting == (parts.cube,) and GraphSource(steps, 8).drifts
    pushed = plan[1].copy()
    pushed[parts.cube[0]] += 0.7
    ages = np.array([1, 1])
    np.testing.assert_allclose(steps.drift(np.stack([plan[1], pushed]), np.stack([plan, plan]), ages), [0.0, 0.7])


def test_a_scenes_graphs_are_its_parts(tmp_path):
    """``graph --objects`` on scene: one graph per part over the effector and that part's columns, at the family's
    radius (scene's own is for the graph over all its parts); a goal that turns button 0 over is searched in its
    graph, the path ending with the button turned as the data turned it."""
    from bridgeplan.envs.ogbench_manipulation import GRAPH
    from bridgeplan.graph import SceneSteps, for_stream

    generate_dataset("scene-play-v0", tmp_path, seed=0, episodes=3, episode_steps=301, progress=False)
    stream = FAMILY.load_stream(str(tmp_path / "scene-play-v0.npz"), "scene-play-v0")
    steps, settings = for_stream(stream, FAMILY, {"keep": 2}, objects=True)
    assert isinstance(steps, SceneSteps) and settings["radius"] == GRAPH["radius"]
    parts = [(19, 20, 21), (29,), (33,), (36,), (38,)]
    assert [g.space.columns for g in steps.graphs] == [(12, 13, 14, *p) for p in parts]
    assert [g.space.goal for g in steps.graphs] == parts
    on = stream.states[:, 29] > 0.5
    turned = np.flatnonzero(on[1:] != on[:-1])
    assert len(turned), "the tiny data never presses button 0"
    start = stream.states[turned[0] - 40 if turned[0] >= 40 else 0]
    goal = start.copy()
    goal[29] = 1.0 - round(start[29])
    goal[33] = round(start[33])
    path = steps.path(start, goal)
    assert steps.chosen == [1] and path[-1, 29] == goal[29]
    assert steps.summary()["paths_per_part"] == [0, 1, 0, 0, 0]
    # --hand: the window's graph and its button's (button 1) measure the hand's opening too, not as a goal column
    held, _ = for_stream(stream, FAMILY, {"keep": 2}, objects=True, hand=True)
    hand = [(), (), (17,), (), (17,)]
    assert [g.space.columns for g in held.graphs] == [(12, 13, 14, *h, *p) for h, p in zip(hand, parts)]
    assert [g.space.goal for g in held.graphs] == parts
    with pytest.raises(BridgeplanError, match="give --objects"):
        for_stream(stream, FAMILY, {"keep": 2}, hand=True)
