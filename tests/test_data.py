"""Generation, the Minari round trip and cache, the episode-joining rule, windows, the D4RL reader."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest
import torch

from bridgeplan.cli import main
from bridgeplan.data.stream import Stream, join_episodes
from bridgeplan.data.windows import WindowDataset, hold_tails, window_starts
from bridgeplan.envs.maze2d.d4rl_io import continuity_breaks, read_d4rl, to_d4rl
from bridgeplan.envs.maze2d.datasets import CACHE_NAME, generate_dataset, load_stream, stream_from_generated
from bridgeplan.envs.maze2d.expert import (
    D_GAIN,
    P_GAIN,
    WAYPOINT_RADIUS,
    WaypointExpert,
    noisy_action,
    pd_action,
    waypoints,
)
from bridgeplan.envs.maze2d.generate import DATA_VERSION, _plan, generate_stream, generate_streams
from bridgeplan.envs.maze2d.grids import GOAL_RADIUS, get_maze
from bridgeplan.envs.maze2d.info import summarize
from bridgeplan.envs.maze2d.minari_io import METADATA_FILE, VERSION_KEY
from bridgeplan.envs.maze2d.rollout import rollout
from bridgeplan.errors import BridgeplanError
from bridgeplan.normalizer import Normalizer
from bridgeplan.trajectory import MAZE2D

UMAZE = get_maze("umaze")


@pytest.fixture(scope="module")
def umaze_stream():
    return generate_stream(UMAZE, 4000, seed=11)


def test_generated_stream_follows_the_recipe(umaze_stream):
    s = umaze_stream
    again = generate_stream(UMAZE, 4000, seed=11)
    np.testing.assert_array_equal(s.observations, again.observations)
    assert not np.array_equal(s.actions, generate_stream(UMAZE, 4000, seed=12).actions)
    assert s.observations.shape == (4001, 4) and s.actions.shape == (4000, 2)
    assert np.abs(s.actions).max() <= 1.0 and np.abs(s.actions).max() == 1.0  # clipped
    assert not continuity_breaks(s.observations).any()  # one physically continuous stretch
    assert UMAZE.is_free_xy(s.observations[:, :2]).all()
    # a new episode (goal) starts exactly when the goal was reached
    assert s.goals_reached == len(s.episode_starts) - 1 > 20
    for k, lo in enumerate(s.episode_starts[1:], start=1):
        assert np.linalg.norm(s.observations[lo, :2] - s.goals[k - 1]) <= GOAL_RADIUS
        assert np.linalg.norm(s.observations[lo, :2] - s.goals[k]) > GOAL_RADIUS
        between = s.observations[s.episode_starts[k - 1] + 1:lo, :2]
        assert (np.linalg.norm(between - s.goals[k - 1], axis=1) > GOAL_RADIUS).all()
    assert (np.abs(s.goals - UMAZE.cell_to_xy(UMAZE.xy_to_cell(s.goals))) <= 0.25).all()
    episodes = list(s.episodes())
    assert len(episodes) == len(s.episode_starts)
    assert all(rew[-1] == 1.0 for _, _, rew, _ in episodes[:-1])


def test_generator_runs_the_expert_and_the_sim():
    """Without noise and jitter, the scalar generator loop equals the batched expert in the batched sim."""
    s = generate_stream(UMAZE, 600, seed=4, jitter=0.0, action_noise=0.0)
    steps = int(s.episode_starts[1]) if len(s.episode_starts) > 1 else 600
    expert = WaypointExpert(UMAZE)
    expert.plan(s.observations[:1, :2], s.goals[:1])
    result = rollout(UMAZE, lambda t, obs: expert(obs), s.observations[:1, :2], s.goals[:1], steps=steps)
    np.testing.assert_allclose(result.states[0], s.observations[:steps + 1], atol=1e-12)
    np.testing.assert_allclose(result.actions[0], s.actions[:steps], atol=1e-12)


def test_noisy_action_law():
    """Minari's order: clip the PD output, add the noise, clip again."""
    assert noisy_action(5.0, -0.3) == pytest.approx(0.7)  # noise first would give clip(4.7) = 1
    assert noisy_action(-3.0, 0.5) == pytest.approx(-0.5)
    assert noisy_action(0.2, 0.1) == pytest.approx(0.3)
    assert noisy_action(0.9, 0.5) == 1.0 and noisy_action(-0.9, -0.5) == -1.0
    # the batched expert draws the same law: a PD output of 10 (one cell from its waypoint, at rest)
    # moves inward by E max(0, -n) = 0.5 * 0.5 * sqrt(2 / pi) = 0.1995 on average
    n = 20_000
    start, goal = UMAZE.cell_to_xy(np.array([3, 1])), UMAZE.eval_goal_xy
    expert = WaypointExpert(UMAZE, action_noise=0.5, rng=0)
    expert.plan(np.repeat(start[None], n, axis=0), np.repeat(goal[None], n, axis=0))
    obs = np.repeat(np.concatenate([start, [0.0, 0.0]])[None], n, axis=0)
    raw = pd_action(expert.current, obs)
    assert np.allclose(raw[:, 0], 10.0) and np.allclose(raw[:, 1], 0.0)
    actions = expert(obs)
    assert abs(np.mean(1.0 - actions[:, 0]) - 0.1995) < 0.02
    assert abs(np.mean(actions[:, 0] == 1.0) - 0.5) < 0.03


