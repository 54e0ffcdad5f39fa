"""GCBC on hand-made OGBench-format datasets: goal sampling, training, exact resume, imitation, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.gcbc import GCBCConfig, GoalDataset, load_policy, policy_snapshots, read_metrics, train_gcbc

LENGTHS = (5, 2, 7, 1, 3, 6)  # raw steps per trajectory, as OGBench's files store them (a 1-step one too)
TINY = dict(hidden_dims=(16, 16), batch_size=32, log_every=5, checkpoint_every=10, device="cpu")


def write_npz(path: Path, observations: np.ndarray, actions: np.ndarray, terminals: np.ndarray) -> Path:
    """A dataset in OGBench's npz format (``qpos``/``qvel`` as the generator writes them)."""
    obs = observations.astype(np.float32)
    np.savez(path, observations=obs, actions=actions.astype(np.float32), terminals=terminals.astype(bool),
             qpos=obs, qvel=np.zeros_like(obs))
    return path


def labelled_dataset(path: Path, lengths=LENGTHS) -> Path:
    """Observation = (trajectory number, time in it): a goal's origin can be read off its value."""
    obs = np.concatenate([np.stack([np.full(n, k), np.arange(n)], 1) for k, n in enumerate(lengths)])
    terminals = np.concatenate([np.arange(n) == n - 1 for n in lengths])
    return write_npz(path, obs, np.zeros_like(obs), terminals)


def sampled(path: Path, n: int = 20_000, seed: int = 0, **probs) -> tuple[np.ndarray, np.ndarray]:
    data = GoalDataset(path, **probs)
    idx, goal = data.sample(n, np.random.default_rng(seed))
    return data.observations[idx], data.observations[goal]


def test_goals_are_future_states_of_the_same_trajectory(tmp_path):
    states, goals = sampled(labelled_dataset(tmp_path / "d.npz"))
    length = np.asarray(LENGTHS)[states[:, 0].astype(int)]
    assert (goals[:, 0] == states[:, 0]).all()  # never across a terminal
    assert (states[:, 1] <= length - 2).all()  # a trajectory's last state is no sample (no next state) ...
    assert (goals[:, 1] <= length - 2).all()  # ... and, in OGBench's compact form, no goal either
    final = states[:, 1] == length - 2
    assert (goals[~final, 1] > states[~final, 1]).all()  # strictly in the future ...
    assert (goals[final] == states[final]).all()  # ... except at the final state, its own goal
    # uniform over the future: every future state of the 7-step trajectory's first state shows up
    first_of_long = (states[:, 0] == 2) & (states[:, 1] == 0)
    assert set(goals[first_of_long, 1].astype(int)) == {1, 2, 3, 4, 5}


def test_uniform_goals_follow_ogbench_rounding(tmp_path):
    """From t = 0 of the 7-step trajectory (final state 5): round(1 u + 5 (1 - u)), so 1 and 5 at 1/8, the rest 1/4."""
    states, goals = sampled(labelled_dataset(tmp_path / "d.npz"), n=200_000)
    g = goals[(states[:, 0] == 2) & (states[:, 1] == 0), 1].astype(int)
    freq = np.bincount(g, minlength=6)[1:] / len(g)
    np.testing.assert_allclose(freq, [1 / 8, 1 / 4, 1 / 4, 1 / 4, 1 / 8], atol=0.02)


def test_current_goal_and_random_goal(tmp_path):
    path = labelled_dataset(tmp_path / "d.npz")
    states, goals = sampled(path, p_curgoal=1.0, p_trajgoal=0.0)
    assert (goals == states).all()
    states, goals = sampled(path, p_trajgoal=0.0, p_randomgoal=1.0)
    assert (goals[:, 0] != states[:, 0]).mean() > 0.5  # random states: mostly another trajectory
    length = np.asarray(LENGTHS)[goals[:, 0].astype(int)]
    assert (goals[:, 1] <= length - 2).all()  # but valid states only
    states, goals = sampled(path, p_curgoal=0.5, p_trajgoal=0.5)
    assert 0.45 < (goals == states).all(1).mean() < 0.65  # half current, plus the final states' own goals


