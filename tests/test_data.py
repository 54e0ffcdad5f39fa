"""Datasets: generation, the Minari round trip, D4RL files, the joining rule, windows, bad input."""

from __future__ import annotations

import os

import h5py
import numpy as np
import pytest
import torch

from bridgeplan.cli import main
from bridgeplan.data import WindowDataset, load_stream
from bridgeplan.data.normalizer import Normalizer
from bridgeplan.data.stream import join_episodes
from bridgeplan.errors import BridgeplanError
from bridgeplan.maze.layouts import get_maze
from tests.conftest import TINY_STEPS


def test_generated_stream_is_one_continuous_noisy_expert(tiny_dataset):
    stream = load_stream(tiny_dataset)
    assert stream.maze == "umaze" and len(stream) == TINY_STEPS
    assert list(stream.segment_starts) == [0]  # goal changes do not split the stream
    assert stream.episodes > 20  # about 80 steps per reached goal in umaze
    maze = get_maze("umaze")
    assert maze.is_free_xy(stream.states[:, :2]).all()
    assert np.abs(stream.actions).max() <= 1.0
    # physically continuous: each position follows from the previous one within one step's reach
    assert np.linalg.norm(np.diff(stream.states[:, :2], axis=0), axis=1).max() < 0.06


def test_minari_round_trip(tiny_dataset, monkeypatch):
    import minari

    # minari's own reader opens our dataset and rebuilds its evaluation environment
    root, dataset_id = os.path.dirname(os.path.dirname(tiny_dataset)), None
    monkeypatch.setenv("MINARI_DATASETS_PATH", root)
    ours = load_stream(tiny_dataset, use_cache=False)
    link = os.path.join(root, "bridgeplan", "pointmaze-umaze-v0")
    os.makedirs(os.path.dirname(link), exist_ok=True)
    if not os.path.exists(link):
        os.symlink(tiny_dataset, link)
    dataset_id = "bridgeplan/pointmaze-umaze-v0"
    ds = minari.load_dataset(dataset_id)
    assert ds.total_steps == TINY_STEPS and ds.total_episodes == ours.episodes
    episodes = list(ds.iterate_episodes())
    states = np.concatenate([e.observations["observation"][:-1] for e in episodes])
    actions = np.concatenate([e.actions for e in episodes])
    assert np.array_equal(states, ours.states) and np.array_equal(actions, ours.actions)
    rewards = np.concatenate([e.rewards for e in episodes])
    assert rewards.sum() == ours.episodes - (rewards[-1] == 0)  # each episode but maybe the last ends at its goal
    env = ds.recover_environment(eval_env=True)
    assert env.unwrapped.reset_target is False
    # the id resolves through MINARI_DATASETS_PATH as well
    assert np.array_equal(load_stream(dataset_id).states, ours.states)


def test_cache_is_used_and_refreshed(tiny_dataset):
    cache = os.path.join(tiny_dataset, "bridgeplan-cache.npz")
    first = load_stream(tiny_dataset)
    assert os.path.exists(cache)
    with open(cache, "wb") as f:
        f.write(b"garbage")
    again = load_stream(tiny_dataset)  # a broken cache is rebuilt, not trusted
    assert np.array_equal(again.states, first.states)


def test_joining_rule():
    a = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [2, 0, 0, 0]], dtype=float)
    b = np.array([[2, 0, 0, 0], [3, 0, 0, 0]], dtype=float)  # continues a (first == a's last)
    c = np.array([[9, 9, 0, 0], [8, 9, 0, 0]], dtype=float)  # a reset: new segment
    acts = [np.ones((2, 2)), np.ones((1, 2)), np.ones((1, 2))]
    states, actions, starts = join_episodes([a, b, c], acts)
    assert states[:, 0].tolist() == [0, 1, 2, 9]
    assert starts.tolist() == [0, 3] and len(actions) == 4


def _synthetic_stream(lengths):
    from bridgeplan.data.stream import Stream

    total = sum(lengths)
    states = np.stack([np.arange(total, dtype=float), np.zeros(total), np.ones(total), -np.ones(total)], axis=1)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    return Stream("umaze", states, np.zeros((total, 2)), starts, len(lengths))


def test_windows_stay_inside_segments_and_invert():
    stream = _synthetic_stream([10, 3, 7])
    norm = Normalizer.fit(stream.transitions())
    windows = WindowDataset(stream, 5, norm)
    assert len(windows) == (10 - 5 + 1) + 0 + (7 - 5 + 1)
    batch = windows.batch(torch.arange(len(windows)))
    assert batch.shape == (len(windows), 5, 6)
    raw = norm.unnormalize(batch.double().numpy())
    x = raw[..., 2]
    assert np.allclose(np.diff(x, axis=1), 1.0)  # consecutive steps, never across a segment boundary
    assert np.allclose(raw[..., 4:], [1.0, -1.0])
    assert np.allclose(batch.numpy().max(), 1.0, atol=1e-6) and batch.numpy().min() >= -1 - 1e-6
    assert torch.equal(windows[0], batch[0])
    with pytest.raises(BridgeplanError, match="longer than every continuous segment"):
        WindowDataset(stream, 11, norm)


