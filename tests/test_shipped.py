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


def test_every_shipped_file_matches_its_manifest():
    planners = shipped.manifest()
    assert list(planners) == NAMES
    listed = {p.name for p in shipped.DIR.glob("*.pt")}
    assert listed == {e.file for e in planners.values()}  # no file the manifest does not name
    for e in planners.values():
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
                       "(shipped: umaze, medium, large; see `bridgeplan planners list`)"]
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
    assert [line.split("\t")[0] for line in out[:3]] == NAMES == [line.split("\t")[0] for line in out[4:7]]
    e = shipped.get("large")
    assert f"sha256 {e.sha256}" in out[2] and f"code {e.code_version}" in out[2] and e.study in out[2]
    assert main(["planners", "list", "--json"]) == 0
    assert [d["name"] for d in json.loads(capsys.readouterr().out)] == NAMES


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