def test_first_waypoint_is_not_jittered():
    """Minari's controller heads for the exact centre of the next cell after planning; only the
    waypoints it moves on to are shifted by -U(0, 0.2), and the goal is the goal."""
    start, goal = UMAZE.cell_to_xy(np.array([3, 1])), UMAZE.eval_goal_xy + 0.1
    centres = UMAZE.cell_to_xy(np.array([(3, 2), (3, 3), (2, 3), (1, 3), (1, 2)], dtype=np.float64))
    points = np.stack([waypoints(UMAZE, start, goal, 0.2, np.random.default_rng(k)) for k in range(200)])
    assert points.shape == (200, 6, 2)
    np.testing.assert_array_equal(points[:, 0], np.broadcast_to(centres[0], (200, 2)))
    shift = centres[None, 1:] - points[:, 1:-1]
    assert shift.min() >= 0.0 and shift.max() <= 0.2 and abs(shift.mean() - 0.1) < 0.01
    np.testing.assert_array_equal(points[:, -1], np.broadcast_to(goal, (200, 2)))


def _first_waypoint_steps(s):
    """``(PD output, applied action)`` components of every step before an episode's first waypoint
    switch: there the waypoint is known exactly (the unjittered first one), so the PD output is too."""
    raws, acts = [], []
    ends = [*s.episode_starts[1:].tolist(), len(s)]
    for lo, hi, goal in zip(s.episode_starts.tolist(), ends, s.goals):
        path = _plan(UMAZE, *s.observations[lo, :2], tuple(goal), 0.0, None)
        w = np.asarray(path[0])
        obs = s.observations[lo:hi]
        if len(path) > 1:  # the generator moves on at the first step within WAYPOINT_RADIUS
            near = np.flatnonzero(np.linalg.norm(obs[:, :2] - w, axis=1) <= WAYPOINT_RADIUS)
            obs = obs[:near[0]] if len(near) else obs
        raws.append(P_GAIN * (w - obs[:, :2]) + D_GAIN * obs[:, 2:])
        acts.append(s.actions[lo:lo + len(obs)])
    return np.concatenate(raws).ravel(), np.concatenate(acts).ravel()


