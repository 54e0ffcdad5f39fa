"""Hierarchical planning: subgoal conditions in training, the coarse prior, levels that fit, the closed loop."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from bridgeplan import config as cfg
from bridgeplan.cli import main
from bridgeplan.errors import BridgeplanError
from bridgeplan.normalizer import Normalizer
from bridgeplan.priors import CoarsePrior, LinePrior
from bridgeplan.trajectory import MAZE2D, window_conditions
from tests.test_train import train_args

HIGH = ["--horizon", "8", "--stride", "12"]
"""umaze: 8 coarse states 12 steps apart (85 steps)."""
LOW = ["--horizon", "16", "--stride", "4", "--subgoal-every", "3"]
"""5 subgoals 3 x 4 = 12 steps apart: one high-level step each."""


def _normalizer() -> Normalizer:
    return Normalizer(np.array([-2.0, -2.0, -3.0, -3.0, -1.0, -1.0]), np.array([2.0, 2.0, 3.0, 3.0, 1.0, 1.0]))


def test_window_conditions_take_every_subgoal():
    x0 = torch.randn(3, 16, MAZE2D.transition_dim)
    cond = window_conditions(x0, MAZE2D, subgoal_every=3)
    assert sorted(cond) == [0, 3, 6, 9, 12, 15]
    assert torch.equal(cond[9], x0[:, 9, 2:])
    assert sorted(window_conditions(x0, MAZE2D)) == [0, 15]


def test_coarse_prior_is_the_line_through_the_subgoals():
    norm = _normalizer()
    torch.manual_seed(0)
    states = torch.rand(2, 3, 4) * 2 - 1  # start, subgoal at t=6, goal at t=12 (normalized states)
    cond = {0: states[:, 0], 6: states[:, 1], 12: states[:, 2]}
    x = CoarsePrior(norm, MAZE2D, stride=2).sample(cond, 13, 2)
    pos = MAZE2D.positions(torch.as_tensor(norm.unnormalize(x.double().numpy())))
    knots = MAZE2D.state_positions(torch.as_tensor(norm.unnormalize(states.double().numpy(), MAZE2D.state_columns)))
    for a, b, piece in ((0, 1, slice(0, 7)), (1, 2, slice(6, 13))):
        frac = torch.linspace(0, 1, 7, dtype=torch.float64)[None, :, None]
        expected = knots[:, a, None] + frac * (knots[:, b] - knots[:, a])[:, None]
        assert torch.allclose(pos[:, piece], expected, atol=1e-5)
    # between the knots the velocity covers each piece in its 6 x 2 steps (0.01 s each), as the line prior's
    vel = MAZE2D.velocities(torch.as_tensor(norm.unnormalize(x.double().numpy())))
    want = ((knots[:, 1] - knots[:, 0]) / (6 * 2 * 0.01)).clamp(-5, 5)
    assert torch.allclose(vel[:, 3], want, atol=1e-4)
    # with only the start and the goal it is the line prior
    ends = {0: states[:, 0], 12: states[:, 2]}
    line = LinePrior(norm, MAZE2D, 2).sample(ends, 13, 2)
    assert torch.allclose(CoarsePrior(norm, MAZE2D, 2).sample(ends, 13, 2), line)


def test_subgoal_config_is_checked():
    with pytest.raises(BridgeplanError, match="multiple"):
        cfg.preset_config("umaze", "cpu-small", horizon=16, stride=4, subgoal_every=4)
    with pytest.raises(BridgeplanError, match="--subgoal-every"):
        cfg.preset_config("umaze", "cpu-small", horizon=16, stride=4, process={"name": "flow"}, prior="coarse")
    c = cfg.preset_config("umaze", "cpu-small", horizon=16, stride=4, subgoal_every=3, process={"name": "flow"},
                          prior="coarse")
    assert "-sg3-" in c.run_name()


@pytest.fixture(scope="module")
def levels(tiny_dataset, tmp_path_factory):
    root = tmp_path_factory.mktemp("hierarchy")
    runs = {"high": root / "high", "low": root / "low", "low-ddpm": root / "low-ddpm"}
    assert main(train_args(tiny_dataset, runs["high"], 3, *HIGH, "--process", "flow", "--prior", "line")) == 0
    assert main(train_args(tiny_dataset, runs["low"], 3, *LOW, "--process", "flow", "--prior", "coarse")) == 0
    assert main(train_args(tiny_dataset, runs["low-ddpm"], 3, *LOW)) == 0
    return runs


def test_low_level_trains_on_its_windows_subgoals():
    """The training loss of a low level is the process's loss with every subgoal conditioned and the coarse prior
    through them, not the loss with the start and the goal only."""
    from bridgeplan.train import planner_job

    config = cfg.preset_config("umaze", "cpu-small", horizon=16, stride=4, subgoal_every=3, process={"name": "flow"},
                               prior="coarse")
    job = planner_job(config, _normalizer(), torch.device("cpu"))
    torch.manual_seed(0)
    x0 = torch.randn(4, 16, MAZE2D.transition_dim) * 0.3

    def by_hand(subgoal_every: int) -> torch.Tensor:
        gen = torch.Generator().manual_seed(5)
        cond = window_conditions(x0, MAZE2D, subgoal_every)
        x1 = CoarsePrior(_normalizer(), MAZE2D, 4).sample(cond, 16, 4, generator=gen) if subgoal_every else \
            LinePrior(_normalizer(), MAZE2D, 4).sample(cond, 16, 4, generator=gen)
        return config.process.training_loss(job.model, x0, x1, cond, generator=gen)

    loss = job.loss(x0, torch.Generator().manual_seed(5))
    assert torch.equal(loss, by_hand(3)) and not torch.allclose(loss, by_hand(0))
    x1 = CoarsePrior(_normalizer(), MAZE2D, 4).sample(window_conditions(x0, MAZE2D, 3), 16, 4)
    assert torch.allclose(x1[:, 6, 2:], x0[:, 6, 2:]) and not torch.allclose(x1[:, 5, 2:], x0[:, 5, 2:])


def test_hierarchy_eval_end_to_end(levels, tmp_path):
    out = tmp_path / "h.json"
    assert main(["hierarchy", "eval", str(levels["high"]), str(levels["low"]), "--episodes", "4", "--nfe-high", "2",
                 "--nfe-low", "1", "--out", str(out), "--device", "cpu"]) == 0
    r = json.loads(out.read_text())
    assert r["kind"] == "hierarchy" and r["episodes"] == 4
    assert r["high"]["stride"] == 12 and r["low"]["subgoal_every"] == 3 and r["low"]["prior"] == "coarse"
    assert r["execution"]["replan_every"] == 12 and r["execution"]["controller"] == "pursuit"
    # one coarse plan (2 calls) and one low-level plan (1 call) every 12 of umaze's 300 steps
    assert r["plans_per_episode"]["mean"] == 25
    assert r["calls_per_episode"] == 2 + 25
    assert 0 <= r["success_rate"]["mean"] <= 1 and "score" in r["high_alone"] and "score" in r["floor_line"]
    assert "/" not in r["high"]["config"]["dataset"]
    # the high level replanned every 60 steps: coarse plans at steps 0, 60, 120, 180 and 240 (2 calls each)
    assert main(["hierarchy", "eval", str(levels["high"]), str(levels["low"]), "--episodes", "4", "--nfe-high", "2",
                 "--nfe-low", "1", "--replan-high-every", "60", "--out", str(out), "--device", "cpu"]) == 0
    r = json.loads(out.read_text())
    assert r["execution"]["replan_high_every"] == 60 and r["calls_per_episode"] == 5 * 2 + 25


def test_hierarchy_subgoals_follow_progress(levels):
    from bridgeplan.hierarchy import HierarchySource, load_hierarchy

    hierarchy, _, _ = load_hierarchy(levels["high"], levels["low"], device="cpu")
    coarse = np.zeros((2, 8, 4))
    coarse[:, :, 0] = np.arange(8)  # coarse positions x = 0..7
    source = HierarchySource(hierarchy, 1, 1, torch.Generator().manual_seed(0), 2)
    source.coarse, source.progress = coarse, np.array([0, 5])
    # episode 0 stands at x = 2.2: nearest coarse index 2; episode 1 at x = 0 but progress never runs back
    progress = source.advance(np.array([[2.2, 0.0], [0.0, 0.0]]), np.arange(2))
    assert list(progress) == [2, 5]
    sub = hierarchy.subgoals(coarse, progress)
    assert sub.shape == (2, 5, 4)
    assert list(sub[0, :, 0]) == [3, 4, 5, 6, 7] and list(sub[1, :, 0]) == [6, 7, 7, 7, 7]  # the goal repeats


def test_levels_that_do_not_fit_are_one_error_line(levels, tmp_path, tiny_dataset, capsys):
    for high, low, message in ((levels["low"], levels["low"], "high level must plan from a start"),
                               (levels["high"], levels["high"], "low level must plan between subgoals")):
        assert main(["hierarchy", "eval", str(high), str(low), "--episodes", "2", "--device", "cpu"]) == 2
        assert message in capsys.readouterr().err
    other = tmp_path / "high-other"
    assert main(train_args(tiny_dataset, other, 1, "--horizon", "8", "--stride", "8")) == 0
    assert main(["hierarchy", "eval", str(other), str(levels["low"]), "--episodes", "2", "--device", "cpu"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: the levels do not fit") and err.count("\n") == 1
    # a low level alone is not a planner to a goal
    assert main(["eval", str(levels["low"]), "--episodes", "2", "--device", "cpu"]) == 2
    assert "hierarchy's low level" in capsys.readouterr().err


def test_hierarchy_as_a_policy(levels):
    from bridgeplan.policy import PlannerPolicy

    policy = PlannerPolicy.from_hierarchy(levels["high"], levels["low"], nfe_high=1, nfe_low=1, replan_every=12)
    obs = {"observation": np.array([1.0, 1.0, 0.0, 0.0]), "desired_goal": np.array([1.0, -1.0])}
    for _ in range(13):
        action = policy(obs)
    assert action.shape == (2,) and policy.plans_made == 2
    policy.reset()
    policy(obs)
    assert policy.plans_made == 1


def test_the_graph_hierarchy_as_a_policy(levels):
    """One search per goal, one low-level plan every 12 steps; a new goal plans afresh."""
    from bridgeplan.policy import PlannerPolicy

    policy = PlannerPolicy.from_graph(levels["low"], nfe_low=1, lookahead=1.0)
    obs = {"observation": np.array([1.0, 1.0, 0.0, 0.0]), "desired_goal": np.array([1.0, -1.0])}
    for _ in range(13):
        action = policy(obs)
    graph = policy.source.hierarchy.graph
    assert action.shape == (2,) and policy.plans_made == 2 and len(graph.queries) == 1
    policy(obs | {"desired_goal": np.array([-1.0, -1.0])})
    assert policy.plans_made == 3 and len(graph.queries) == 2


def test_coarse_plans_hold_the_goal_from_their_first_arrival(levels):
    from bridgeplan.hierarchy import COARSE_ARRIVAL, load_hierarchy
    from bridgeplan.replan import arrival_index

    hierarchy, _, _ = load_hierarchy(levels["high"], levels["low"], device="cpu")
    starts = MAZE2D.at_rest(np.array([[1.0, 1.0]] * 6))
    goals = np.array([[1.0, -1.0]] * 3 + [[1.0, 1.2]] * 3)  # the last three start within 0.45 of their goal
    coarse, seconds = hierarchy.coarse_plans(starts, goals, 1, torch.Generator().manual_seed(0))
    assert coarse.shape == (6, 8, 4) and seconds > 0
    plan = hierarchy.high.plan(starts, goals, 1, torch.Generator().manual_seed(0))  # the same draw, uncut
    full = hierarchy.high.normalizer.unnormalize(plan.sampled.double().numpy())
    arrival, raw = arrival_index(full, goals, MAZE2D, COARSE_ARRIVAL), MAZE2D.states(full)
    assert list(arrival[3:]) == [0, 0, 0]
    for k in range(6):
        a = arrival[k]
        assert np.allclose(coarse[k, :a + 1], raw[k, :a + 1])
        assert np.allclose(coarse[k, a + 1:, :2], goals[k]) and np.allclose(coarse[k, a + 1:, 2:], 0)


def test_coarse_diagnostics_measure_walls_and_arrival():
    from bridgeplan.envs.maze2d.grids import get_maze
    from bridgeplan.hierarchy import coarse_diagnostics

    maze = get_maze("umaze")  # cell (2, 2) is a wall; (1, 1) and (3, 1) are free
    a, wall, b = maze.cell_to_xy(np.array([[1, 1], [2, 2], [3, 1]]))
    dense = np.zeros((2, 5, 4))
    dense[0, :, :2] = [a, a, wall, b, b]  # one of five positions in a wall, at the goal from step 3
    dense[1, :, :2] = a                   # never arrives: the last step
    out = coarse_diagnostics(dense, np.array([b, b]), maze.is_free_xy, MAZE2D)
    assert out == {"in_walls": 0.1, "crossing_walls": 0.5, "arrival_step": (3 + 4) / 2}


@pytest.mark.parametrize("rule, expected", [("nearest", [5, 5]), ("sequential", [0, 1])])
def test_progress_along_a_plan_that_winds_back(rule, expected):
    """A U-shaped coarse plan (out along y = 0, back along y = 2, a wall between): a position near its start but
    nearer its last state across the wall. ``nearest`` jumps there (Maze2D's committed rule); ``sequential`` (the
    dataset graph's) moves one coarse state at a time, only past states it has reached."""
    from types import SimpleNamespace

    from bridgeplan.hierarchy import HierarchySource
    from bridgeplan.trajectory import KINEMATIC_POINT

    low = SimpleNamespace(layout=KINEMATIC_POINT, process=SimpleNamespace(max_nfe=1, validate_nfe=lambda n: None))
    hierarchy = SimpleNamespace(low=low, subgoals_per_plan=5, progress_rule=rule, resolve_high_nfe=lambda n: 0,
                                points=KINEMATIC_POINT.state_positions)
    source = HierarchySource(hierarchy, None, None, None, 1)
    source.coarse = np.array([[[0, 0], [2, 0], [4, 0], [4, 2], [2, 2], [0, 2.0]]])
    source.progress = np.zeros(1, dtype=np.int64)
    reached = [int(source.advance(np.array([p]), np.arange(1))[0]) for p in ([0.5, 1.5], [2.1, 0.1])]
    assert reached == expected


def test_graph_eval_makes_the_data_the_high_level(levels, tmp_path, capsys):
    """`graph --low LOW` on Maze2D: the graph over the low level's own dataset plans once per episode (no network
    call), the low level every 12 steps (its subgoal spacing, by default); its coarse plans never cross a wall of
    umaze (the data never does)."""
    out = tmp_path / "g.json"
    args = ["graph", "--low", str(levels["low"]), "--episodes", "4", "--nfe-low", "1", "--device", "cpu"]
    assert main([*args, "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["kind"] == "graph" and r["high"]["method"] == "dataset graph" and r["high"]["nfe"] == 0
    assert r["high"]["stride"] == 12 and r["execution"]["replan_every"] == 12
    g = r["high"]["graph"]
    assert (g["keep"], g["radius"]) == (10, 0.2) and g["paths_found"] == 1.0 and g["nodes"] > 500
    assert g["dataset_identity"].startswith("umaze-tiny (umaze, ") and "/" not in g["dataset_identity"]
    assert r["calls_per_episode"] == 25 and "floor_line" not in r  # one low-level call per 12 of 300 steps
    assert r["coarse_plans"]["in_walls"] == 0.0
    assert "dataset graph -> " in capsys.readouterr().out
    assert main([*args, "--replan-high-every", "100", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["execution"]["replan_high_every"] == 100
    for bad in (["--keep", "0"], ["--radius", "-1"], ["--nfe-low", "0"], ["--replan-high-every", "0"]):
        assert main([*args, *bad, "--out", str(tmp_path / "bad.json")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1
    assert not (tmp_path / "bad.json").exists()
    # the graph holds Maze2D states; a high level's run is no low level
    assert main(["graph", "--low", str(levels["high"]), "--episodes", "2", "--device", "cpu"]) == 2
    assert "low level must plan between subgoals" in capsys.readouterr().err
