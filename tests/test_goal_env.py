"""A user's own environment (``bridgeplan.envs.goal_env``) end to end: a tiny goal-reaching gymnasium environment and
its dataset made here, in OGBench's npz format and Minari's, declared by a spec file; DDPM, the bridge and flow
trained, planned and evaluated through the real CLI, the dataset graph too; and its bad inputs refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bridgeplan.cli import main
from bridgeplan.envs import family_of
from tests.test_bad_inputs import refused

STEP = 0.1
"""The point moves by STEP x its action (each component in [-1, 1])."""
ENV_SOURCE = f'''
import gymnasium as gym
import numpy as np


class Reach(gym.Env):
    """A point in [-1, 1]^2 that moves by {STEP} x its action toward a goal drawn at reset. Its state is (x, c, y):
    the goal is columns 0 and 2; c, between them, is the distance the last step moved (what no goal says)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, (3,))
    action_space = gym.spaces.Box(-1.0, 1.0, (2,))

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.xy = self.np_random.uniform(-1, 1, 2)
        self.goal = self.np_random.uniform(-1, 1, 2)
        self.moved = 0.0
        return self._obs(), {{"goal": self.goal.copy()}}

    def _obs(self):
        return np.array([self.xy[0], self.moved, self.xy[1]])

    def step(self, action):
        before = self.xy.copy()
        self.xy = np.clip(self.xy + {STEP} * np.clip(action, -1, 1), -1, 1)
        self.moved = float(np.linalg.norm(self.xy - before))
        success = bool(np.linalg.norm(self.xy - self.goal) < 0.1)
        return self._obs(), float(success), success, False, {{"success": success}}


def make_env():
    return Reach()