def test_generated_actions_follow_minari_order():
    """The generator's applied actions against Minari's procedure (clip, + N(0, 0.5^2), clip) simulated
    directly on the same PD outputs. Noise added to the raw output and clipped once (the old order)
    puts 57 % of the components at the bounds (Minari: 34 %) and moves a saturated one (PD output
    >= 2 in size) by 0.004 on average (Minari: 0.1995)."""
    s = generate_stream(UMAZE, 20_000, seed=3)
    # whatever the states: P(|a| = 1 | PD output) <= P(n >= 0) + P(n <= -2) = 0.50003
    assert np.mean(np.abs(s.actions) == 1.0) < 0.5
    raw, applied = _first_waypoint_steps(s)
    clipped = np.clip(raw, -1.0, 1.0)
    minari = np.clip(clipped + np.random.default_rng(0).normal(0.0, 0.5, raw.shape), -1.0, 1.0)
    saturated = np.abs(raw) >= 2.0
    assert raw.size > 15_000 and saturated.sum() > 5_000
    assert abs(np.mean(np.abs(applied) == 1.0) - np.mean(np.abs(minari) == 1.0)) < 0.03
    moved = np.abs(applied - clipped)[saturated]
    assert abs(moved.mean() - 0.1995) < 0.02
    assert abs(moved.mean() - np.abs(minari - clipped)[saturated].mean()) < 0.02
    # the noise seen where neither bound is touched: centred, sd 0.5 (truncated), as Minari's
    inside, minari_inside = np.abs(applied) < 1.0, np.abs(minari) < 1.0
    assert abs(np.mean((applied - clipped)[inside]) - np.mean((minari - clipped)[minari_inside])) < 0.02
    assert abs(np.std((applied - clipped)[inside]) - np.std((minari - clipped)[minari_inside])) < 0.02


def test_parallel_workers_give_independent_continuous_streams():
    streams = generate_streams(UMAZE, 3001, seed=5, workers=2, progress=False)
    assert [len(s) for s in streams] == [1501, 1500]
    assert not np.array_equal(streams[0].observations[:100], streams[1].observations[:100])
    stream = stream_from_generated("umaze", streams)
    assert stream.segment_starts.tolist() == [0, 1501] and len(stream) == 3001
    with pytest.raises(BridgeplanError, match="workers"):
        generate_streams(UMAZE, 10, seed=0, workers=0)


def test_pieces_are_independent_short_streams(tmp_path, capsys):
    """``--piece-steps N``: ceil(steps / N) pieces of about N steps, each from its own seed and a random start, read
    back as that many segments (the same for 1 or 2 workers)."""
    pieces = generate_streams(UMAZE, 1000, seed=5, progress=False, piece_steps=300)
    assert [len(s) for s in pieces] == [250, 250, 250, 250]
    starts = np.array([s.observations[0, :2] for s in pieces])
    assert len(np.unique(starts.round(6), axis=0)) == 4 and np.allclose([s.observations[0, 2:] for s in pieces], 0)
    two = generate_streams(UMAZE, 1000, seed=5, workers=2, progress=False, piece_steps=300)
    assert all(np.array_equal(a.observations, b.observations) for a, b in zip(pieces, two))
    out = tmp_path / "pieces"
    assert main(["data", "generate", "--maze", "umaze", "--steps", "1000", "--piece-steps", "300", "--out", str(out),
                 "--no-progress"]) == 0
    stream = load_stream(str(out))
    assert stream.segment_starts.tolist() == [0, 250, 500, 750] and len(stream) == 1000
    for bad in ("0", "1001"):
        assert main(["data", "generate", "--maze", "umaze", "--steps", "1000", "--piece-steps", bad, "--out",
                     str(tmp_path / "bad"), "--no-progress"]) == 2
        assert capsys.readouterr().err.startswith("error: --piece-steps must be in 1..1000")
    assert not (tmp_path / "bad").exists()


def test_join_rule():
    a = np.arange(12.0).reshape(3, 4)           # 3 observations, 2 actions
    b = np.concatenate([a[-1:], a[-1:] + 1.0])  # starts where a ended: continuous
    c = np.full((4, 4), 50.0)                   # starts elsewhere: a new segment
    d = np.concatenate([c[-1:] + 1e-12, c[:1]])  # almost equal is not equal: a new segment
    acts = [np.zeros((len(o) - 1, 2)) + k for k, o in enumerate((a, b, c, d))]
    states, actions, starts = join_episodes([a, b, c, d], acts)
    assert starts.tolist() == [0, 3, 6]
    np.testing.assert_array_equal(states, np.concatenate([a[:-1], b[:-1], c[:-1], d[:-1]]))
    np.testing.assert_array_equal(actions[:, 0], [0, 0, 1, 2, 2, 2, 3])


