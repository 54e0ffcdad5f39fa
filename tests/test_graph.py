"""The dataset graph (``bridgeplan.graph``): paths over the data's own states, stitched across episodes
where they pass close, densified from the data; and ``bridgeplan graph`` on OGBench's protocol."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bridgeplan.cli import main
from bridgeplan.envs.ogbench_pointmaze import GRAPH
from bridgeplan.envs.ogbench_pointmaze.controllers import GAIN as STEP
from bridgeplan.errors import BridgeplanError
from bridgeplan.graph import DatasetGraph, GraphSource, fixed_length
from bridgeplan.trajectory import KINEMATIC_POINT


def build(obs, starts, **settings) -> DatasetGraph:
    """A graph of OGBench's kinematic point (its family's settings and step under ``settings``)."""
    return DatasetGraph.build(obs, starts, **{**GRAPH, "layout": KINEMATIC_POINT, "step": STEP, **settings})


def _walk(a, b, steps):
    """``steps + 1`` states from ``a`` to ``b`` at constant speed."""
    return np.asarray(a, float) + (np.asarray(b, float) - np.asarray(a, float)) * np.linspace(0, 1, steps + 1)[:, None]


def two_pieces(gap: float = 0.1):
    """Episode 0 walks (0, 0) -> (10, 0); episode 1 walks (10, gap) -> (10, 10): they meet near (10, 0)."""
    a, b = _walk((0, 0), (10, 0), 50), _walk((10, gap), (10, 10), 50)
    return np.concatenate([a, b]), np.array([0, len(a)])


def test_a_path_stitches_two_episodes_where_they_meet():
    obs, starts = two_pieces()
    g = build(obs, starts, keep=5, radius=0.5, neighbours=4)
    assert g.jumps >= 1
    nodes = g.path_nodes(np.array([0.0, 0.0]), np.array([10.0, 10.0]))
    assert {int(g.episode[n]) for n in nodes} == {0, 1} and g.episode[nodes[0]] == 0 and g.episode[nodes[-1]] == 1
    path = g.densify(np.array([0.0, 0.0]), np.array([10.0, 10.0]), nodes)
    assert np.allclose(path[0], [0, 0]) and np.allclose(path[-1], [10, 10])
    assert np.abs(np.diff(path, axis=0)).max() <= STEP + 1e-9  # one step apart at most, per axis
    # the data's own states, in order: all of episode 0, then all of episode 1
    assert any(np.allclose(p, obs[25]) for p in path) and any(np.allclose(p, obs[51 + 25]) for p in path)
    # walked back (undirected): episode 1, then 0 (where the ends join is a tie between nodes within reach)
    back = [int(g.episode[n]) for n in g.path_nodes(np.array([10.0, 10.0]), np.array([0.0, 0.0]))]
    assert back[0] == 1 and back[-1] == 0 and back == sorted(back, reverse=True)


def test_no_jump_beyond_the_radius():
    obs, starts = two_pieces(gap=1.0)
    g = build(obs, starts, keep=5, radius=0.5, neighbours=4)
    assert g.jumps == 0
    assert g.path_nodes(np.array([0.0, 0.0]), np.array([10.0, 10.0])) == []
    # no path: the straight line, at most a step apart
    line = g.densify(np.array([0.0, 0.0]), np.array([10.0, 10.0]), [])
    assert np.allclose(line[0], 0) and np.allclose(line[-1], 10) and len(line) == 10 / STEP + 1
    assert len(build(obs, starts, keep=5, radius=1.5, neighbours=4).path_nodes(
        np.array([0.0, 0.0]), np.array([10.0, 10.0]))) > 0


def test_the_cheapest_path_is_taken():
    """Two ways from (0, 0) to (10, 0): straight (50 steps) and a detour over (5, 5) (100 steps)."""
    straight = _walk((0, 0), (10, 0), 50)
    detour = np.concatenate([_walk((0, 0.1), (5, 5), 50), _walk((5, 5), (10, 0.1), 50)[1:]])
    obs = np.concatenate([detour, straight])
    g = build(obs, np.array([0, len(detour)]), keep=5, radius=0.5, neighbours=4)
    nodes = g.path_nodes(np.array([0.0, 0.0]), np.array([10.0, 0.0]))
    assert {int(g.episode[n]) for n in nodes} == {1}
    path = g.densify(np.array([0.0, 0.0]), np.array([10.0, 0.0]), nodes)
    assert np.abs(path[:, 1]).max() < 0.2


def test_settings_and_episodes_are_checked():
    obs, starts = two_pieces()
    for bad in ({"keep": 0}, {"radius": -1.0}, {"neighbours": -1}, {"reach": 0.0}, {"radius": float("nan")}):
        with pytest.raises(BridgeplanError):
            build(obs, starts, **bad)
    with pytest.raises(BridgeplanError):
        build(obs, np.array([3, 10]))


def test_paths_have_a_fixed_length():
    path = np.arange(10.0).reshape(5, 2)
    assert np.array_equal(fixed_length(path, 3), path[:3])
    padded = fixed_length(path, 8)
    assert padded.shape == (8, 2) and np.array_equal(padded[5:], np.repeat(path[-1:], 3, axis=0))
    obs, starts = two_pieces()
    graph = build(obs, starts, keep=5)
    out = GraphSource(graph, length=400)(np.array([[0.0, 0.0], [10.0, 10.0]]), np.array([[10.0, 10.0], [0.0, 0.0]]),
                                        np.arange(2), 0)
    assert out.shape == (2, 400, 2)
    assert [(found, pieces) for _, found, pieces in graph.queries] == [(True, 2), (True, 2)]
    assert np.allclose(out[0, -1], [10, 10]) and np.allclose(out[1, -1], [0, 0])


NAME = "pointmaze-medium-stitch-v0"


@pytest.fixture(scope="module")
def stitch(tmp_path_factory) -> Path:
    """A small stitch dataset (150 episodes of 201 steps, each to a cell 4 BFS steps away) by the real generator."""
    out = tmp_path_factory.mktemp("ogbench-stitch")
    assert main(["data", "generate", "--maze", NAME, "--episodes", "150", "--out", str(out), "--no-progress"]) == 0
    return out / f"{NAME}.npz"


def test_graph_eval_stitches_the_pieces_on_the_protocol(stitch, tmp_path, capsys):
    """Task 1 crosses the maze (more than 4 cells): no episode of the data does, so every path found joins
    several; the JSON says how the graph was built and what its paths asked for."""
    out = tmp_path / "g.json"
    assert main(["graph", "--maze", NAME, "--dataset", str(stitch), "--episodes", "2", "--tasks", "1",
                 "--controller", "pursuit", "--no-progress", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["kind"] == "graph" and r["nfe"] == 0 and r["calls_per_episode"] == 0 and r["episodes"] == 2
    g = r["graph"]
    assert (g["keep"], g["radius"], g["neighbours"], g["reach"]) == (10, 0.5, 8, 2.0)
    assert g["nodes"] > 150 * 20 and g["jumps"] > 0 and g["paths_found"] == 1.0
    assert g["episodes_per_path"]["mean"] >= 2  # no episode of the data goes from a task's start to its goal
    assert r["config"]["dataset_identity"].startswith(f"{NAME}.npz (")
    assert "wrote" in capsys.readouterr().out


def test_graph_eval_refuses_bad_input(stitch, tmp_path, capsys):
    for args in (["--keep", "0"], ["--radius", "-1"], ["--episodes", "0"]):
        assert main(["graph", "--maze", NAME, "--dataset", str(stitch), "--no-progress", *args]) == 2
        assert capsys.readouterr().err.startswith("error: ")
    assert main(["graph", "--maze", NAME, "--dataset", str(tmp_path / "none.npz"), "--no-progress"]) == 2
    assert "no dataset" in capsys.readouterr().err
    assert main(["graph", "--maze", "pointmaze-huge-stitch-v0", "--dataset", str(stitch), "--no-progress"]) == 2
    assert "unknown OGBench pointmaze dataset" in capsys.readouterr().err
    assert main(["graph", "--maze", NAME, "--no-progress"]) == 2
    assert "give the dataset" in capsys.readouterr().err


def test_the_graph_as_a_high_level_spaces_its_path_by_the_low_levels_subgoals():
    """Coarse plans: the path every J = subgoal_every x stride positions, the goal last and repeated; a low level
    without subgoals, or of another layout, is refused; the graph takes no NFE."""
    from types import SimpleNamespace

    from bridgeplan.hierarchy import GraphHierarchy
    from bridgeplan.trajectory import KINEMATIC_POINT, MAZE2D

    obs, starts = two_pieces()
    graph = build(obs, starts, keep=5)
    low = SimpleNamespace(subgoal_every=3, stride=4, layout=KINEMATIC_POINT, subgoals_per_plan=3)
    h = GraphHierarchy(graph, low, episode_steps=1000)
    assert (h.spacing, h.coarse_length, h.resolve_high_nfe(None)) == (12, 85, 0)
    start, goal = np.array([[0.0, 0.0]]), np.array([[10.0, 10.0]])
    coarse, seconds = h.coarse_plans(start, goal, 0, None)
    path = graph.densify(start[0], goal[0], graph.path_nodes(start[0], goal[0]))
    n = (len(path) - 1) // 12 + 1
    assert coarse.shape == (1, 85, 2) and seconds > 0
    assert np.allclose(coarse[0, :n], path[::12]) and np.allclose(coarse[0, n:], goal)
    assert np.allclose(h.subgoals(coarse, np.array([n - 2])), [[path[(n - 1) * 12], goal[0], goal[0]]])
    with pytest.raises(BridgeplanError):
        h.resolve_high_nfe(4)
    for bad in (SimpleNamespace(subgoal_every=0, stride=4, layout=KINEMATIC_POINT, subgoals_per_plan=0),
                SimpleNamespace(subgoal_every=3, stride=4, layout=MAZE2D, subgoals_per_plan=3)):
        with pytest.raises(BridgeplanError):
            GraphHierarchy(graph, bad, episode_steps=1000)


def test_graph_eval_with_a_low_level(stitch, tmp_path, capsys):
    """`graph --low RUN`: the low level (10 states 4 apart through every 3rd) plans through the graph's path
    every 12 steps; one search per episode, no network call for it."""
    low = tmp_path / "low"
    assert main(["train", "--maze", NAME, "--dataset", str(stitch), "--preset", "cpu-small", "--steps", "2",
                 "--checkpoint-every", "2", "--run-dir", str(low), "--device", "cpu", "--no-progress", "--dim", "8",
                 "--dim-mults", "1,2", "--process", "flow", "--prior", "coarse", "--horizon", "10", "--stride", "4",
                 "--subgoal-every", "3"]) == 0
    args = ["graph", "--maze", NAME, "--dataset", str(stitch), "--episodes", "1", "--tasks", "1,2",
            "--controller", "pursuit", "--no-progress", "--device", "cpu"]
    out = tmp_path / "h.json"
    assert main([*args, "--low", str(low), "--nfe-low", "1", "--replan-every", "12", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["kind"] == "graph" and r["method"] == "dataset graph -> flow (coarse) H10k4" and r["nfe"] == 1
    assert r["low"]["subgoal_every"] == 3 and r["config"]["low"]["seed"] == 0
    steps = [sum(t["steps"]) for t in r["tasks"].values()]
    assert r["calls_per_episode"] == pytest.approx(sum(-(-s // 12) for s in steps) / 2)  # one call per low plan
    assert r["graph"]["paths_found"] == 1.0
    capsys.readouterr()
    for bad in (["--nfe-low", "1"], ["--replan-high-every", "50"],
                ["--low", str(low), "--replan-every", "12", "--replan-high-every", "0"]):
        assert main([*args, *bad]) == 2
        assert capsys.readouterr().err.startswith("error: ")


def test_a_stream_that_passes_a_place_again_is_joined_to_itself_and_walked_back_reversed():
    """Maze2D's data is one continuous stream: east along y = 0 to (10, 0), north to (10, 5), west to (5, 5), south
    across its own start of way at (5, 0.05), on to (5, -5). Only with ``within_episodes`` does a path from (0, 0)
    to (5, -5) cut across where the stream passes itself; a stretch walked back has its velocity reversed."""
    from bridgeplan.trajectory import MAZE2D

    xy = np.concatenate([_walk((0, 0), (10, 0), 100), _walk((10, 0), (10, 5), 50)[1:], _walk((10, 5), (5, 5), 50)[1:],
                         _walk((5, 5), (5, 0.05), 50)[1:], _walk((5, 0.05), (5, -5), 50)[1:]])
    states = np.concatenate([xy, np.gradient(xy, axis=0)], axis=1)  # velocity: the step
    alone = build(states, np.array([0]), keep=5, radius=0.2, layout=MAZE2D, step=0.1)
    joined = build(states, np.array([0]), keep=5, radius=0.2, layout=MAZE2D, step=0.1,
                                within_episodes=True)
    assert alone.jumps == 0 and joined.jumps > 0
    start, goal = MAZE2D.at_rest(np.array([0.0, 0.0])), np.array([5.0, -5.0])
    around, across = alone.path(start, goal), joined.path(start, goal)
    assert len(around) > 290 and len(across) < 110  # the whole stream, or 50 + 50 steps and the jump
    for path in (around, across):
        assert path.shape[1] == 4 and np.allclose(path[0], start) and np.allclose(path[-1], [5, -5, 0, 0])
    assert np.abs(across[:, 0] - 5).max() <= 5 and across[:, 1].max() < 0.2
    # walked back from (5, -5) to (0, 0): north (the data went south) then west (it went east)
    back = joined.path(MAZE2D.at_rest(np.array([5.0, -5.0])), np.array([0.0, 0.0]))
    south, west = back[(back[:, 1] < -1) & (back[:, 1] > -4)], back[(back[:, 0] > 1) & (back[:, 0] < 4)]
    assert len(south) and np.all(south[:, 3] > 0) and len(west) and np.all(west[:, 2] < 0)


def test_the_maze2d_graph_takes_its_familys_settings(tiny_dataset):
    from bridgeplan.envs import maze2d
    from bridgeplan.envs.maze2d.datasets import load_stream
    from bridgeplan.graph import for_stream
    from bridgeplan.trajectory import MAZE2D

    stream = load_stream(tiny_dataset)
    graph, settings = for_stream(stream, maze2d.FAMILY, {"keep": 20, "radius": None})
    moves = np.linalg.norm(np.diff(stream.states[:, :2], axis=0), axis=1)
    assert graph.layout == MAZE2D and graph.step == stream.pace()
    assert 0.5 * moves.mean() < graph.step < 2 * moves.max()
    assert settings == {**maze2d.GRAPH, "keep": 20} and graph.reach == maze2d.GRAPH["reach"]
    assert len(graph.nodes) == pytest.approx(len(stream) / 20, abs=5)
    assert graph.jumps > 0  # the stream comes back to places it passed


def test_one_search_per_goal_serves_every_start(monkeypatch):
    """The graph is searched once per goal; later starts (replans, other episodes) look the way up, and find the
    same paths a fresh search would."""
    import bridgeplan.graph as graph_module

    obs, starts = two_pieces()
    calls = []
    real = graph_module.dijkstra
    monkeypatch.setattr(graph_module, "dijkstra", lambda *a, **k: calls.append(1) or real(*a, **k))
    g = build(obs, starts, keep=5, radius=0.5, neighbours=4)
    goal = np.array([10.0, 10.0])
    paths = [g.path_nodes(np.array(s), goal) for s in ([0.0, 0.0], [5.0, 0.0], [10.0, 3.0])]
    assert len(calls) == 1 and g.path_nodes(np.array([0.0, 0.0]), np.array([0.0, 0.0])) and len(calls) == 2
    for s, nodes in zip(([0.0, 0.0], [5.0, 0.0], [10.0, 3.0]), paths):
        fresh = build(obs, starts, keep=5, radius=0.5, neighbours=4)
        assert fresh.path_nodes(np.array(s), goal) == nodes and g.episode[nodes[-1]] == 1
    for s, nodes in zip(([5.0, 0.0], [10.0, 3.0]), paths[1:]):  # each starts where it stands, not at (0, 0)
        assert np.linalg.norm(obs[g.nodes[nodes[0]]] - s) <= g.reach and nodes[0] != paths[0][0]
