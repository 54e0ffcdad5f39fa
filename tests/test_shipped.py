"""Shipped planners (src/bridgeplan/shipped/): the files match their manifest, a name plans wherever a run
directory does (eval, render, PlannerPolicy), an unknown name is one error line, and `planners export` makes the
files and the manifest from a study's runs. Scores are measured by the shipped studies, never asserted here."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from bridgeplan import shipped
from bridgeplan.cli import main
from bridgeplan.errors import BridgeplanError
from bridgeplan.evaluate import make_tasks
from bridgeplan.runs import load_planner, resolve_run, run_dir_of
from tests.test_experiments import TINY_STUDY

REPO = Path(__file__).resolve().parents[1]
NAMES = ["umaze", "medium", "large"]
"""The shipped planners; then the shipped policies."""
POLICIES = ["cube-single"]


def test_every_shipped_file_matches_its_manifest():
    planners = shipped.manifest()
    assert list(planners) == NAMES + POLICIES
    assert [e.kind for e in planners.values()] == ["planner"] * len(NAMES) + ["policy"] * len(POLICIES)
    listed = {p.name for p in shipped.DIR.glob("*.pt")}
    assert listed == {e.file for e in planners.values()}  # no file the manifest does not name
    for e in planners.values():
        if e.kind == "policy":
            continue  # test_every_shipped_policy_matches_its_rows
        assert e.path.stat().st_size == e.bytes and e.bytes < 1_500_000
        assert shipped.sha256(e.path) == e.sha256
        assert (REPO / e.study).is_file() and (REPO / e.rows).is_file()
        assert e.code_version.startswith("0.1.0+") and not e.code_version.endswith(".dirty")
        with open(REPO / e.rows) as f:  # the shipped weights' own committed rows, at the shipped step
            rows = [r for r in csv.DictReader(f) if r["run_name"] == e.run and int(r["step"]) == e.step]
        assert rows and {r["maze"] for r in rows} == {e.maze}
        state = torch.load(e.path, map_location="cpu", weights_only=False)
        assert not {"model", "optimizer", "generator"} & set(state)  # inference only
        assert all(v.dtype == torch.float32 for v in state["ema"].values())
        assert state["step"] == e.step and state["config"]["maze"] == e.maze and "/" not in state["config"]["dataset"]


def test_every_shipped_policy_matches_its_rows(tmp_path, monkeypatch, capsys):
    """A shipped policy: the policy alone in float32 (no critics, no optimizer), its dataset named by its file, its
    committed rows of that run at that step (the policy alone and the graph over it, whose data identity the manifest
    keeps); it loads by name and acts, and `eval NAME` scores it by OGBench's protocol without the dataset."""
    from bridgeplan.gcbc import load_policy

    for name in POLICIES:
        e = shipped.get(name)
        assert e.path.stat().st_size == e.bytes < 3_000_000 and shipped.sha256(e.path) == e.sha256
        assert e.code_version.startswith("0.1.0+") and not e.code_version.endswith(".dirty")
        assert (REPO / e.study).is_file() and e.dataset == f"{e.maze}.npz"
        rows = [json.loads(p.read_text()) for p in sorted((REPO / e.rows).rglob("*.json"))]
        (alone,) = [r for r in rows if "graph" not in r]
        (graph,) = [r for r in rows if "graph" in r]
        assert (alone["run"], alone["step"]) == (e.run, e.step) == (graph["low"]["run"], graph["low"]["step"])
        assert graph["config"]["dataset_identity"] == e.dataset_identity and graph["env_id"] == alone["env_id"]
        state = torch.load(e.path, map_location="cpu", weights_only=False)
        assert not {"agent", "optimizer", "rng"} & set(state) and state["shipped"] == name
        assert all(v.dtype == torch.float32 for v in state["policy"].values())
        assert state["step"] == e.step and "/" not in state["config"]["dataset"]
        policy = load_policy(name)
        assert policy.env == e.maze and policy.dataset_identity == e.dataset_identity
        action = policy.act(np.zeros((2, policy.net.obs_dim)), np.zeros((2, policy.net.obs_dim)))
        assert action.shape == (2, 5) and np.abs(action).max() <= 1
    monkeypatch.chdir(tmp_path)
    assert main(["eval", POLICIES[0], "--episodes", "1", "--tasks", "1", "--no-progress", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["run"] == POLICIES[0] and row["episodes"] == 1 and list(row["tasks"]) == ["1"]
    assert row["method"] == "gciql" and row["train_seconds"] > 0  # the shipped snapshot's training time
    saved = tmp_path / "runs" / "shipped" / POLICIES[0] / "eval" / f"gciql-step{row['step']}-ep1-seed0-tasks1.json"
    assert json.loads(saved.read_text()) == row


def test_pyproject_ships_the_files_as_package_data():
    text = (REPO / "pyproject.toml").read_text()
    assert '"shipped/*.pt"' in text and '"shipped/manifest.json"' in text


def test_a_shipped_name_loads_and_plans():
    planner, info = load_planner("medium", device="cpu")
    e = shipped.get("medium")
    assert info.step == e.step and info.config.maze == "medium" and info.path == Path("runs/shipped/medium")
    assert info.dataset_covers_every_cell
    tasks = make_tasks("medium", 3, 0, False)
    plan = planner.plan(tasks.start_states, tasks.goals_xy, 2, torch.Generator().manual_seed(tasks.seed))
    steps = (planner.horizon - 1) * info.config.stride + 1  # the planned states densified to every step
    assert plan.states.shape == (3, steps, planner.layout.obs_dim) and np.isfinite(plan.states).all()
    np.testing.assert_allclose(plan.states[:, 0], tasks.start_states, atol=1e-4)  # conditioned on the start


def test_planner_policy_from_a_shipped_name():
    from bridgeplan.policy import PlannerPolicy

    policy = PlannerPolicy.from_run("umaze", nfe=1, replan_every=None)
    tasks = make_tasks("umaze", 1, 0, False)
    obs = {"observation": tasks.start_states[0], "desired_goal": tasks.goals_xy[0]}
    actions = [policy(obs) for _ in range(3)]
    assert policy.maze.name == "umaze" and policy.plans_made == 1
    assert all(a.shape == (2,) and np.isfinite(a).all() and np.abs(a).max() <= 1 for a in actions)


def test_eval_and_render_take_a_shipped_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # beside a shipped planner: runs/shipped/NAME under the current directory
    assert main(["eval", "medium", "--episodes", "3", "--nfe", "1", "--multi-task", "--device", "cpu"]) == 0
    out, err = capsys.readouterr()
    assert "warning" not in err  # the shipped dataset's coverage is known: no warning about a missing dataset
    (written,) = (tmp_path / "runs" / "shipped" / "medium" / "eval").glob("*.json")
    result = json.loads(written.read_text())
    assert result["step"] == shipped.get("medium").step and result["episodes"] == 3
    assert result["run"] == "medium" and np.isfinite(result["score"]["minari"]["mean"])
    assert main(["render", "umaze", "--episodes", "2", "--nfe", "1", "--device", "cpu"]) == 0
    assert list((tmp_path / "runs" / "shipped" / "umaze" / "render").glob("*.png"))


def test_a_real_path_wins_over_a_shipped_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "medium").mkdir()
    assert resolve_run("medium") == Path("medium") and run_dir_of("medium") == Path("medium")
    with pytest.raises(BridgeplanError, match="no checkpoint at"):
        load_planner("medium")


def test_an_unknown_name_is_one_error_line_listing_the_shipped(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for command in (["eval", "tiny-maze"], ["render", "tiny-maze"]):
        assert main(command) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == ["error: no checkpoint or run directory 'tiny-maze', and no shipped planner of that name "
                       "(shipped: umaze, medium, large, cube-single; see `bridgeplan planners list`)"]
    assert not (tmp_path / "runs").exists()


def test_a_damaged_shipped_file_is_refused(tmp_path, monkeypatch):
    copy = tmp_path / "shipped"
    shutil.copytree(shipped.DIR, copy, ignore=shutil.ignore_patterns("__init__.py", "__pycache__"))
    data = bytearray((copy / "umaze.pt").read_bytes())
    data[len(data) // 2] ^= 1
    (copy / "umaze.pt").write_bytes(bytes(data))
    monkeypatch.setattr(shipped, "DIR", copy)
    with pytest.raises(BridgeplanError, match="shipped planner 'umaze': .* has sha256 .* the manifest says"):
        load_planner("umaze")
    load_planner("medium")  # the others are intact


def test_planners_list(capsys):
    assert main(["planners"]) == 0 and main(["planners", "list"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    n = len(NAMES + POLICIES)
    assert [line.split("\t")[0] for line in out[:n]] == NAMES + POLICIES == [
        line.split("\t")[0] for line in out[n + 1:2 * n + 1]]
    assert "(bridgeplan graph --low NAME)" in out[n - 1]
    e = shipped.get("large")
    assert f"sha256 {e.sha256}" in out[2] and f"code {e.code_version}" in out[2] and e.study in out[2]
    assert main(["planners", "list", "--json"]) == 0
    assert [d["name"] for d in json.loads(capsys.readouterr().out)] == NAMES + POLICIES


TINY = TINY_STUDY.replace("{steps}", "2").replace("{seeds}", "[0]").replace("episodes = 4", "episodes = 2") + """
[methods.flow-line]
process = "flow"
prior = "line"

[[experiments]]
name = "shipped"
last_snapshot_only = true
series = [{{ method = "flow-line", nfe = [1] }}]
"""


def test_export_makes_the_files_and_the_manifest_from_a_study(tiny_dataset, tmp_path, monkeypatch, capsys):
    import bridgeplan.train

    monkeypatch.setattr(bridgeplan.train, "code_version", lambda: "0.1.0+abc1234")
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(TINY.format(dataset=tiny_dataset))
    (root / "studies" / "ship.toml").write_text('uses = ["tiny"]\n')
    out = tmp_path / "out"
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out)]) == 2
    assert "no committed rows at" in capsys.readouterr().err  # unscored weights are not shipped
    rows = root / "docs" / "results" / "tiny" / "results.csv"
    assert main(["report", "--results", str(root / "results" / "tiny"), "--csv", str(rows)]) == 0
    capsys.readouterr()
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out)]) == 0
    assert "wrote umaze.pt (umaze: flow (line) on umaze" in capsys.readouterr().out

    made = json.loads((out / "manifest.json").read_text())
    assert made["made_by"] == "bridgeplan planners export --study ship"
    (entry,) = made["planners"]
    assert {k: entry[k] for k in ("name", "maze", "method", "study", "rows", "run", "seed", "step", "code_version",
                                  "dataset")} == {
        "name": "umaze", "maze": "umaze", "method": "flow (line)", "study": "studies/tiny.toml",
        "rows": "docs/results/tiny/results.csv", "run": "umaze-flow-line-N6-H32-cpu-small-s0", "seed": 0,
        "step": 2, "code_version": "0.1.0+abc1234", "dataset": Path(tiny_dataset).name}
    assert entry["sha256"] == shipped.sha256(out / "umaze.pt") and entry["bytes"] == (out / "umaze.pt").stat().st_size
    monkeypatch.setattr(shipped, "DIR", out)
    planner, info = load_planner("umaze", device="cpu")
    snapshot, _ = load_planner(root / "results" / "tiny" / "runs" / entry["run"], device="cpu")
    for a, b in zip(planner.model.state_dict().values(), snapshot.model.state_dict().values(), strict=True):
        assert torch.equal(a, b)  # the shipped weights are the evaluated snapshot's
    assert info.step == 2 and list(shipped.manifest()) == ["umaze"]

    # --only: one planner remade, the others' files and entries kept as they are (their runs need not be here)
    other = TINY.format(dataset=tiny_dataset).replace('maze = "umaze"', 'maze = "medium"', 1)
    (root / "studies" / "other.toml").write_text(other)
    (root / "studies" / "ship.toml").write_text('uses = ["other", "tiny"]\n')
    kept = dict(entry, name="medium", maze="medium", file="medium.pt", study="studies/other.toml")
    shutil.copy(out / "umaze.pt", out / "medium.pt")
    (out / "manifest.json").write_text(json.dumps({"made_by": "earlier", "planners": [kept]}))
    before = (out / "umaze.pt").read_bytes()
    (out / "umaze.pt").unlink()
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out),
                 "--only", "umaze"]) == 0
    said = capsys.readouterr().out
    assert "kept medium.pt (medium: as shipped" in said and "wrote umaze.pt (umaze: flow (line)" in said
    made = json.loads((out / "manifest.json").read_text())["planners"]
    assert [e["name"] for e in made] == ["medium", "umaze"] and made[0] == kept
    assert (out / "umaze.pt").read_bytes() == before  # the same snapshot, remade
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out),
                 "--only", "large"]) == 2
    assert "no shipped planner named large: choose from medium, umaze" in capsys.readouterr().err
    (out / "medium.pt").write_bytes(b"damaged")
    manifest_text = (out / "manifest.json").read_text()
    (out / "umaze.pt").unlink()
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out),
                 "--only", "umaze"]) == 2
    assert "medium would be kept as shipped, but" in capsys.readouterr().err
    assert not (out / "umaze.pt").exists() and (out / "manifest.json").read_text() == manifest_text  # nothing written