def test_minari_round_trip_and_cache(tmp_path, monkeypatch):
    out = tmp_path / "umaze-3000"
    assert generate_dataset("umaze", 3000, seed=2, out=out, progress=False) == out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["umaze-3000"]  # no temporary left
    expected = stream_from_generated("umaze", generate_streams(UMAZE, 3000, seed=2, progress=False))
    from_hdf5 = load_stream(out, use_cache=False)
    cached = load_stream(out)
    for s in (from_hdf5, cached):
        assert s.maze == "umaze"
        np.testing.assert_array_equal(s.states, expected.states)
        np.testing.assert_array_equal(s.actions, expected.actions)
        assert s.segment_starts.tolist() == [0]  # goal changes do not split the stream
        assert (s.episodes, s.goals_reached) == (expected.episodes, expected.goals_reached)
        assert s.data_version == expected.data_version == DATA_VERSION
    assert json.loads((out / METADATA_FILE).read_text())[VERSION_KEY] == DATA_VERSION
    # the dataset is a real Minari dataset with its environments
    import minari

    ds = minari.MinariDataset(out / "data")
    assert ds.total_steps == 3000 and ds.total_episodes == expected.episodes
    ep = next(ds.iterate_episodes())
    assert set(ep.observations) == {"observation", "achieved_goal", "desired_goal"}
    assert ep.truncations[-1] and not ep.terminations.any()
    env = ds.recover_environment(eval_env=True)
    obs, _ = env.reset(seed=0)
    assert np.linalg.norm(obs["desired_goal"] - UMAZE.eval_goal_xy) <= 0.25 * np.sqrt(2)
    assert env.spec.max_episode_steps == 300
    env.close()
    # the cache is used: a stale cache (the source changed) is ignored and rebuilt
    cache = out / CACHE_NAME
    with np.load(cache) as z:
        assert z["states"].shape == (3000, 4)
    cache.write_bytes(b"garbage")
    np.testing.assert_array_equal(load_stream(out).states, expected.states)
    # by Minari id, under MINARI_DATASETS_PATH
    root = tmp_path.parent / (tmp_path.name + "-minari")
    shutil.copytree(out, root / "D4RL" / "pointmaze" / "umaze-v2")
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    np.testing.assert_array_equal(load_stream("D4RL/pointmaze/umaze-v2").states, expected.states)
    shutil.rmtree(root)
    # existing datasets are not overwritten without force
    with pytest.raises(BridgeplanError, match="already exists"):
        generate_dataset("umaze", 100, seed=2, out=out, progress=False)
    generate_dataset("umaze", 100, seed=2, out=out, progress=False, force=True)
    assert len(load_stream(out)) == 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["umaze-3000"]


def test_summary(tiny_dataset):
    info = summarize(load_stream(tiny_dataset))
    assert info["maze"] == "umaze" and info["transitions"] == 6000 and info["segments"] == 1
    assert info["episodes"] == info["goals_reached"] + 1 or info["episodes"] == info["goals_reached"]
    assert info["free_cells_visited"] == 1.0  # a fraction of the free cells
    assert all(-1.0 <= v <= 1.0 for v in info["action_min"] + info["action_max"])
    assert info["data_version"] == DATA_VERSION
    stream = _two_segment_stream()
    stream.actions[:5] = [[1.0, 0.0], [-1.0, -1.0], [0.3, 1.0], [0.999, -0.2], [1.0, 1.0]]
    assert summarize(stream)["actions_at_bounds"] == 0.06  # 6 of the 100 components (the rest uniform)
    assert summarize(stream)["data_version"] is None


def _two_segment_stream() -> Stream:
    rng = np.random.default_rng(0)
    states = rng.normal(size=(50, 4))
    actions = rng.uniform(-1, 1, size=(50, 2))
    return Stream("umaze", states, actions, np.array([0, 30]), episodes=3, goals_reached=2, layout=MAZE2D)