'''
EPISODES, EPISODE_STEPS = 300, 40


def expert_data(seed: int = 0) -> dict[str, np.ndarray]:
    """A noisy expert's episodes (each a random start and goal, the goal reached and held), stepped by the
    environment's own rule: OGBench's arrays, one row per step (the state before the action, the action)."""
    rng = np.random.default_rng(seed)
    obs, actions, terminals = [], [], []
    for _ in range(EPISODES):
        xy, goal, moved = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2), 0.0
        for t in range(EPISODE_STEPS):
            a = np.clip((goal - xy) / STEP + rng.normal(0, 0.3, 2), -1, 1)
            obs.append([xy[0], moved, xy[1]])
            actions.append(a)
            terminals.append(t == EPISODE_STEPS - 1)
            before, xy = xy, np.clip(xy + STEP * a, -1, 1)
            moved = float(np.linalg.norm(xy - before))
    return {"observations": np.array(obs), "actions": np.array(actions), "terminals": np.array(terminals)}


def write_minari(folder: Path, data: dict[str, np.ndarray]) -> Path:
    """The same episodes in Minari's layout (each episode's T + 1 observations and T actions)."""
    import h5py

    (folder / "data").mkdir(parents=True)
    (folder / "data" / "metadata.json").write_text(json.dumps({"dataset_id": "reach/expert-v0"}))
    ends = np.flatnonzero(data["terminals"])
    with h5py.File(folder / "data" / "main_data.hdf5", "w") as f:
        for k, (lo, hi) in enumerate(zip(np.r_[0, ends[:-1] + 1], ends + 1)):
            g = f.create_group(f"episode_{k}")
            # the episode's last row has its action; its next state is not in the npz: Minari's form drops that row
            g["observations"] = data["observations"][lo:hi]
            g["actions"] = data["actions"][lo:hi - 1]
    return folder


@pytest.fixture(scope="module")
def reach(tmp_path_factory) -> Path:
    """The spec file of the environment, its module and its npz dataset in one folder."""
    root = tmp_path_factory.mktemp("reach")
    (root / "reach_env.py").write_text(ENV_SOURCE)
    np.savez(root / "reach.npz", **expert_data())
    (root / "reach.toml").write_text('env = "reach_env.py:make_env"\ndataset = "reach.npz"\ngoal = [0, 2]\n'
                                     "episode_steps = 60\nepisodes = 40\nhorizon = 16\nstride = 2\n")
    return root / "reach.toml"


def test_the_spec_declares_the_environment_and_its_data_gives_the_columns(reach):
    family = family_of(str(reach))
    assert family.name == "goal-env"
    layout = family.layout(str(reach))
    assert (layout.act_dim, layout.obs_dim, layout.goal_dim) == (2, 3, 2) and layout.rest_columns() == [2]
    stream = family.load_stream(str(reach.parent / "reach.npz"), str(reach))
    raw = np.load(reach.parent / "reach.npz")
    assert len(stream) == EPISODES * EPISODE_STEPS and stream.episodes == EPISODES
    assert stream.segment_starts.tolist() == list(range(0, EPISODES * EPISODE_STEPS, EPISODE_STEPS))
    # the plan's order: the goal's columns (x, y) first, then c
    np.testing.assert_array_equal(stream.states, raw["observations"][:, [0, 2, 1]])
    minari = family.load_stream(str(write_minari(reach.parent / "reach-minari", raw)), str(reach))
    per_episode = stream.states.reshape(EPISODES, EPISODE_STEPS, 3)
    np.testing.assert_array_equal(minari.states, per_episode[:, :-1].reshape(-1, 3))
    assert minari.segment_starts.tolist() == list(range(0, EPISODES * (EPISODE_STEPS - 1), EPISODE_STEPS - 1))


def test_the_controller_fitted_on_the_data_steps_onto_its_target(reach):
    """The inverse dynamics of the data: exact for this environment's linear step, within its action bounds."""
    body = family_of(str(reach)).body(str(reach))
    states = np.array([[0.0, 0.0, 0.0], [0.5, -0.5, 0.1]])
    targets = states.copy()
    targets[:, :2] += [[0.05, -0.02], [0.5, 0.0]]  # the second is beyond one step: saturated
    np.testing.assert_allclose(body.track(states, targets), [[0.5, -0.2], [1.0, 0.0]], atol=0.02)
    # pursuit: a step at the data's pace toward the waypoint, the lookahead ten such steps
    pace = family_of(str(reach)).load_stream(str(reach.parent / "reach.npz"), str(reach)).pace()
    assert body.default_lookahead == pytest.approx(10 * pace)
    action = body.pursue(states[:1], np.array([[3.0, 4.0]]))
    np.testing.assert_allclose(STEP * action, [[0.6 * pace, 0.8 * pace]], atol=0.002)


def test_the_priors_hold_what_a_goal_leaves_free():
    """A state with a column beyond the goal's (the plan's order: x, y, c): the goal leaves c free (NaN), the line
    and the coarse line hold it at the start's, the learned prior sees the start's in its place, as it was trained."""
    import torch

    from bridgeplan.nets.prior_mlp import PriorMLP
    from bridgeplan.normalizer import Normalizer
    from bridgeplan.priors import CoarsePrior, LearnedPrior, LinePrior, train_prior_loss
    from bridgeplan.trajectory import Layout

    layout = Layout("reach state", act_dim=2, obs_dim=3, position=0, velocity=None, rest=True)
    norm = Normalizer((-1.0, -1.0, -1.0, -1.0, 0.0), (1.0, 1.0, 1.0, 1.0, 0.2))
    start = np.array([[-0.5, 0.5, 0.1]])
    goal = layout.at_rest(np.array([[0.5, -0.5]]))
    assert np.isnan(goal[0, 2]) and goal[0, :2].tolist() == [0.5, -0.5]
    cond = {t: torch.as_tensor(norm.normalize(s, layout.state_columns), dtype=torch.float32)
            for t, s in ((0, start), (7, goal))}
    for prior in (LinePrior(norm, layout), CoarsePrior(norm, layout)):
        states = layout.states(norm.unnormalize(prior.sample(cond, 8, 1).double().numpy()))
        np.testing.assert_allclose(states[0, :, 2], 0.1, atol=1e-6)  # c held, at the goal too
        np.testing.assert_allclose(states[0, [0, 7], :2], [[-0.5, 0.5], [0.5, -0.5]], atol=1e-6)
    net = PriorMLP(3, 8, 5)
    x = LearnedPrior(net).sample(cond, 8, 1)
    filled = torch.where(torch.isnan(cond[7]), cond[0], cond[7])
    torch.testing.assert_close(x[0, 1:7], net(cond[0], filled)[0, 1:7].detach())
    window = torch.randn(4, 8, 5)
    expected = torch.mean((net(window[:, 0, 2:], torch.cat([window[:, -1, 2:4], window[:, 0, 4:]], 1)) - window) ** 2)
    torch.testing.assert_close(train_prior_loss(net, window, layout), expected)


def _eval(run: Path, *flags) -> dict:
    out = run / "eval.json"
    assert main(["eval", str(run), "--device", "cpu", "--no-progress", "--out", str(out), *flags]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize("process, prior, steps", [
    ("bridge", "line", 200),  # the thesis's bridge in the default run; DDPM, flow and the learned prior in -m slow
    *(pytest.param(*case, marks=pytest.mark.slow) for case in [("ddpm", None, 400), ("flow", "line", 200),
                                                               ("bridge", "learned", 200)])])
def test_train_plan_and_evaluate_on_your_own_environment(reach, tmp_path, process, prior, steps):
    """A few hundred steps of a small network (seconds) plan well enough to reach most goals, replanned every 8 steps,
    where the straight line alone, executed alike, reaches about half (its 31-step plans, replanned, slow down as they
    near the goal)."""
    run, data = tmp_path / process, str(reach.parent / "reach.npz")
    learned = []
    if prior == "learned":
        learned = ["--prior-run", str(tmp_path / "prior")]
        assert main(["train-prior", "--maze", str(reach), "--dataset", data, "--preset", "cpu-small", "--steps", "500",
                     "--run-dir", learned[1], "--device", "cpu", "--no-progress"]) == 0
    assert main(["train", "--maze", str(reach), "--dataset", data, "--preset", "cpu-small", "--process", process,
                 *(["--prior", prior] if prior else []), *learned, "--diffusion-steps", "8",
                 "--steps", str(steps), "--checkpoint-every", str(steps), "--batch-size", "64", "--lr", "3e-3",
                 "--seed", "0", "--run-dir", str(run), "--device", "cpu", "--no-progress"]) == 0
    config = json.loads((run / "config.json").read_text())["config"]
    assert config["maze"] == str(reach) and (config["horizon"], config["stride"]) == (16, 2)
    r = _eval(run, "--replan-every", "8")
    assert (r["env"], r["episodes"], r["episode_steps"], r["process"]) == ("reach", 40, 60, process)
    assert r["plans_per_episode"]["mean"] > 1 and r["execution"]["replan_every"] == 8
    # success from the environment's info, beside the straight line alone
    assert 0.3 <= r["floor_line"]["success_rate"] <= 0.7
    assert r["success_rate"] >= max(0.8, r["floor_line"]["success_rate"] + 0.2), r["success_rate"]
    assert r["successes"] == round(r["success_rate"] * 40) and 0 < r["return"]["mean"] <= 1
    # the run as a policy in the user's own loop (its observation and info["goal"] in): it reaches goals as well
    from bridgeplan.policy import PlannerPolicy

    policy, scope = PlannerPolicy.from_run(run, nfe=r["nfe"], replan_every=8, device="cpu"), {}  # eval's NFE
    exec(ENV_SOURCE, scope)
    env, reached = scope["make_env"](), 0
    for episode in range(20):
        obs, info = env.reset(seed=episode)
        policy.reset()
        for _ in range(60):
            obs, _, success, _, _ = env.step(policy(obs, info["goal"]))
            if success:
                reached += 1
                break
    assert reached >= 16, reached  # as `eval` (>= 0.8); 9 of 20 with the columns in the environment's order


def test_a_policy_gets_the_plans_columns_and_the_environments_action_box(reach, tmp_path):
    """What ``PlannerPolicy`` asks the family in a user's own loop: the state in the plan's column order (the goal's
    first), the goal from its columns or a whole goal state, and the actions' box from the environment."""
    family, env = family_of(str(reach)), str(reach)
    state, goal = family.policy_input(env, np.array([0.1, 0.2, 0.3]), np.array([0.5, -0.5]))
    assert state.tolist() == [0.1, 0.3, 0.2] and goal.tolist() == [0.5, -0.5]
    assert family.policy_input(env, np.zeros(3), np.array([0.5, 9.0, -0.5]))[1].tolist() == [0.5, -0.5]
    assert [b.tolist() for b in family.action_bounds(env)] == [[-1, -1], [1, 1]]
    (tmp_path / "slow_env.py").write_text(ENV_SOURCE.replace("Box(-1.0, 1.0, (2,))", "Box(-0.5, 0.5, (2,))"))
    (tmp_path / "slow.toml").write_text(reach.read_text().replace("reach_env.py", "slow_env.py").replace(
        "reach.npz", str(reach.parent / "reach.npz")))
    assert [b.tolist() for b in family.action_bounds(str(tmp_path / "slow.toml"))] == [[-0.5, -0.5], [0.5, 0.5]]


def test_the_dataset_graph_on_your_own_environment(reach, tmp_path):
    out = tmp_path / "graph.json"
    assert main(["graph", "--maze", str(reach), "--dataset", str(reach.parent / "reach.npz"), "--episodes", "20",
                 "--replan-every", "10", "--out", str(out), "--no-progress"]) == 0
    r = json.loads(out.read_text())
    assert r["graph"]["paths_found"] == 1.0 and r["graph"]["radius"] == pytest.approx(2.5 * r["graph"]["step"])
    assert r["success_rate"] >= 0.9


STUDY = """
[dataset]
maze = "{spec}"
path = "{dataset}"

[training]
steps = 200
checkpoint_every = 200
seeds = [0]
diffusion_steps = 8
batch_size = 64
lr = 3e-3
device = "cpu"

[evaluation]
episodes = 20
workers = 1

[runs.flow-line]
process = "flow"
prior = "line"

[[evaluations]]
command = "eval"
runs = ["flow-line"]
args = {{ replan_every = 8 }}
out = "reach/flow-line-replan8-seed{{eval_seed}}.json"

[[evaluations]]
command = "graph"
runs = []
args = {{ replan_every = 10 }}
out = "reach/graph-replan10-seed{{eval_seed}}.json"
"""


def test_a_study_of_your_own_environment(reach, tmp_path, monkeypatch):
    """A study file takes the spec as its maze: `study run` trains its named run and writes its evaluations."""
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "reach.toml").write_text(STUDY.format(spec=reach, dataset=reach.parent / "reach.npz"))
    monkeypatch.chdir(tmp_path)
    assert main(["study", "run", "reach", "--no-progress", "--root", str(tmp_path)]) == 0
    planner = json.loads((tmp_path / "results" / "reach" / "reach" / "flow-line-replan8-seed0.json").read_text())
    graph = json.loads((tmp_path / "results" / "reach" / "reach" / "graph-replan10-seed0.json").read_text())
    assert (planner["env"], planner["episodes"], planner["process"], planner["step"]) == ("reach", 20, "flow", 200)
    assert planner["success_rate"] >= 0.8 and graph["success_rate"] >= 0.9 and graph["method"] == "dataset graph"


GRAPH_STUDY = """
[dataset]
maze = "{spec}"
path = "{dataset}"

[training]
seeds = [0, 1]

[evaluation]
episodes = 2

[[evaluations]]
command = "graph"
runs = []
out = "{name}/graph-seed{{eval_seed}}.json"
"""


def graph_study_of(reach, root: Path, name: str, reset_source: str) -> None:
    """``root/studies/NAME.toml``: :data:`GRAPH_STUDY` (two training seeds' graph evaluations, into NAME/) on the
    reach environment whose ``reset`` is ``reset_source`` (a method's source; ``os`` and ``signal`` imported)."""
    (root / f"{name}_env.py").write_text(ENV_SOURCE + f"""
import os, signal


class Changed(Reach):
{reset_source}

def make_changed():
    return Changed()
""")
    spec = root / f"{name}.toml"
    spec.write_text(reach.read_text().replace('"reach_env.py:make_env"', f'"{name}_env.py:make_changed"').replace(
        '"reach.npz"', f'"{reach.parent / "reach.npz"}"'))
    (root / "studies").mkdir()
    (root / "studies" / f"{name}.toml").write_text(GRAPH_STUDY.format(spec=spec, dataset=reach.parent / "reach.npz",
                                                                      name=name))


def test_a_study_worker_killed_ends_the_study_with_one_error(reach, tmp_path):
    """Two workers, each a training seed's graph evaluation; the environment SIGKILLs the first process that resets
    it (as the out-of-memory killer would): ``study run`` ends (in seconds, not never) with one error line naming the
    worker that died and the JSON it was writing, exit 2, the other worker's JSON kept."""
    import os
    import subprocess
    import sys

    claimed = tmp_path / "claimed"
    graph_study_of(reach, tmp_path, "dying", f"""
    def reset(self, seed=None, options=None):
        try:
            os.close(os.open({str(claimed)!r}, os.O_CREAT | os.O_EXCL))
        except FileExistsError:
            return super().reset(seed=seed, options=options)
        os.kill(os.getpid(), signal.SIGKILL)
""")
    r = subprocess.run([sys.executable, "-m", "bridgeplan.cli", "study", "run", "dying", "--workers", "2",
                        "--no-progress", "--root", str(tmp_path)], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    written = sorted(p.name for p in (tmp_path / "results" / "dying" / "dying").iterdir())
    assert len(written) == 1 and claimed.exists()
    dead = 1 if written == ["graph-seed0.json"] else 0
    assert lines[0].startswith(f"error: the worker of training seed {dead} (runs: none) was killed by SIGKILL (likely "
                               f"out of memory) while running `graph` for ")
    assert lines[0].endswith(f"graph-seed{dead}.json; what the others wrote is kept: the same command again runs "
                             f"what is missing")


@pytest.mark.slow
def test_a_declared_study_runs_its_units_as_ray_tasks(reach, tmp_path):
    """``--backend ray`` runs a study's declared evaluations as Ray tasks, as it runs a grid's runs (one executor
    for both): each training seed's graph evaluation is made in a process other than the command's."""
    import os

    pytest.importorskip("ray")
    pids = tmp_path / "pids"
    graph_study_of(reach, tmp_path, "graphs", f"""
    def reset(self, seed=None, options=None):
        with open({str(pids)!r}, "a") as f:
            f.write(f"{{os.getpid()}}\\n")
        return super().reset(seed=seed, options=options)
""")
    assert main(["study", "run", "graphs", "--backend", "ray", "--no-progress", "--root", str(tmp_path)]) == 0
    written = sorted(p.name for p in (tmp_path / "results" / "graphs" / "graphs").iterdir())
    assert written == ["graph-seed0.json", "graph-seed1.json"]
    assert pids.exists() and str(os.getpid()) not in pids.read_text().split()


def test_coarse_plans_without_a_wall_map():
    """A hierarchy's diagnostics of its coarse plans in a family without a wall map: no wall shares, the arrival."""
    from bridgeplan.hierarchy import COARSE_ARRIVAL, coarse_diagnostics
    from bridgeplan.trajectory import KINEMATIC_POINT

    dense = np.zeros((2, 5, 2))
    dense[1, 3:, 0] = 2 * COARSE_ARRIVAL  # the second plan arrives at step 3 at a goal 2 x COARSE_ARRIVAL away
    goals = np.array([[0.0, 0.0], [2 * COARSE_ARRIVAL, 0.0]])
    assert coarse_diagnostics(dense, goals, None, KINEMATIC_POINT) == {"in_walls": None, "crossing_walls": None,
                                                                       "arrival_step": 1.5}


@pytest.mark.slow
def test_a_hierarchy_on_your_own_environment(reach, tmp_path):
    """A high level (flow from the line, every 3rd step) and a low level through its subgoals (flow from the coarse
    line): the coarse plans' diagnostics without a wall map, the goals reached."""
    common = ["--maze", str(reach), "--dataset", str(reach.parent / "reach.npz"), "--preset", "cpu-small",
              "--diffusion-steps", "8", "--steps", "200", "--checkpoint-every", "200", "--batch-size", "64", "--lr",
              "3e-3", "--device", "cpu", "--no-progress", "--process", "flow"]
    assert main(["train", *common, "--prior", "line", "--horizon", "12", "--stride", "3", "--run-dir",
                 str(tmp_path / "high")]) == 0
    assert main(["train", *common, "--prior", "coarse", "--horizon", "16", "--stride", "1", "--subgoal-every", "3",
                 "--run-dir", str(tmp_path / "low")]) == 0
    out = tmp_path / "hierarchy.json"
    assert main(["hierarchy", "eval", str(tmp_path / "high"), str(tmp_path / "low"), "--nfe-high", "4", "--nfe-low",
                 "2", "--device", "cpu", "--no-progress", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["coarse_plans"]["in_walls"] is None and r["success_rate"] >= 0.8


@pytest.mark.slow
def test_ogbench_pointmaze_declared_as_your_own_environment(tmp_path, medium_navigate):
    """OGBench's own environment and dataset through a spec file alone: the controller fitted on the data finds its
    point's step (0.2 per unit of action), the graph's settings in the data's pace come out as OGBench's family's
    (a jump of 0.5, reach 2.0, within a few hundredths), and its paths reach the goals of the environment's resets."""
    (tmp_path / "ogb_env.py").write_text("import gymnasium as gym\nimport ogbench  # noqa: F401\n\n\n"
                                         "def make():\n    return gym.make('pointmaze-medium-v0')\n")
    spec = tmp_path / "ogb.toml"
    spec.write_text(f'env = "ogb_env.py:make"\ndataset = "{medium_navigate}"\ngoal = [0, 1]\n')
    body = family_of(str(spec)).body(str(spec))
    np.testing.assert_allclose(body.track(np.zeros((1, 2)), np.array([[0.1, -0.05]])), [[0.5, -0.25]], atol=0.02)
    out = tmp_path / "graph.json"
    assert main(["graph", "--maze", str(spec), "--dataset", medium_navigate, "--episodes", "50", "--out", str(out),
                 "--no-progress"]) == 0
    r = json.loads(out.read_text())
    assert r["graph"]["radius"] == pytest.approx(0.5, abs=0.02) and r["graph"]["reach"] == pytest.approx(2.0, abs=0.1)
    assert r["episode_steps"] == 1000 and r["success_rate"] >= 0.9


# --- bad input: one error line, exit 2, nothing written -------------------------------------------------------------


def test_a_dataset_of_another_family(capsys, reach, tmp_path, tiny_dataset):
    line = refused(capsys, "train", "--maze", reach, "--dataset", tiny_dataset, "--preset", "cpu-small",
                   "--steps", "1", "--run-dir", tmp_path / "run", watch=tmp_path)
    assert "its states have 4 columns and its actions 2, the environment's 3 and 2" in line
    line = refused(capsys, "train", "--maze", "umaze", "--dataset", reach.parent / "reach.npz", "--preset",
                   "cpu-small", "--steps", "1", "--run-dir", tmp_path / "run", watch=tmp_path)
    assert "npz file (OGBench's format), not a Maze2D dataset" in line


def test_a_run_of_one_family_on_another_familys_tasks(capsys, reach, tmp_path, tiny_runs):
    line = refused(capsys, "graph", "--maze", reach, "--low", tiny_runs["ddpm"], "--out", tmp_path / "g.json",
                   watch=tmp_path)
    assert "the low level was trained on umaze, not" in line


@pytest.mark.parametrize("spec, message", [
    (None, "no environment spec file at"),
    ('env = "reach_env.py:make_env"\ngoal = [0, 2]\n', "no 'dataset'"),
    ('env = "reach_env.py:make_env"\ndataset = "reach.npz"\ngoal = [0, 3]\nepisode_steps = 60\n',
     "are not all in the 3-column state"),
    ('env = "reach_env.py:nothing"\ndataset = "reach.npz"\ngoal = [0, 2]\n', "cannot be loaded"),
    ('env = "reach_env.py:make_env"\ndataset = "reach.npz"\ngoal = [0, 2]\nhorizon = 0\n', "horizon must be"),
    ('env = "reach_env.py:make_env"\ndataset = "reach.npz"\ngoal = [0, 2]\ncolour = 1\n', "unknown key 'colour'"),
])
def test_a_bad_spec(capsys, reach, spec, message):
    bad = reach.parent / "bad.toml"
    if spec is None:
        bad.unlink(missing_ok=True)
    else:
        bad.write_text(spec)
    line = refused(capsys, "train", "--maze", bad, "--dataset", reach.parent / "reach.npz", "--preset", "cpu-small",
                   "--steps", "1", "--run-dir", reach.parent / "never", watch=reach.parent)
    assert message in line


def test_an_unknown_environment_names_every_family(capsys, tmp_path):
    line = refused(capsys, "graph", "--maze", "nowhere", "--dataset", tmp_path, watch=tmp_path)
    assert "unknown environment 'nowhere'" in line and "user-declared: the path of a spec file" in line