def test_geometric_goals_stay_in_the_trajectory(tmp_path):
    states, goals = sampled(labelled_dataset(tmp_path / "d.npz"), geom_sample=True, discount=0.5)
    length = np.asarray(LENGTHS)[states[:, 0].astype(int)]
    assert (goals[:, 0] == states[:, 0]).all()
    assert (goals[:, 1] <= length - 2).all()
    offsets = (goals[:, 1] - states[:, 1])[states[:, 1] + 3 <= length - 2]  # clamping cannot reach these
    np.testing.assert_allclose(np.bincount(offsets.astype(int), minlength=3)[1:3] / len(offsets), [0.5, 0.25],
                               atol=0.02)


def line_dataset(path: Path, trajectories: int = 300, length: int = 16, seed: int = 0) -> Path:
    """Straight lines at a constant action 0.5 u (u a random unit vector per trajectory): the action that
    reaches any future goal g from s is 0.5 (g - s) / |g - s|, a closed form to imitate."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, trajectories)
    act = 0.5 * np.stack([np.cos(angle), np.sin(angle)], 1)
    start = rng.uniform(-1, 1, (trajectories, 2))
    t = np.arange(length)[None, :, None]
    obs = start[:, None] + 0.2 * t * act[:, None]
    actions = np.repeat(act[:, None], length, 1)
    terminals = np.zeros((trajectories, length), bool)
    terminals[:, -1] = True
    return write_npz(path, obs.reshape(-1, 2), actions.reshape(-1, 2), terminals.reshape(-1))


def test_loss_decreases(tmp_path):
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz")), steps=100, lr=1e-3, **TINY)
    rows = read_metrics(train_gcbc(config, tmp_path / "run", progress=False))
    assert [r["step"] for r in rows] == list(range(5, 101, 5))
    assert rows[-1]["mse"] < 0.5 * rows[0]["mse"]
    assert rows[-1]["loss"] < rows[0]["loss"]


def test_trained_policy_imitates_the_closed_form(tmp_path):
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz")), steps=1500, lr=3e-3, seed=1,
                        hidden_dims=(64, 64), batch_size=256, log_every=500, checkpoint_every=1500, device="cpu")
    policy = load_policy(train_gcbc(config, tmp_path / "run", progress=False))
    rng = np.random.default_rng(5)
    s = rng.uniform(-1, 1, (500, 2))
    angle = rng.uniform(0, 2 * np.pi, 500)
    u = np.stack([np.cos(angle), np.sin(angle)], 1)
    g = s + rng.uniform(0.2, 1.2, (500, 1)) * u  # within the data's reach (up to 1.4)
    a = policy.act(s.astype(np.float32), g.astype(np.float32))
    assert a.shape == (500, 2) and a.dtype == np.float32
    err = np.linalg.norm(a - 0.5 * u, axis=1)
    assert np.median(err) < 0.08, np.median(err)  # measured 0.04; untrained ~0.5 (the mean starts near 0)
    np.testing.assert_array_equal(a, policy.act(s, g))  # deterministic


def states(run: Path) -> tuple[dict, dict, int]:
    state = torch.load(run / "checkpoint.pt", weights_only=False)
    return state["policy"], state["optimizer"]["state"], state["step"]


def test_resume_is_exact(tmp_path):
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz")), steps=24, lr=1e-3, **TINY)
    straight, interrupted = tmp_path / "straight", tmp_path / "interrupted"
    train_gcbc(config, straight, progress=False)
    train_gcbc(GCBCConfig(**{**config.__dict__, "steps": 12}), interrupted, progress=False)
    assert states(interrupted)[2] == 12
    train_gcbc(config, interrupted, resume=True, progress=False)
    (p1, o1, s1), (p2, o2, s2) = states(straight), states(interrupted)
    assert s1 == s2 == 24
    for key in p1:
        assert torch.equal(p1[key], p2[key]), key
    for key in o1:
        for name in o1[key]:
            assert torch.equal(o1[key][name], o2[key][name]), (key, name)
    assert read_metrics(straight) == [{**r, "steps_per_s": r2["steps_per_s"], "elapsed_seconds": r2["elapsed_seconds"]}
                                      for r, r2 in zip(read_metrics(interrupted), read_metrics(straight))]
    assert [s for s, _ in policy_snapshots(straight)] == [10, 20, 24]
    assert [s for s, _ in policy_snapshots(interrupted)] == [10, 12, 20, 24]
    assert load_policy(policy_snapshots(straight)[1][1]).step == 20
    assert (straight / "config.json").exists()


def test_a_non_finite_loss_stops_training_at_its_step_and_keeps_the_last_checkpoint(tmp_path, monkeypatch):
    """GCBC trains in the planners' loop (``train.run_steps``): the step whose loss is not finite stops training,
    named, and is never saved; the last checkpoint before it stays."""
    import bridgeplan.gcbc

    real = bridgeplan.gcbc._GCBCStep.loss
    calls = []

    def loss(self, obs, actions, rng):
        value, logged = real(self, obs, actions, rng)
        calls.append(1)
        return (value * float("nan") if len(calls) == 13 else value), logged

    monkeypatch.setattr(bridgeplan.gcbc._GCBCStep, "loss", loss)
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz", trajectories=4)), steps=30, **TINY)
    with pytest.raises(BridgeplanError, match=r"loss became nan at step 13; stopped\. The last good checkpoint "
                                              r"\(step 10\)"):
        train_gcbc(config, tmp_path / "run", progress=False)
    assert states(tmp_path / "run")[2] == 10 and [s for s, _ in policy_snapshots(tmp_path / "run")] == [10]


def test_run_directory_mistakes(tmp_path):
    config = GCBCConfig(dataset=str(line_dataset(tmp_path / "d.npz", trajectories=4)), steps=2, **TINY)
    with pytest.raises(BridgeplanError, match="does not exist"):
        train_gcbc(config, tmp_path / "run", resume=True, progress=False)
    train_gcbc(config, tmp_path / "run", progress=False)
    with pytest.raises(BridgeplanError, match="pass --resume"):
        train_gcbc(config, tmp_path / "run", progress=False)
    with pytest.raises(BridgeplanError, match="different config.*lr"):
        train_gcbc(GCBCConfig(**{**config.__dict__, "lr": 1.0, "steps": 4}), tmp_path / "run", resume=True,
                   progress=False)
    other = line_dataset(tmp_path / "other.npz", trajectories=4, seed=1)
    with pytest.raises(BridgeplanError, match="different data"):
        train_gcbc(GCBCConfig(**{**config.__dict__, "dataset": str(other), "steps": 4}), tmp_path / "run",
                   resume=True, progress=False)


@pytest.mark.parametrize("changes,match", [
    (dict(lr=0.0), "lr must be"), (dict(lr=-1e-3), "lr must be"), (dict(lr=float("nan")), "lr must be"),
    (dict(batch_size=0), "batch_size must be"), (dict(steps=0), "steps must be"),
    (dict(hidden_dims=()), "hidden_dims"), (dict(p_trajgoal=0.5), "sum to 1"),
    (dict(p_curgoal=-0.5, p_trajgoal=1.5), ">= 0"), (dict(geom_sample=True, discount=1.0), "discount"),
])
def test_bad_config(changes, match):
    with pytest.raises(BridgeplanError, match=match):
        GCBCConfig(**changes)


def test_bad_dataset_files(tmp_path):
    with pytest.raises(BridgeplanError, match="no dataset file"):
        GoalDataset(tmp_path / "missing.npz")
    (tmp_path / "text.npz").write_text("not an npz")
    with pytest.raises(BridgeplanError, match="cannot read"):
        GoalDataset(tmp_path / "text.npz")
    np.savez(tmp_path / "keys.npz", observations=np.zeros((3, 2)))
    with pytest.raises(BridgeplanError, match="lacks actions, terminals"):
        GoalDataset(tmp_path / "keys.npz")
    open_end = write_npz(tmp_path / "open.npz", np.zeros((3, 2)), np.zeros((3, 2)), np.array([0, 0, 0]))
    with pytest.raises(BridgeplanError, match="last step must end"):
        GoalDataset(open_end)
    singles = write_npz(tmp_path / "singles.npz", np.zeros((2, 2)), np.zeros((2, 2)), np.array([1, 1]))
    with pytest.raises(BridgeplanError, match="no transition"):
        GoalDataset(singles)
    with pytest.raises(BridgeplanError, match="no dataset file"):
        train_gcbc(GCBCConfig(dataset=str(tmp_path / "missing.npz"), **TINY), tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()  # refused before anything is written


def test_cli_train_and_evaluate_on_pointmaze(tmp_path, capsys, monkeypatch):
    """Through the CLI: a tiny generated medium dataset, training, the protocol on the snapshot (one: each
    evaluation runs 5 episodes of up to 1000 steps) through the one evaluation, the policy acting at every step on
    the states and goals the environment gives."""
    import json

    from bridgeplan.cli import main
    from bridgeplan.device import cpu_model

    assert main(["data", "generate", "--maze", "pointmaze-medium-navigate-v0", "--episodes", "4",
                 "--episode-steps", "40", "--out", str(tmp_path), "--no-progress"]) == 0
    data, run = str(tmp_path / "pointmaze-medium-navigate-v0.npz"), tmp_path / "run"
    train = ["gcbc", "train", data, "--run-dir", str(run), "--maze", "medium", "--steps", "4",
             "--batch-size", "8", "--hidden-dims", "8,8", "--checkpoint-every", "4", "--log-every", "2",
             "--device", "cpu", "--no-progress"]
    assert main(train) == 0
    assert "step 4" in capsys.readouterr().out
    assert main(["eval", str(run), "--episodes", "1", "--no-progress", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    saved = json.loads((run / "eval" / "gcbc-step4-ep1-seed0.json").read_text())
    assert saved == row and row["env_id"] == "pointmaze-medium-v0" and row["method"] == "gcbc"
    assert saved["step"] == 4 and saved["episodes"] == 5 and set(saved["tasks"]) == {"1", "2", "3", "4", "5"}
    assert saved["execution"]["controller"] == "policy" and saved["train_seed"] == 0
    assert saved["calls_per_episode"] == np.mean([t["steps"] for t in saved["tasks"].values()])  # one per step
    # at batch 1 the first episode again, every step (the policy's call) timed; one decision (its goal)
    assert saved["step_ms_batch1"]["count"] == saved["tasks"]["1"]["steps"][0]
    assert saved["decision_ms_batch1"]["count"] == 1
    assert saved["environment"]["cpu"] == cpu_model() == json.loads((run / "config.json").read_text())["cpu"]
    # mistakes: one error line, exit 2
    assert main(train) == 2
    assert "pass --resume" in capsys.readouterr().err
    assert main([*train[:-1], "--lr", "0", "--run-dir", str(tmp_path / "r2")]) == 2
    assert capsys.readouterr().err.strip().splitlines() == ["error: lr must be a positive, finite number, got 0.0"]
    assert main(["gcbc", "train", data, "--run-dir", str(tmp_path / "r3"), "--maze", "large"]) == 2
    assert "not a pointmaze-large dataset" in capsys.readouterr().err
    assert main(["eval", str(run), "--snapshot", "3"]) == 2
    assert "no snapshot at step 3" in capsys.readouterr().err
    unnamed = [*train[:train.index("--maze")], *train[train.index("--maze") + 2:]]
    unnamed[unnamed.index("--run-dir") + 1] = str(tmp_path / "r4")
    assert main(unnamed) == 0
    capsys.readouterr()
    assert main(["eval", str(tmp_path / "r4")]) == 2
    assert capsys.readouterr().err.strip() == (f"error: {tmp_path / 'r4'} was trained without --maze: name the "
                                               f"environment its data is of (`bridgeplan graph --maze NAME --low "
                                               f"{tmp_path / 'r4'}`)")
    assert not (tmp_path / "r4" / "eval").exists()
    # the policy acts at every step on the environment's states and goals (the goal is the decision it follows)
    from bridgeplan.gcbc import GCBCPolicy, evaluate_policy
    from bridgeplan.replan import PlanExecutor

    given, seen = [], []
    executor_act, policy_act = PlanExecutor.act, GCBCPolicy.act
    monkeypatch.setattr(PlanExecutor, "act", lambda self, s, g: given.append((s, g)) or executor_act(self, s, g))
    monkeypatch.setattr(GCBCPolicy, "act", lambda self, s, g: seen.append((s, g)) or policy_act(self, s, g))
    evaluate_policy(run, episodes=1, task_ids=(2,))
    assert len(seen) == len(given) > 1
    for (s, g), (ps, pg) in zip(given, seen):
        np.testing.assert_array_equal(ps, s)
        np.testing.assert_array_equal(pg, g)