def test_windows():
    stream = _two_segment_stream()
    normalizer = Normalizer.fit(stream.transitions())
    data = WindowDataset(stream, 8, normalizer)
    starts = window_starts(stream, 8)
    assert len(data) == (30 - 8 + 1) + (20 - 8 + 1) == len(starts)
    assert 29 - 7 + 1 not in starts.tolist()  # no window crosses the segment boundary at 30
    assert all(s + 8 <= 30 or s >= 30 for s in starts.tolist())
    x = data[0]
    assert x.shape == (8, 6) and x.dtype == torch.float32
    assert x.abs().max() <= 1.0 + 1e-6
    back = normalizer.unnormalize(x.double().numpy())
    np.testing.assert_allclose(back, stream.transitions()[:8], atol=1e-5)
    # the conditions are the window's own first and last states
    np.testing.assert_allclose(normalizer.unnormalize(x[0].double().numpy())[2:], stream.states[0], atol=1e-5)
    last = data[len(data) - 1]
    last_state = normalizer.unnormalize(last[-1].double().numpy())[2:]
    np.testing.assert_allclose(last_state, stream.states[-1], atol=1e-5)
    batch = data.batch(torch.tensor([0, 5, len(data) - 1]))
    assert batch.shape == (3, 8, 6)
    torch.testing.assert_close(batch[1], data[5])
    assert len(WindowDataset(stream, 30, normalizer)) == 1
    with pytest.raises(BridgeplanError, match="horizon 31 is longer than every continuous segment"):
        WindowDataset(stream, 31, normalizer)
    with pytest.raises(BridgeplanError):
        WindowDataset(stream, 1, normalizer)