def test_the_report_looks_the_shipped_rows_up_at_the_headlines_choice(tmp_path):
    """Each line is the headline's chosen setting (read from its rows) with the shipped run's row there; a setting
    the shipped study did not evaluate says so instead of showing another one's score."""
    from tests.reports import report as generator

    report = generator("shipped")

    root = tmp_path / "results"
    shutil.copytree(REPO / "docs" / "results", root, ignore=shutil.ignore_patterns("*.png"))
    found = report.entries(root)
    assert [(e["maze"], e["multi_task"], e["pursued"]) for e in found] == [
        (m, multi, p) for m in NAMES for multi in (False, True) for p in (False, True)]
    for e in found:
        assert e["row"] is not None and e["row"].key == e["key"] and e["row"].nfe == e["nfe"]
        assert e["shipped"] == f"{e['row'].score:.1f} ± {e['row'].score_se:.1f} ({e['row'].success:.2f})"
    # large's shipped run is the headline's seed-0 run (copied: equal rows); umaze's and medium's were retrained
    assert [report.same_run(found, m) for m in NAMES] == [False, False, True]
    assert "seeds 0-2, seed 0 is this run" in report.block(root) and "seeds 0-2, not this run" in report.block(root)
    path = root / "shipped" / "large" / "results.csv"
    text = path.read_text()
    score = str(next(e for e in found if e["maze"] == "large")["row"].score)
    path.write_text(text.replace(score, str(float(score) + 0.5), 1))  # one setting's evaluation differs
    assert not report.same_run(report.entries(root), "large")
    path.write_text(text)
    drop = next(e for e in found if e["maze"] == "medium" and e["pursued"] and not e["multi_task"])
    path = root / "shipped" / "medium" / "results.csv"
    with open(path) as f:
        rows = list(csv.DictReader(f))
    kept = [r for r in rows if (r["execution"], int(r["nfe"]), r["multi_task"]) != (drop["row"].key.tag, drop["nfe"],
                                                                                     "0")]
    assert len(kept) == len(rows) - 1
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(kept)
    after = report.entries(root)
    assert [e["shipped"] is None for e in after] == [e is drop for e in found]
    assert f"medium single-task, {drop['setting']}: not evaluated" in report.block(root)


