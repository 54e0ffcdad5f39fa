"""OGBench pointmaze datasets: names, the generator against OGBench's recipe, the npz files, reading them back."""

from __future__ import annotations

import json
import math
import zipfile

import numpy as np
import pytest

from bridgeplan.cli import main
from bridgeplan.envs.ogbench_pointmaze import generate as gen
from bridgeplan.envs.ogbench_pointmaze.generate import KEYS, generate_dataset, generate_episodes
from bridgeplan.envs.ogbench_pointmaze.maze import Oracle, bfs, geometry, make_env
from bridgeplan.envs.ogbench_pointmaze.names import ACTION_NOISE, KINDS, MAZES, env_id, parse_dataset_name
from bridgeplan.envs.ogbench_pointmaze.reading import check_dataset, load_dataset
from bridgeplan.errors import BridgeplanError

NAV_EPISODES, NAV_STEPS = 3, 400
STITCH_EPISODES, STITCH_STEPS = 12, 201


@pytest.fixture(scope="module")
def navigate(tmp_path_factory):
    out = tmp_path_factory.mktemp("ogb")
    return generate_dataset("pointmaze-medium-navigate-v0", out, seed=3, episodes=NAV_EPISODES,
                            episode_steps=NAV_STEPS, progress=False)


@pytest.fixture(scope="module")
def navigate_rows():
    return generate_episodes("medium", "navigate", NAV_EPISODES, NAV_STEPS, seed=3)


@pytest.fixture(scope="module")
def stitch_rows():
    return generate_episodes("large", "stitch", STITCH_EPISODES, STITCH_STEPS, seed=5)


def test_names():
    for maze in MAZES:
        for kind in KINDS:
            spec = parse_dataset_name(f"pointmaze-{maze}-{kind}-v0")
            assert (spec.maze, spec.kind, spec.env_id) == (maze, kind, f"pointmaze-{maze}-v0")
    assert (parse_dataset_name("pointmaze-giant-navigate-v0").episodes,
            parse_dataset_name("pointmaze-giant-navigate-v0").episode_steps) == (500, 2001)
    assert (parse_dataset_name("pointmaze-large-navigate-v0").episodes,
            parse_dataset_name("pointmaze-large-navigate-v0").episode_steps) == (1000, 1001)
    assert (parse_dataset_name("pointmaze-medium-stitch-v0").episodes,
            parse_dataset_name("pointmaze-medium-stitch-v0").episode_steps) == (5000, 201)
    for bad in ("pointmaze-huge-navigate-v0", "pointmaze-medium-explore-v0", "antmaze-medium-navigate-v0",
                "pointmaze-medium-navigate-v1", "pointmaze-medium-navigate-v0.npz", ""):
        with pytest.raises(BridgeplanError):
            parse_dataset_name(bad)
    with pytest.raises(BridgeplanError):
        env_id("umaze")


def test_env_ids_are_registered():
    import gymnasium
    import ogbench  # noqa: F401

    for maze in MAZES:
        spec = gymnasium.spec(env_id(maze))
        assert spec.max_episode_steps == 1000 and spec.kwargs["maze_type"] == maze


def test_oracle_equals_get_oracle_subgoal():
    rng = np.random.default_rng(0)
    for maze in MAZES:
        u = make_env(maze).unwrapped
        oracle, g = Oracle(maze), geometry(maze)
        free = np.array(g.free_cells)
        for _ in range(150):
            a, b = free[rng.integers(len(free), size=2)]
            xy = g.cell_xy(tuple(a)) + rng.uniform(-1.9, 1.9, 2)
            goal = g.cell_xy(tuple(b)) + rng.uniform(-1, 1, 2)
            expected, _ = u.get_oracle_subgoal(xy, goal)
            np.testing.assert_array_equal(oracle.subgoal(xy, goal), expected)


def test_vertex_cells_exclude_hallways():
    g = geometry("medium")
    assert len(g.free_cells) == 26
    # read off the medium map: the cells open on two opposite sides and walled on the other two
    assert set(g.free_cells) - set(g.vertex_cells) == {(3, 3), (4, 5), (5, 1), (5, 6), (6, 2)}
    for i, j in set(g.free_cells) - set(g.vertex_cells):  # a hallway: open on two opposite sides only
        m = g.maze_map
        assert (m[i - 1, j], m[i + 1, j], m[i, j - 1], m[i, j + 1]) in ((0, 0, 1, 1), (1, 1, 0, 0))


