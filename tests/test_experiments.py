"""Sweeps, the results store and the report, with a tiny grid."""

from __future__ import annotations

import sqlite3

import pytest

from bridgeplan.cli import main
from bridgeplan.experiments.store import SCHEMA_VERSION, ResultsStore

TINY_SWEEP = ["--maze", "umaze", "--train-steps", "2", "--prior-steps", "2", "--checkpoint-every", "1",
              "--episodes", "4", "--no-progress",
              "--horizon", "32", "--dim", "8", "--dim-mults", "1,2", "--diffusion-steps", "6", "--batch-size", "4",
              "--device", "cpu"]


def test_sweep_resumes_and_reports(tiny_dataset, tmp_path, capsys):
    results = tmp_path / "results"
    args = ["experiment", "nfe1", "--dataset", tiny_dataset, "--results", str(results), *TINY_SWEEP]
    assert main(args) == 0
    rows = ResultsStore(results / "results.sqlite").rows("nfe1")
    # 4 series (DDPM + 3 priors) x 2 snapshots
    assert len(rows) == 8
    assert {(r["process"], r["prior"]) for r in rows} == {
        ("ddpm", "gaussian"), ("bridge", "gaussian"), ("bridge", "line"), ("bridge", "learned")}
    assert all(r["nfe"] == 1 and r["episodes"] == 4 for r in rows)
    capsys.readouterr()
    # running it again does only what is missing: nothing
    assert main(args) == 0
    assert "0 new results" in capsys.readouterr().out
    assert len(ResultsStore(results / "results.sqlite").rows()) == 8
    # a second experiment reuses the trained runs (no new training directory)
    runs_before = sorted(p.name for p in (results / "runs").iterdir())
    assert main(["experiment", "priors", "--dataset", tiny_dataset, "--results", str(results), *TINY_SWEEP]) == 0
    assert sorted(p.name for p in (results / "runs").iterdir()) == runs_before

    assert main(["report", "--results", str(results)]) == 0
    report = (results / "report" / "report.md").read_text()
    assert "## nfe1" in report and "| DDPM N=6 NFE=1 | 2 |" in report
    assert (results / "report" / "nfe1.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["report", "--results", str(results), "--csv", str(tmp_path / "all.csv")]) == 0
    assert len((tmp_path / "all.csv").read_text().strip().splitlines()) == 1 + len(
        ResultsStore(results / "results.sqlite").rows())


@pytest.mark.parametrize("args, message", [
    (["nfe1", "--maze", "maze9"], "unknown maze"),
    (["priors", "--diffusion-steps", "4", "--fixed-nfe", "8"], "allows 1..3"),
    (["nfe1", "--train-steps", "0"], "must be positive"),
])
def test_bad_sweeps_leave_no_store(tmp_path, capsys, args, message):
    assert main(["experiment", *args, "--results", str(tmp_path / "r")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_unknown_experiment(tmp_path, capsys):
    assert main(["experiment", "nope", "--results", str(tmp_path / "r")]) == 2
    assert "unknown experiment" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_newer_schema_is_refused_untouched(tmp_path, capsys):
    db = tmp_path / "results.sqlite"
    with sqlite3.connect(db) as con:
        con.execute("CREATE TABLE results (id INTEGER)")
        con.execute(f"PRAGMA user_version={SCHEMA_VERSION + 1}")
    before = db.read_bytes()
    assert main(["report", "--results", str(tmp_path)]) == 2
    assert "newer" in capsys.readouterr().err
    assert db.read_bytes() == before


@pytest.mark.parametrize("backend", [["--workers", "2"], ["--backend", "ray"]])
def test_parallel_backends_fill_the_same_store(tiny_dataset, tmp_path, backend):
    if "ray" in backend:
        pytest.importorskip("ray")
    results = tmp_path / "results"
    args = ["experiment", "bridge-vs-ddpm", "--dataset", tiny_dataset, "--results", str(results), *TINY_SWEEP]
    assert main(args + backend) == 0
    rows = ResultsStore(results / "results.sqlite").rows()
    assert len(rows) == 4 and {r["process"] for r in rows} == {"ddpm", "bridge"}
    assert all(r["nfe"] == 5 for r in rows)  # N - 1 with the tiny 6 diffusion steps


def test_ray_address_that_does_not_answer(tiny_dataset, tmp_path, capsys):
    pytest.importorskip("ray")
    results = tmp_path / "r"
    assert main(["experiment", "nfe1", "--dataset", tiny_dataset, "--results", str(results),
                 *TINY_SWEEP, "--backend", "ray", "--ray-address", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ray" in err[0].lower()
    assert not (results / "runs").exists()