def test_normalizer_round_trip_numpy_and_torch():
    rng = np.random.default_rng(0)
    data = rng.normal(size=(100, 6)) * [1, 2, 3, 4, 5, 6]
    norm = Normalizer.from_dict(Normalizer.fit(data).to_dict())
    z = norm.normalize(data)
    assert z.min() == pytest.approx(-1) and z.max() == pytest.approx(1)
    assert np.allclose(norm.unnormalize(z), data)
    t = torch.as_tensor(data)
    assert torch.allclose(norm.unnormalize(norm.normalize(t)), t)
    assert np.allclose(norm.normalize(data[:, 2:], slice(2, None)), z[:, 2:])


def test_legacy_d4rl_file(tmp_path):
    maze = get_maze("umaze")
    rows, cols = maze.shape
    # a D4RL-style stream: (qpos_x, qpos_y) in row/column coordinates, one reset in the middle
    xy = np.array([[1.0, 1.0], [1.0, 1.02], [1.0, 1.04], [3.0, 1.0], [3.0, 1.02]])
    qvel = np.array([[0.0, 2.0]] * 5)
    path = tmp_path / "maze2d-umaze-sparse-v1.hdf5"
    with h5py.File(path, "w") as f:
        f["observations"] = np.concatenate([xy, qvel], axis=1)
        f["actions"] = np.array([[0.5, 0.1]] * 5)
        f["rewards"] = np.zeros(5)
        f["terminals"] = np.zeros(5, dtype=bool)
        f["timeouts"] = np.array([0, 1, 0, 0, 0], dtype=bool)
    stream = load_stream(str(path))
    assert stream.maze == "umaze" and stream.segment_starts.tolist() == [0, 3]
    assert np.allclose(stream.states[0], [1.0 + 0.7 - cols / 2, rows / 2 - 0.7 - 1.0, 2.0, 0.0])
    assert np.allclose(stream.actions[0], [0.1, -0.5])
    assert maze.is_free_xy(stream.states[:, :2]).all()


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


@pytest.mark.parametrize("args, message", [
    (["--maze", "maze9"], "unknown maze"),
    (["--maze", "umaze", "--steps", "0"], "must be positive"),
    (["--maze", "umaze", "--steps", "-5"], "must be positive"),
])
def test_generate_bad_input(tmp_path, capsys, args, message):
    out = tmp_path / "d"
    assert main(["data", "generate", *args, "--out", str(out), "--no-progress"]) == 2
    assert message in _one_error_line(capsys)
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_generate_refuses_to_overwrite_and_writes_relative_paths(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["data", "generate", "--maze", "open", "--steps", "500", "--out", "d", "--no-progress"]) == 0
    before = sorted(p.name for p in (tmp_path / "d").rglob("*"))
    capsys.readouterr()
    assert main(["data", "generate", "--maze", "open", "--steps", "500", "--out", "d", "--no-progress"]) == 2
    assert "already exists" in _one_error_line(capsys)
    assert sorted(p.name for p in (tmp_path / "d").rglob("*")) == before
    assert [p.name for p in tmp_path.iterdir()] == ["d"]  # no temporary leftovers


def test_bad_dataset_files(tmp_path, tiny_dataset, capsys):
    assert main(["data", "info", str(tmp_path / "missing")]) == 2
    assert "no dataset" in _one_error_line(capsys)
    foreign = tmp_path / "maze2d-umaze-foreign.hdf5"
    with h5py.File(foreign, "w") as f:
        f["pixels"] = np.zeros((3, 3))
    assert main(["data", "info", str(foreign)]) == 2
    assert "cannot read" in _one_error_line(capsys)
    truncated = tmp_path / "maze2d-umaze-truncated.hdf5"
    truncated.write_bytes(open(foreign, "rb").read()[:200])
    assert main(["data", "info", str(truncated)]) == 2
    assert "cannot read" in _one_error_line(capsys)
    # a truncated Minari data file
    import shutil

    broken = tmp_path / "broken"
    shutil.copytree(tiny_dataset, broken)
    (broken / "bridgeplan-cache.npz").unlink(missing_ok=True)
    data_file = broken / "data" / "main_data.hdf5"
    data_file.write_bytes(data_file.read_bytes()[:4096])
    assert main(["data", "info", str(broken)]) == 2
    assert "cannot read" in _one_error_line(capsys)


def test_data_info(tiny_dataset, capsys):
    assert main(["data", "info", tiny_dataset, "--json"]) == 0
    import json

    info = json.loads(capsys.readouterr().out)
    assert info["transitions"] == TINY_STEPS and info["maze"] == "umaze"
    assert info["free_cells_visited"] == "7/7"