def test_files_follow_ogbench_format(navigate):
    for path, episodes in ((navigate.train_path, NAV_EPISODES), (navigate.val_path, 1)):
        with np.load(path) as f:
            assert sorted(f.keys()) == sorted(KEYS)
            n = episodes * NAV_STEPS
            for k in ("observations", "actions", "qpos", "qvel"):
                assert f[k].shape == (n, 2) and f[k].dtype == np.float32, k
            assert f["terminals"].shape == (n,) and f["terminals"].dtype == bool
            ends = np.flatnonzero(f["terminals"])
            np.testing.assert_array_equal(ends, np.arange(1, episodes + 1) * NAV_STEPS - 1)
            np.testing.assert_array_equal(f["observations"], f["qpos"])  # the point's observation is its xy
            assert np.abs(f["actions"]).max() <= 1.0
            obs = f["observations"]
            steps = np.linalg.norm(np.diff(obs, axis=0), axis=1)[~f["terminals"][:-1]]
            assert steps.max() <= 0.2 * math.sqrt(2) + 1e-4  # qpos += 0.2 * action
    assert not [p for p in navigate.train_path.parent.iterdir() if p.name.startswith(".")]  # no temp files


def test_rows_are_the_state_before_the_action(navigate_rows):
    d = navigate_rows
    same = ~d["terminals"][:-1]
    moved = d["observations"][1:][same] - d["observations"][:-1][same]
    free = np.abs(moved - 0.2 * d["actions"][:-1][same]).max(axis=1) < 1e-4  # away from walls: exactly 0.2 a
    assert free.mean() > 0.8


def _phi(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1 + np.vectorize(math.erf)(x / math.sqrt(2)))


def noise_fits(rows: dict, sigma: float, maze: str) -> bool:
    """Whether action = clip(oracle unit direction + N(0, sigma^2), -1, 1) fits the rows: the number of
    clipped components matches its expectation, and the unclipped residuals, mapped through the normal CDF
    truncated to their unclipped window, are uniform (Kolmogorov-Smirnov at about 0.1 %)."""
    oracle = Oracle(maze)
    d = np.stack([oracle.direction(o, g) for o, g in zip(rows["observations"].astype(np.float64), rows["goals"])])
    assert np.linalg.norm(d, axis=1).max() <= 1  # unit up to the recipe's + 1e-6
    a = rows["actions"].astype(np.float64).ravel()
    d = d.ravel()
    lo, hi = _phi((-1 - d) / sigma), _phi((1 - d) / sigma)
    clipped = np.abs(a) >= 1 - 1e-7
    p_clip = 1 - (hi - lo)
    if abs(clipped.sum() - p_clip.sum()) > 4 * math.sqrt((p_clip * (1 - p_clip)).sum()):
        return False
    u = (_phi((a - d) / sigma) - lo)[~clipped] / (hi - lo)[~clipped]
    u = np.sort(u)
    n = len(u)
    ks = max(np.max(np.arange(1, n + 1) / n - u), np.max(u - np.arange(n) / n))
    return bool(ks < 1.95 / math.sqrt(n))


def test_action_noise_is_the_recipes(navigate_rows, stitch_rows):
    assert ACTION_NOISE == 0.5  # generate_locomaze.py --noise=0.5 (commands.sh)
    assert noise_fits(navigate_rows, 0.5, "medium")
    assert noise_fits(stitch_rows, 0.5, "large")
    # the check can tell: the same rows do not fit other noise levels, nor do rows made with another level
    assert not noise_fits(navigate_rows, 0.4, "medium") and not noise_fits(navigate_rows, 0.6, "medium")
    assert not noise_fits(generate_episodes("medium", "navigate", 3, 400, seed=3, noise=0.4), 0.5, "medium")


def _episodes(rows: dict, steps: int):
    for lo in range(0, len(rows["terminals"]), steps):
        yield {k: v[lo:lo + steps] for k, v in rows.items()}