def test_hold_tails_wait_still_after_a_random_index():
    """A held window keeps its states up to k, then k's position with zero velocity and zero action (normalized
    by ``rest``); the share of held windows follows ``share``; share 0 changes nothing."""
    gen = torch.Generator().manual_seed(0)
    x = torch.rand((4000, 16, 6), generator=gen) * 2 - 1
    rest = torch.tensor([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
    out = hold_tails(x, 0.5, rest, MAZE2D, gen)
    changed = (out != x).any(dim=2)  # [B, H]
    held = changed.any(dim=1)
    assert abs(held.float().mean().item() - 0.5) < 0.03
    for i in torch.nonzero(held)[:50, 0].tolist():
        k = int(torch.nonzero(changed[i])[0]) - 1  # the first waiting state follows k
        assert 1 <= k <= 14 and changed[i, k + 1:].all() and not changed[i, :k + 1].any()
        torch.testing.assert_close(out[i, k + 1:, 2:4], x[i, k, 2:4].expand(15 - k, 2))  # position of state k
        torch.testing.assert_close(out[i, k + 1:, :2], rest[:2].expand(15 - k, 2))  # no action
        torch.testing.assert_close(out[i, k + 1:, 4:], rest[4:].expand(15 - k, 2))  # no velocity
    assert torch.equal(hold_tails(x, 0.0, rest, MAZE2D, gen), x)
    assert (hold_tails(x, 1.0, rest, MAZE2D, gen)[:, -1] != x[:, -1]).any(dim=1).all()


def _write_d4rl(path, stream, maze, stale_after=()):
    """A D4RL-style file: D4RL coordinates, float32, and after each goal step ``t`` in ``stale_after``
    a row that repeats observation ``t`` while the simulator had moved on (D4RL's generator recorded
    that at every goal change)."""
    obs, act = to_d4rl(stream.observations[:-1], stream.actions, maze)
    flags = np.zeros(len(obs), dtype=bool)
    for t in stale_after:
        obs[t + 1] = obs[t]
        flags[t] = True
    with h5py.File(path, "w") as f:
        f["observations"] = obs.astype(np.float32)
        f["actions"] = act.astype(np.float32)
        f["rewards"] = np.zeros(len(obs), dtype=np.float32)
        f["terminals"] = np.zeros(len(obs), dtype=bool)
        f["timeouts"] = flags
        f["infos/goal"] = np.zeros((len(obs), 2), dtype=np.float32)


def test_d4rl_reader(tmp_path, umaze_stream):
    s = umaze_stream
    goal_steps = [int(i) - 1 for i in s.episode_starts[1:4]]
    path = tmp_path / "maze2d-umaze-sparse-v1.hdf5"
    _write_d4rl(path, s, UMAZE, stale_after=goal_steps)
    stream = read_d4rl(path)
    assert stream.maze == "umaze" and len(stream) == len(s)
    assert stream.data_version is None  # not ours
    assert stream.goals_reached == 3
    # the rows come back in gymnasium-robotics coordinates (float32 precision)
    keep = np.ones(len(stream), dtype=bool)
    keep[[t + 1 for t in goal_steps]] = False
    np.testing.assert_allclose(stream.states[keep], s.observations[:-1][keep], atol=1e-5)
    np.testing.assert_allclose(stream.actions, s.actions, atol=1e-6)
    # the stream breaks exactly around each stale row, which is left as a one-step segment
    cuts = {t + 1 for t in goal_steps} | {t + 2 for t in goal_steps}
    assert stream.segment_starts.tolist() == [0] + sorted(cuts)
    for lo, hi in stream.segment_bounds():
        assert not continuity_breaks(stream.states[lo:hi]).any()
    # through load_stream and its cache; a foreign name needs the maze (or data that tells it)
    assert len(load_stream(path)) == len(stream)
    assert (tmp_path / (path.name + "." + CACHE_NAME)).exists()
    other = tmp_path / "recording.hdf5"
    shutil.copy(path, other)
    assert read_d4rl(other, "umaze").maze == "umaze"
    assert read_d4rl(other).maze == "umaze"  # inferred from the data: it fits open too, but covers it less
    with pytest.raises(BridgeplanError, match="unknown maze"):
        read_d4rl(other, "nomaze")


def test_bad_files(tmp_path):
    text = tmp_path / "maze2d-umaze-v1.hdf5"
    text.write_text("not hdf5")
    with pytest.raises(BridgeplanError, match="not an hdf5 file"):
        load_stream(text)
    foreign = tmp_path / "maze2d-large-v1.hdf5"
    with h5py.File(foreign, "w") as f:
        f["images"] = np.zeros((3, 8, 8))
    with pytest.raises(BridgeplanError, match="no observations, actions"):
        load_stream(foreign)
    wrong = tmp_path / "maze2d-medium-v1.hdf5"
    with h5py.File(wrong, "w") as f:
        f["observations"] = np.zeros((10, 7))
        f["actions"] = np.zeros((10, 2))
    with pytest.raises(BridgeplanError, match="not maze2d data"):
        load_stream(wrong)
    with pytest.raises(BridgeplanError, match="no dataset at"):
        load_stream(tmp_path / "missing")
    with pytest.raises(BridgeplanError, match="not a Minari dataset"):
        load_stream(tmp_path)


def test_minari_reads_our_dataset_by_id(tiny_dataset, tmp_path, monkeypatch):
    """minari's own reader opens our dataset by id; its episodes are our stream, cut at goals."""
    import minari

    from tests.conftest import TINY_STEPS

    ours = load_stream(tiny_dataset, use_cache=False)
    (tmp_path / "bridgeplan").mkdir()
    (tmp_path / "bridgeplan" / "pointmaze-umaze-v0").symlink_to(tiny_dataset)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    ds = minari.load_dataset("bridgeplan/pointmaze-umaze-v0")
    assert ds.total_steps == TINY_STEPS and ds.total_episodes == ours.episodes
    episodes = list(ds.iterate_episodes())
    np.testing.assert_array_equal(np.concatenate([e.observations["observation"][:-1] for e in episodes]),
                                  ours.states)
    np.testing.assert_array_equal(np.concatenate([e.actions for e in episodes]), ours.actions)
    rewards = np.concatenate([e.rewards for e in episodes])
    assert [e.rewards[-1] for e in episodes[:-1]] == [1.0] * (len(episodes) - 1)
    assert rewards.sum() >= ours.goals_reached == len(episodes) - (episodes[-1].rewards[-1] == 0)
    env = ds.recover_environment(eval_env=True)
    assert env.unwrapped.reset_target is False and env.unwrapped.continuing_task is True
    env.close()
    np.testing.assert_array_equal(load_stream("bridgeplan/pointmaze-umaze-v0").states, ours.states)


def test_normalizer_round_trip_numpy_and_torch():
    rng = np.random.default_rng(0)
    data = rng.normal(size=(100, 6)) * [1, 2, 3, 4, 5, 6]
    norm = Normalizer.from_dict(Normalizer.fit(data).to_dict())
    z = norm.normalize(data)
    assert z.min() == pytest.approx(-1) and z.max() == pytest.approx(1)
    np.testing.assert_allclose(norm.unnormalize(z), data)
    t = torch.as_tensor(data)
    torch.testing.assert_close(norm.unnormalize(norm.normalize(t)), t)
    np.testing.assert_allclose(norm.normalize(data[:, 2:], slice(2, None)), z[:, 2:])


def test_legacy_d4rl_hand_made_file(tmp_path):
    """A tiny hand-made D4RL stream: row/column coordinates, a reset after the third row."""
    maze = get_maze("umaze")
    rows, cols = maze.shape
    qpos = np.array([[1.0, 1.0], [1.0, 1.02], [1.0, 1.04], [3.0, 1.0], [3.0, 1.02]])
    qvel = np.array([[0.0, 2.0]] * 5)  # 2 m/s along qpos_y: 0.02 per step, as the rows move
    path = tmp_path / "maze2d-umaze-sparse-v1.hdf5"
    with h5py.File(path, "w") as f:
        f["observations"] = np.concatenate([qpos, qvel], axis=1)
        f["actions"] = np.array([[0.5, 0.1]] * 5)
        f["rewards"] = np.zeros(5)
        f["terminals"] = np.zeros(5, dtype=bool)
        f["timeouts"] = np.array([0, 1, 0, 0, 0], dtype=bool)
    stream = load_stream(str(path))
    assert stream.maze == "umaze" and stream.segment_starts.tolist() == [0, 3]
    np.testing.assert_allclose(stream.states[0], [1.0 + 0.7 - cols / 2, rows / 2 - 0.7 - 1.0, 2.0, 0.0])
    np.testing.assert_allclose(stream.actions[0], [0.1, -0.5])
    assert maze.is_free_xy(stream.states[:, :2]).all()
    truncated = tmp_path / "maze2d-umaze-truncated.hdf5"
    truncated.write_bytes(path.read_bytes()[:200])
    with pytest.raises(BridgeplanError, match="truncated"):
        load_stream(truncated)


def _stderr_lines(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


def test_old_datasets_warn_once_per_load(tiny_dataset, tmp_path, capsys):
    """Our datasets from before data versions (or of an older one) load with one warning line naming them;
    current ones and official Minari ones load silently."""
    old = tmp_path / "old"
    shutil.copytree(tiny_dataset, old)
    capsys.readouterr()
    assert load_stream(old).data_version == DATA_VERSION and _stderr_lines(capsys) == []
    # as the previous version left it: no version in the metadata, a version-1 cache without one
    meta = json.loads((old / METADATA_FILE).read_text())
    del meta[VERSION_KEY]
    (old / METADATA_FILE).write_text(json.dumps(meta))
    stream = load_stream(old, use_cache=False)
    stat = (old / "data" / "main_data.hdf5").stat()
    np.savez(old / CACHE_NAME, stamp=np.array([1, stat.st_size, stat.st_mtime_ns]), maze="umaze",
             states=stream.states, actions=stream.actions, segment_starts=stream.segment_starts,
             episodes=stream.episodes, goals_reached=stream.goals_reached, source=str(old))
    capsys.readouterr()
    for _ in range(2):  # from the hdf5 (the old cache is rebuilt), then from the new cache
        assert load_stream(old).data_version == 1
        lines = _stderr_lines(capsys)
        assert len(lines) == 1 and lines[0].startswith(f"warning: {old} was made by an older bridgeplan data "
                                                       f"generator (data version 1;")
        assert "regenerate it with `bridgeplan data generate`" in lines[0]
    with np.load(old / CACHE_NAME) as z:
        assert int(z["stamp"][0]) == 2 and int(z["data_version"]) == 1
    # an older recorded version
    meta[VERSION_KEY] = DATA_VERSION - 1
    (old / METADATA_FILE).write_text(json.dumps(meta))
    assert load_stream(old, use_cache=False).data_version == DATA_VERSION - 1
    assert len(_stderr_lines(capsys)) == 1
    # someone else's Minari dataset (an official D4RL/pointmaze one) has no bridgeplan version: no warning
    del meta[VERSION_KEY]
    meta["author"] = ["Rodrigo de Lazcano"]
    (old / METADATA_FILE).write_text(json.dumps(meta))
    (old / CACHE_NAME).unlink()
    for _ in range(2):
        assert load_stream(old).data_version is None
    assert _stderr_lines(capsys) == []
