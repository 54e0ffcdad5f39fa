"""Sweeps (the thesis's grids in tiny study files), the results store and the report."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from bridgeplan.cli import main
from bridgeplan.experiments.grids import get_experiment
from bridgeplan.experiments.store import SCHEMA_VERSION, ResultsStore
from bridgeplan.processes import Flow

TINY_STUDY = """
[dataset]
maze = "umaze"
path = "{dataset}"

[training]
steps = {steps}
checkpoint_every = 1
prior_steps = 2
seeds = {seeds}
diffusion_steps = 6
horizon = 32
batch_size = 4
device = "cpu"
model = {{ dim = 8, dim_mults = [1, 2] }}

[evaluation]
episodes = 4
workers = 1
"""


def tiny_study(root: Path, dataset: str, *grids: str, steps: int = 2, seeds: tuple = (0,),
               validation: bool = False) -> tuple[list[str], Path]:
    """The study ``root/studies/tiny.toml`` of the thesis's ``grids`` at a tiny scale (6 diffusion steps, a
    horizon of 32, a U-Net of dim 8, ``steps`` optimizer steps snapshotted at each); returns its `study run`
    arguments and its results directory."""
    (root / "studies").mkdir(parents=True, exist_ok=True)
    splits = '\nsplits = ["test", "validation"]' if validation else ""
    experiments = "".join(f'\n[[experiments]]\ngrid = "{g}"{splits}\n' for g in grids)
    (root / "studies" / "tiny.toml").write_text(TINY_STUDY.format(dataset=dataset, steps=steps, seeds=list(seeds))
                                               + experiments)
    return ["study", "run", "tiny", "--no-progress", "--root", str(root)], root / "results" / "tiny"


def test_sweep_resumes_and_reports(tiny_dataset, tmp_path, capsys, monkeypatch):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
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
    # a second experiment reuses the trained runs (no new training directory) and the evaluations it shares with
    # the first (DDPM and the bridge from the line at NFE 1): it computes only its own
    import bridgeplan.evaluate

    runs_before = sorted(p.name for p in (results / "runs").iterdir())
    calls = []
    real = bridgeplan.evaluate.evaluate_planner
    monkeypatch.setattr(bridgeplan.evaluate, "evaluate_planner", lambda *a, **k: calls.append(1) or real(*a, **k))
    args, _ = tiny_study(tmp_path, tiny_dataset, "nfe1", "nfe-curves")
    assert main(args) == 0
    assert sorted(p.name for p in (results / "runs").iterdir()) == runs_before
    assert "12 new results" in capsys.readouterr().out  # (4 + 4 NFE) x 2 snapshots, 4 of them stored already
    assert len(calls) == 12  # and not evaluated again
    store = ResultsStore(results / "results.sqlite")
    assert len(store.rows("nfe-curves")) == 16 and len(store.rows()) == 8 + 12
    shared = [r for r in store.rows() if r["experiments"] == "nfe-curves nfe1"]
    assert {(r["process"], r["prior"], r["nfe"]) for r in shared} == {("ddpm", "gaussian", 1), ("bridge", "line", 1)}

    assert main(["report", "--results", str(results)]) == 0
    report = (results / "report" / "report.md").read_text()
    assert "## nfe1" in report and "| DDPM N=6 NFE=1 | 2 |" in report
    assert (results / "report" / "nfe1.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["report", "--results", str(results), "--csv", str(tmp_path / "all.csv")]) == 0
    assert len((tmp_path / "all.csv").read_text().strip().splitlines()) == 1 + len(
        ResultsStore(results / "results.sqlite").rows())


def test_a_run_from_the_learned_prior_trains_it_inside_its_unit(tiny_dataset, tmp_path):
    """The learned prior is trained by the unit of the run that samples from it (in a worker where the units run in
    workers, the seeds' priors side by side), not before the units start: making the units trains nothing."""
    from bridgeplan.experiments.runner import grid_units
    from bridgeplan.studies.plan import sweeps
    from bridgeplan.studies.spec import read_study
    from bridgeplan.workers import Executor

    tiny_study(tmp_path, tiny_dataset, "nfe1", steps=1)
    sweep = sweeps(read_study(tmp_path / "studies" / "tiny.toml"), tmp_path)[0]
    units = grid_units([(sweep.settings, [sweep.experiment])], progress=False)
    runs = tmp_path / "results" / "tiny" / "runs"
    assert len(units) == 4 and not runs.exists()
    learned = [u for u in units if u.args[3] is not None]
    assert len(learned) == 1 and learned[0].args[1].prior == "learned"
    assert sum(Executor().map(learned, False)) == 1  # its one snapshot's row, after training its prior
    prior = runs / learned[0].args[3].run_name()
    assert json.loads((prior / "config.json").read_text())["config"]["steps"] == 2


def test_validation_sweep_scores_other_episodes_of_the_same_runs(tiny_dataset, tmp_path, capsys):
    """`--validation`: the final snapshot of each run, on tasks of another seed, under `<name>-validation`;
    the test rows and the trained runs are left as they were."""
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe-curves", seeds=(0, 1))
    assert main(args) == 0
    store = ResultsStore(results / "results.sqlite")
    test_rows = store.rows("nfe-curves")
    runs_before = sorted(p.name for p in (results / "runs").iterdir())
    args, _ = tiny_study(tmp_path, tiny_dataset, "nfe-curves", seeds=(0, 1), validation=True)
    assert main(args) == 0
    rows = store.rows("nfe-curves-validation")
    assert store.rows("nfe-curves") == test_rows
    assert sorted(p.name for p in (results / "runs").iterdir()) == runs_before
    # DDPM at NFE 1, 2, 4, 6 and the bridge at 1, 2, 4, 5; two seeds; the final snapshot only
    assert len(rows) == 2 * 8 and {r["step"] for r in rows} == {2}
    assert {(r["seed"], r["eval_seed"]) for r in rows} == {(0, 1000), (1, 1001)}
    assert {(r["seed"], r["eval_seed"]) for r in test_rows} == {(0, 0), (1, 1)}
    capsys.readouterr()
    assert main(args) == 0 and "0 new results" in capsys.readouterr().out


def test_prior_curves_has_each_prior_at_nfe_1_2_4_and_full():
    experiment = get_experiment("prior-curves", steps=6, informed=Flow())
    assert {(s.run.process.name, s.run.prior, s.nfe) for s in experiment.series} == {
        ("flow", p, k) for p in ("gaussian", "line", "learned") for k in (1, 2, 4, 6)}
    assert not experiment.last_snapshot_only


def test_samplers_sweep_keys_each_sampler_apart(tiny_dataset, tmp_path, capsys):
    """The samplers experiment evaluates each run at NFE 2, 4 and full by every sampler of its process: the store
    keys them apart by the sampler the evaluated planner used ('' as trained), a second sweep adds nothing, and
    the report names the sampler of each series."""
    args, results = tiny_study(tmp_path, tiny_dataset, "samplers")
    assert main(args) == 0
    rows = ResultsStore(results / "results.sqlite").rows("samplers")
    # per snapshot: DDPM at NFE 1, and 2, 4, 6 by ancestral and ddim; the bridge at 1, and 2, 4, 5 by posterior
    # and mean
    assert len(rows) == 2 * (1 + 3 * 2) * 2
    assert {(r["process"], r["nfe"], r["sampler"]) for r in rows} == {
        *((p, 1, "") for p in ("ddpm", "bridge")),
        *(("ddpm", k, t) for k in (2, 4, 6) for t in ("", "ddim")),
        *(("bridge", k, t) for k in (2, 4, 5) for t in ("", "mean"))}
    capsys.readouterr()
    assert main(args) == 0 and "0 new results" in capsys.readouterr().out
    assert main(["report", "--results", str(results)]) == 0
    report = (results / "report" / "report.md").read_text()
    assert "| bridge (line) N=6 NFE=2 mean | 2 |" in report and "| DDPM N=6 NFE=4 ddim | 1 |" in report
    assert "| bridge (line) N=6 NFE=2 | 2 |" in report


def test_a_series_asks_only_a_sampler_its_process_has():
    from bridgeplan.errors import BridgeplanError
    from bridgeplan.experiments.grids import Experiment, RunSpec, Series
    from bridgeplan.processes import DDPM

    bad = Experiment("x", "x", (Series("DDPM", RunSpec(DDPM(6)), 2, sampler="mean"),))
    with pytest.raises(BridgeplanError, match="asks sampler 'mean'.*ancestral, ddim"):
        bad.validate()
    flow = Experiment("x", "x", (Series("flow", RunSpec(Flow(6), "line"), 2, sampler="stochastic"),))
    with pytest.raises(BridgeplanError, match="asks sampler 'stochastic'.*euler"):  # no noise on its path
        flow.validate()


def test_controllers_experiment_pairs_tracking_with_pursuit():
    experiment = get_experiment("controllers", steps=6)
    assert experiment.last_snapshot_only
    tags = {(s.run.process.name, s.nfe, s.execution.tag(), s.multi_task) for s in experiment.series}
    for process, full in (("ddpm", 6), ("bridge", 5)):
        for multi in (False, True):
            for nfe in (1, full):
                assert {t for t in ("", "pursuit0.5", "pursuit1", "pursuit1.5")
                        if (process, nfe, t, multi) in tags} == {"", "pursuit0.5", "pursuit1", "pursuit1.5"}
    assert ("bridge", 1, "replan32-warm-pursuit1", True) in tags and ("ddpm", 1, "replan32-pursuit1", False) in tags
    assert len(experiment.series) == 2 * 2 * 9


def test_newer_schema_is_refused_untouched(tmp_path, capsys):
    db = tmp_path / "results.sqlite"
    with sqlite3.connect(db) as con:
        con.execute("CREATE TABLE results (id INTEGER)")
        con.execute(f"PRAGMA user_version={SCHEMA_VERSION + 1}")
    before = db.read_bytes()
    assert main(["report", "--results", str(tmp_path)]) == 2
    assert "newer" in capsys.readouterr().err
    assert db.read_bytes() == before


@pytest.mark.slow
@pytest.mark.parametrize("backend", [["--workers", "2"], ["--backend", "ray"]])
def test_parallel_backends_fill_the_same_store(tiny_dataset, tmp_path, backend):
    if "ray" in backend:
        pytest.importorskip("ray")
    args, results = tiny_study(tmp_path, tiny_dataset, "bridge-vs-ddpm")
    assert main(args + backend) == 0
    rows = ResultsStore(results / "results.sqlite").rows()
    assert len(rows) == 4 and {r["process"] for r in rows} == {"ddpm", "bridge"}
    assert all(r["nfe"] == 5 for r in rows)  # N - 1 with the tiny 6 diffusion steps


def test_ray_address_that_does_not_answer(tiny_dataset, tmp_path, capsys):
    pytest.importorskip("ray")
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    assert main([*args, "--backend", "ray", "--ray-address", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ray" in err[0].lower()
    assert not (results / "runs").exists()


def test_closed_loop_sweep(tiny_dataset, tmp_path, capsys):
    """The closed-loop experiment: at the final snapshot only, each run open loop (NFE 1 and full) and replanned
    every 32 steps (truncated, keep; the bridge warm), single-task and Multi2D; keyed apart in the store."""
    args, results = tiny_study(tmp_path, tiny_dataset, "closed-loop")
    assert main(args) == 0
    rows = ResultsStore(results / "results.sqlite").rows("closed-loop")
    assert len(rows) == 2 * 2 * 4 and {r["step"] for r in rows} == {2}
    assert {(r["process"], r["execution"]) for r in rows} == {
        ("ddpm", ""), ("ddpm", "replan32"), ("ddpm", "replan32-arrival-keep"),
        ("bridge", ""), ("bridge", "replan32-warm"), ("bridge", "replan32-warm-arrival-keep")}
    assert sorted({r["multi_task"] for r in rows}) == [0, 1]
    for r in rows:
        replanned = r["execution"] != ""
        assert r["calls_per_episode"] == (10 * r["nfe"] if replanned else r["nfe"])  # ceil(300 / 32) plans
        assert r["decision_ms_p50"] > 0  # a lone episode's decisions at batch 1, open loop (one) or replanned
        assert r["network_calls_per_plan"] == r["nfe"]
        assert (r["plan_dynamics_rms"] is None) == replanned  # residuals of the one plan, open loop only
    capsys.readouterr()
    assert main(args) == 0 and "0 new results" in capsys.readouterr().out
    assert main(["report", "--results", str(results)]) == 0
    report = (results / "report" / "report.md").read_text()
    assert "## closed-loop" in report and "replan32-warm-arrival-keep Multi2D | 2 |" in report
    assert (results / "report" / "closed-loop.png").read_bytes()[:4] == b"\x89PNG"


def test_a_version_1_store_is_upgraded_with_its_rows(tmp_path):
    """Version 1 had no execution / multi-task / sampler columns: its rows become open-loop, single-task rows,
    sampled as trained."""
    db = tmp_path / "results.sqlite"
    v1 = ["experiment", "run_name", "maze", "process", "prior", "diffusion_steps", "seed", "step", "nfe", "episodes",
          "eval_seed", "score_minari"]
    with sqlite3.connect(db) as con:
        con.execute(f"CREATE TABLE results (id INTEGER PRIMARY KEY, {', '.join(v1)}, "
                    "UNIQUE (experiment, run_name, step, nfe, episodes, eval_seed))")
        con.execute(f"INSERT INTO results ({', '.join(v1)}) VALUES "
                    "('nfe1', 'r', 'umaze', 'ddpm', 'gaussian', 16, 0, 1000, 1, 200, 0, 42.5)")
        con.execute("PRAGMA user_version=1")
    store = ResultsStore(db)
    (row,) = store.rows()
    assert (row["score_minari"], row["execution"], row["multi_task"], row["step"]) == (42.5, "", 0, 1000)
    assert row["sampler"] == ""  # as its process samples by default
    assert store.has(("r", 1000, 1, "", "", 0, 200, 0), "nfe1")
    with sqlite3.connect(db) as con:
        assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 6
    ResultsStore(db)  # opening it again changes nothing
    assert len(store.rows()) == 1


def test_a_version_5_store_gains_the_dataset_column(tmp_path):
    from bridgeplan.experiments.store import COLUMNS, KEY

    db = tmp_path / "results.sqlite"
    cols = {k: v for k, v in COLUMNS.items() if k != "dataset"}
    with sqlite3.connect(db) as con:
        con.execute(f"CREATE TABLE evaluations (id INTEGER PRIMARY KEY, "
                    f"{', '.join(f'{k} {v}' for k, v in cols.items())}, UNIQUE ({', '.join(KEY)}))")
        con.execute("CREATE TABLE memberships (experiment TEXT NOT NULL, evaluation INTEGER NOT NULL, "
                    "PRIMARY KEY (experiment, evaluation))")
        con.execute("INSERT INTO evaluations (run_name, maze, process, prior, diffusion_steps, seed, step, nfe, "
                    "episodes, eval_seed, score_minari) VALUES ('r', 'umaze', 'ddpm', 'gaussian', 16, 0, 1000, 1, 200, "
                    "0, 42.5)")
        con.execute("INSERT INTO memberships VALUES ('nfe1', 1)")
        con.execute("PRAGMA user_version=5")
    store = ResultsStore(db)
    (row,) = store.rows("nfe1")
    assert row["dataset"] is None and row["score_minari"] == 42.5
    store.add(dict(row, step=2000, dataset="d (umaze, 6 transitions, sha256 00)"), ["nfe1"])
    assert [r["dataset"] for r in store.rows("nfe1")] == [None, "d (umaze, 6 transitions, sha256 00)"]


def test_a_version_4_store_keeps_one_evaluation_per_key_and_its_experiments(tmp_path):
    """Version 4 keyed rows by experiment too: the same evaluation stored for two experiments becomes one
    evaluation (the first by id) with two memberships; a validation experiment's rows get the validation split."""
    from bridgeplan.experiments.store import stored_keys

    db = tmp_path / "results.sqlite"
    cols = ["experiment", "run_name", "maze", "process", "prior", "diffusion_steps", "seed", "step", "nfe",
            "episodes", "eval_seed", "score_minari", "plan_ms", "execution", "multi_task", "sampler"]
    rows = [("nfe1", "r", 1, 0, 42.5, 3.0), ("nfe-curves", "r", 1, 0, 42.5, 9.0), ("nfe-curves", "r", 2, 0, 50.0, 4.0),
            ("nfe-curves-validation", "r", 1, 1000, 44.0, 3.0)]
    with sqlite3.connect(db) as con:
        con.execute(f"CREATE TABLE results (id INTEGER PRIMARY KEY, {', '.join(cols)}, "
                    "UNIQUE (experiment, run_name, step, nfe, sampler, execution, multi_task, episodes, eval_seed))")
        for experiment, run, nfe, eval_seed, score, ms in rows:
            con.execute(f"INSERT INTO results ({', '.join(cols)}) VALUES (?, ?, 'umaze', 'ddpm', 'gaussian', 16, 0, "
                        "1000, ?, 200, ?, ?, ?, '', 0, '')", (experiment, run, nfe, eval_seed, score, ms))
        con.execute("PRAGMA user_version=4")
    keys, members = stored_keys(db)  # read as the upgrade will make it, without writing
    assert len(keys) == 3 and len(members) == 4
    store = ResultsStore(db)
    assert stored_keys(db) == (keys, members)
    by_nfe = {(r["nfe"], r["eval_seed"]): r for r in store.rows()}
    assert len(by_nfe) == 3
    assert by_nfe[1, 0]["experiments"] == "nfe-curves nfe1" and by_nfe[1, 0]["plan_ms"] == 3.0  # the first row
    assert [r["split"] for r in store.rows("nfe-curves-validation")] == ["validation"]
    assert {r["split"] for r in store.rows("nfe-curves")} == {"test"} and len(store.rows("nfe-curves")) == 2
    assert store.experiments() == ["nfe-curves", "nfe-curves-validation", "nfe1"]