def test_navigate_goals_are_vertex_cells_and_renewed(navigate_rows):
    g = geometry("medium")
    vertex = set(g.vertex_cells)
    renewals = 0
    for ep in _episodes(navigate_rows, NAV_STEPS):
        assert g.is_free(g.cells_of(ep["observations"][:1])).all()
        goal_cells = {tuple(c) for c in g.cells_of(ep["goals"])}
        assert goal_cells <= vertex
        changes = np.flatnonzero(np.any(np.diff(ep["goals"], axis=0) != 0, axis=1))
        for t in changes:  # a new goal only after a step that ended within 1.0 of the old one
            assert np.linalg.norm(ep["observations"][t + 1] - ep["goals"][t]) <= 1.0 + 1e-5
        renewals += len(changes)
    assert renewals >= NAV_EPISODES  # 400 steps in medium reach several goals


def test_stitch_goals_are_four_cells_away(stitch_rows):
    g = geometry("large")
    for ep in _episodes(stitch_rows, STITCH_STEPS):
        start = tuple(g.cells_of(ep["observations"][:1])[0])
        assert np.all(ep["goals"] == ep["goals"][0])  # one goal per episode
        goal = tuple(g.cells_of(ep["goals"][:1])[0])
        assert bfs(g.maze_map, start)[0][goal] == 4
        assert np.all(np.abs(ep["goals"][0] - g.cell_xy(goal)) <= 1.0)  # the env's goal noise: +-1


def test_seeded_and_leaves_the_global_rng_alone():
    np.random.seed(7)
    before = np.random.get_state()[1].copy()
    a = generate_episodes("teleport", "stitch", 2, 50, seed=1)
    assert np.array_equal(np.random.get_state()[1], before)
    b = generate_episodes("teleport", "stitch", 2, 50, seed=1)
    c = generate_episodes("teleport", "stitch", 2, 50, seed=2)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not np.array_equal(a["observations"], c["observations"])


def test_read_back_by_ogbench(navigate):
    import ogbench

    raw = np.load(navigate.train_path)
    ds = ogbench.utils.load_dataset(str(navigate.train_path))
    n = NAV_EPISODES * (NAV_STEPS - 1)  # the loader drops each episode's last step (it has no next one)
    assert ds["observations"].shape == ds["next_observations"].shape == (n, 2)
    np.testing.assert_array_equal(ds["observations"][:NAV_STEPS - 1], raw["observations"][:NAV_STEPS - 1])
    env, train, val = ogbench.make_env_and_datasets("pointmaze-medium-navigate-v0",
                                                    dataset_path=str(navigate.train_path))
    assert len(train["observations"]) == n and len(val["observations"]) == NAV_STEPS - 1
    ours = load_dataset(navigate.train_path, "pointmaze-medium-navigate-v0", add_info=True)
    assert set(ours) == {"observations", "actions", "terminals", "next_observations", "qpos", "qvel"}
    check = check_dataset(navigate.train_path, "medium")
    assert (check.transitions, check.episodes, check.episode_lengths) == (NAV_EPISODES * NAV_STEPS,
                                                                          NAV_EPISODES, [NAV_STEPS])
    assert check.fits == ["medium"]


def test_wrong_maze_and_bad_files(navigate, stitch_rows, tmp_path):
    for maze in ("large", "giant", "teleport"):
        with pytest.raises(BridgeplanError, match=f"not a pointmaze-{maze} dataset.*fits medium"):
            check_dataset(navigate.train_path, maze)
    with pytest.raises(BridgeplanError, match="unknown"):
        check_dataset(navigate.train_path, "umaze")
    with pytest.raises(BridgeplanError, match="no dataset file"):
        check_dataset(tmp_path / "missing.npz", "medium")
    (tmp_path / "text.npz").write_text("not a zip\n")
    with pytest.raises(BridgeplanError, match="not an npz file"):
        check_dataset(tmp_path / "text.npz", "medium")
    raw = dict(np.load(navigate.train_path))
    variants = {
        "no-actions": ({k: v for k, v in raw.items() if k != "actions"}, "no actions array"),
        "antmaze": ({**raw, "observations": np.zeros((len(raw["actions"]), 29), np.float32)}, r"shape \(1200, 29\)"),
        "open-end": ({**raw, "terminals": np.zeros_like(raw["terminals"])}, "no terminal"),
    }
    for name, (arrays, message) in variants.items():
        np.savez(tmp_path / f"{name}.npz", **arrays)
        with pytest.raises(BridgeplanError, match=message):
            check_dataset(tmp_path / f"{name}.npz", "medium")
    np.savez(tmp_path / "large.npz", observations=stitch_rows["observations"], actions=stitch_rows["actions"],
             terminals=stitch_rows["terminals"])
    assert check_dataset(tmp_path / "large.npz", "large").fits == ["large"]
    with pytest.raises(BridgeplanError, match="not a pointmaze-medium"):
        load_dataset(tmp_path / "large.npz", "medium")