POLICY_STUDY = """
title = "a shipped policy"

[dataset]
maze = "pointmaze-medium-navigate-v0"
path = "{dataset}"

[training]
steps = 4
checkpoint_every = 2
seeds = [0]

[runs.gciql]
trainer = "gcbc"
maze = "pointmaze-medium-navigate-v0"
agent = "gciql"
batch_size = 8
hidden_dims = [8, 8]
log_every = 2
device = "cpu"

[[evaluations]]
command = "eval"
runs = ["gciql"]
args = {{ snapshot = 4, episodes = 1 }}
out = "shipped/tiny/gciql-s{{seed}}.json"
task_seed = 0

[[evaluations]]
command = "graph"
runs = ["gciql"]
args = {{ episodes = 1, tasks = "1", keep = 5, replan_every = 20, policy_ahead = 3 }}
out = "shipped/tiny/graph-gciql-s{{seed}}.json"
task_seed = 0
"""


def test_a_shipped_policy_plans_with_the_graph_over_the_users_own_data(tmp_path, monkeypatch, capsys):
    """An evaluation study's GCIQL run exported as a shipped policy (the policy alone, its data named, the identity
    of the data its graph rows were built over): `graph --low NAME` builds the graph over the user's own generated
    data and gives the committed row again, `eval NAME` the policy's row; data of another identity at the default
    place is one error line; unscored weights are not shipped."""
    from bridgeplan.policy import PlannerPolicy

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("BRIDGEPLAN_DATASETS", str(tmp_path / "ds"))
    data = tmp_path / "ds" / "ogbench" / "pointmaze-medium-navigate-v0.npz"
    assert main(["data", "generate", "--maze", "pointmaze-medium-navigate-v0", "--episodes", "4",
                 "--episode-steps", "40", "--no-progress"]) == 0
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "shipped-tiny.toml").write_text(POLICY_STUDY.format(dataset=data))
    (root / "studies" / "ship.toml").write_text('uses = ["shipped-tiny"]\n')
    out = tmp_path / "out"
    import bridgeplan.gcbc

    monkeypatch.setattr(bridgeplan.gcbc, "code_version", lambda: "0.1.0+abc1234")
    assert main(["study", "run", "shipped-tiny", "--no-progress", "--root", str(root)]) == 0
    capsys.readouterr()
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out)]) == 2
    assert "has no committed rows docs/results/shipped/tiny/" in capsys.readouterr().err  # unscored: not shipped
    assert not (out / "tiny.pt").exists()
    assert main(["study", "export", "shipped-tiny", "--root", str(root)]) == 0
    assert main(["planners", "export", "--study", "ship", "--root", str(root), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "wrote tiny.pt (tiny: the dataset graph over GCIQL on pointmaze-medium-navigate-v0" in said
    (entry,) = json.loads((out / "manifest.json").read_text())["planners"]
    committed = json.loads((root / "docs" / "results" / "shipped" / "tiny" / "graph-gciql-s0.json").read_text())
    assert entry["kind"] == "policy" and entry["dataset"] == data.name and entry["run"] == "gciql-s0"
    assert entry["dataset_identity"] == committed["config"]["dataset_identity"]
    assert str(tmp_path) not in (out / "manifest.json").read_text()  # no path of the machine that made it

    monkeypatch.setattr(shipped, "DIR", out)
    assert bridgeplan.gcbc.is_gcbc_run("tiny") and run_dir_of("tiny") == Path("runs/shipped/tiny")
    assert main(["graph", "--low", "tiny", "--episodes", "1", "--tasks", "1", "--keep", "5", "--replan-every", "20",
                 "--policy-ahead", "3", "--no-progress", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["tasks"] == committed["tasks"] and again["low"] == dict(committed["low"], run="tiny")
    assert list((tmp_path / "runs" / "shipped" / "tiny" / "eval").glob("graph-*.json"))
    assert main(["eval", "tiny", "--episodes", "1", "--no-progress", "--json"]) == 0
    alone = json.loads(capsys.readouterr().out)
    policy_row = json.loads((root / "docs" / "results" / "shipped" / "tiny" / "gciql-s0.json").read_text())
    assert alone["tasks"] == policy_row["tasks"] and alone["run"] == "tiny"
    assert PlannerPolicy.from_graph("tiny", replan_every=20, graph={"keep": 5}).env == "pointmaze-medium-navigate-v0"

    with np.load(data) as f:  # other data at the default place: refused, nothing written
        arrays = dict(f)
    arrays["observations"] = arrays["observations"] + 0.01
    np.savez(data, **arrays)
    before = sorted((tmp_path / "runs").rglob("*"))
    assert main(["graph", "--low", "tiny", "--episodes", "1", "--tasks", "1", "--keep", "5", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "not the data the shipped policy was scored over" in err
    assert len(err.strip().splitlines()) == 1 and sorted((tmp_path / "runs").rglob("*")) == before
    assert main(["eval", "tiny", "--snapshot", "2", "--no-progress"]) == 2
    assert "has the weights of step 4 only" in capsys.readouterr().err


def test_the_report_puts_a_shipped_policys_rows_beside_its_campaigns(tmp_path, monkeypatch):
    """A shipped policy's lines: its graph row's success, the flags that evaluate it again (read from the row), the
    policy alone, and its campaign's mean over training seeds, saying whether its seed's run is this one (equal
    episodes). Here the campaign's own seed-0 rows stand in for the shipped ones, so they are that run."""
    from tests.reports import report as generator

    report = generator("shipped")
    root = tmp_path / "results"
    shutil.copytree(REPO / "docs" / "results", root, ignore=shutil.ignore_patterns("*.png", "*.gif"))
    home = root / "shipped" / "cube-single"
    shutil.rmtree(home, ignore_errors=True)  # the shipped rows replaced by the campaign's seed-0 rows
    shutil.copytree(root / "manip-cube-single" / "graph-keep5-r1-gciql-ahead25-s0",
                    home / "graph-keep5-r1-gciql-ahead25-s0")
    shutil.copy(root / "manip-cube-single" / "gciql-s0-step20000-seed0.json", home)
    listed = dict(json.loads((shipped.DIR / "manifest.json").read_text()))
    entry = dict(listed["planners"][0], name="cube-single", maze="cube-single-play-v0", kind="policy",
                 rows="docs/results/shipped/cube-single", method="the dataset graph over GCIQL")
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "manifest.json").write_text(json.dumps({"planners": [entry]}))
    monkeypatch.setattr(shipped, "DIR", tmp_path / "pkg")
    (p,) = report.policies(root)
    graph = json.loads((home / "graph-keep5-r1-gciql-ahead25-s0" / "track-replan50-seed0.json").read_text())
    alone = json.loads((home / "gciql-s0-step20000-seed0.json").read_text())
    line = report.policy_line(p)
    assert p["same"] and "(seed 0 is this run)" in line and len(p["theirs"]) == 3
    assert f": {100 * graph['success_rate']:.1f}% of its 5 test tasks' 250 episodes" in line
    assert f"the policy alone: {100 * alone['success_rate']:.1f}%" in line
    assert "`bridgeplan graph --low cube-single --keep 5 --radius 1 --replan-every 50 --policy-ahead 25`" in line
    assert 'PlannerPolicy.from_graph("cube-single", replan_every=50, graph={"keep": 5, "radius": 1}, ' \
           'policy_ahead=25)' in line
    assert line in report.block(root) and line in report.render(root)
    graph["tasks"]["1"]["successes"] -= 1  # another run: its episodes differ
    (home / "graph-keep5-r1-gciql-ahead25-s0" / "track-replan50-seed0.json").write_text(json.dumps(graph))
    assert "(not this run)" in report.policy_line(report.policies(root)[0])