def test_refuses_to_overwrite_and_writes_atomically(navigate, monkeypatch, tmp_path):
    out = navigate.train_path.parent
    with pytest.raises(BridgeplanError, match="already exist.*--force"):
        generate_dataset("pointmaze-medium-navigate-v0", out, episodes=1, episode_steps=5, progress=False)
    assert np.load(navigate.train_path)["terminals"].shape == (NAV_EPISODES * NAV_STEPS,)  # untouched

    def broken(f, **arrays):
        f.write(b"PK half a file")
        raise OSError("disk full")

    monkeypatch.setattr(gen.np, "savez_compressed", broken)
    with pytest.raises(BridgeplanError, match="cannot write .*pointmaze-medium-stitch-v0.npz: disk full"):
        generate_dataset("pointmaze-medium-stitch-v0", tmp_path, episodes=1, episode_steps=5, progress=False)
    assert list(tmp_path.iterdir()) == []  # neither a half-written file nor a temporary one


def test_cli_generate_and_info(tmp_path, capsys):
    args = ["data", "generate", "--maze", "pointmaze-giant-stitch-v0", "--out", str(tmp_path), "--episodes", "2",
            "--episode-steps", "30", "--seed", "4", "--no-progress"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "60 steps in 2 episodes of 30 steps" in out and "wrote " in out and "cached" not in out
    assert zipfile.is_zipfile(tmp_path / "pointmaze-giant-stitch-v0-val.npz")
    made = (tmp_path / "pointmaze-giant-stitch-v0.npz").stat().st_mtime_ns
    assert main(args) == 0  # the same identity: the cache, nothing made
    out = capsys.readouterr().out
    assert "cached: " in out and "wrote" not in out
    assert (tmp_path / "pointmaze-giant-stitch-v0.npz").stat().st_mtime_ns == made
    record = json.loads((tmp_path / "pointmaze-giant-stitch-v0.json").read_text())
    assert record["identity"]["seed"] == 4 and record["identity"]["episodes"] == 2
    other = args[:-2] + ["5", "--no-progress"]  # another seed: not this dataset, refused
    assert main(other) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "--force" in err and "\n" not in err
    assert main(other + ["--force"]) == 0
    capsys.readouterr()
    assert main(["data", "info", str(tmp_path / "pointmaze-giant-stitch-v0.npz"),
                 "--maze", "pointmaze-medium-stitch-v0"]) == 2
    assert capsys.readouterr().err.startswith("error: ")
    assert main(["data", "info", str(tmp_path / "pointmaze-giant-stitch-v0.npz")]) == 2  # an npz names no maze
    assert "give --maze" in capsys.readouterr().err
    assert main(["data", "info", str(tmp_path / "pointmaze-giant-stitch-v0.npz"), "--maze",
                 "pointmaze-giant-stitch-v0", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["transitions"] == 60
    assert main(["data", "generate", "--maze", "pointmaze-giant-v0", "--out", str(tmp_path)]) == 2
    assert "unknown OGBench pointmaze dataset" in capsys.readouterr().err
    for bad in (["--steps", "100"], ["--workers", "2"], ["--piece-steps", "10"]):  # the recipe's size, one process
        assert main(["data", "generate", "--maze", "pointmaze-giant-stitch-v0", "--out", str(tmp_path / "x"),
                     *bad]) == 2
        assert "recipe's size" in capsys.readouterr().err and not (tmp_path / "x").exists()
