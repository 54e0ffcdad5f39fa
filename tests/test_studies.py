"""Study files, `bridgeplan study list/report/run`: parsing, the committed reports, dry runs and a tiny run."""

from __future__ import annotations

import csv
import json
import re
import shutil
from collections import Counter
from pathlib import Path

import pytest

from bridgeplan.checkpoint import load_checkpoint
from bridgeplan.cli import main
from bridgeplan.experiments.store import ResultsStore
from bridgeplan.studies import load_studies, parse_study
from bridgeplan.studies.jobs import jobs, work_units
from bridgeplan.studies.plan import QUICK_NOTE, Scale, describe_missing, missing
from bridgeplan.studies.spec import Dataset, ExperimentSpec, Study, Training
from tests.test_experiments import TINY_STUDY

REPO = Path(__file__).resolve().parents[1]


def test_committed_studies_parse_into_dataclasses():
    studies = load_studies(REPO)
    medium = studies["medium-v2-curves"]
    assert isinstance(medium, Study) and medium.file == Path("studies/medium-v2-curves.toml")
    assert medium.dataset == Dataset(maze="medium", steps=1_000_000, seed=123, version=2)
    pinned = (("batch_size", 32), ("lr", 0.001))  # cpu-small's medium default when the runs were made
    assert medium.training == Training(preset="cpu-small", steps=8000, checkpoint_every=2000, prior_steps=2000,
                                       seeds=(0, 1, 2), overrides=pinned)
    assert medium.experiments[0] == ExperimentSpec(name="nfe-curves", grid="nfe-curves", splits=("test",
                                                                                               "validation"))
    assert ExperimentSpec(name="nfe-curves", grid="nfe-curves", params=(("consistent", True),)) in medium.experiments
    assert studies["large-v2-curves"].training.all_stages() == ((8000, 2000), (16000, 2000))
    assert studies["medium-v2-hold"].training.overrides == (pinned[0], ("hold_share", 0.5), pinned[1])
    assert [(r.generator, r.output) for r in studies["findings"].reports] == [("findings", "findings.md")]


@pytest.mark.parametrize("name", ["medium-v2-curves", "large-v2-curves", "umaze-v2-hold", "large-v2-batch256",
                                  "large-v2-batch256-fp32", "large-v2-batch256-controllers"])
def test_a_campaign_study_lists_every_committed_evaluation(name):
    """With no store, the dry run lists the committed CSV's evaluations, each computed once, and every experiment
    shows exactly the evaluations the CSV says it shows: the study file encodes the campaign that made them."""
    m = missing(load_studies(REPO)[name], REPO / "no-such-dir")  # root without results: everything is missing
    with open(REPO / "docs" / "results" / name / "results.csv") as f:
        rows = list(csv.DictReader(f))
    shows: dict[str, set] = {}
    for r in rows:
        key = (r["run_name"], int(r["step"]), int(r["nfe"]), r["sampler"], r["execution"], int(r["multi_task"]),
               int(r["episodes"]), int(r["eval_seed"]))
        for experiment in r["experiments"].split():
            shows.setdefault(experiment, set()).add(key)
    assert m.wanted == shows
    assert sum(m.evaluations.values()) == len(rows)


def test_study_import_loads_the_committed_rows_so_that_nothing_is_evaluated_again(tmp_path, capsys):
    """`study import`: the committed CSV into the study's store; the dry run then lists training (the runs are not
    here) but no evaluation; importing again adds nothing."""
    root = _docs_copy(tmp_path)
    study = load_studies(root)["umaze-v2-hold"]
    assert sum(missing(study, root).evaluations.values()) == 84
    assert ("  committed: docs/results/umaze-v2-hold/results.csv holds this study's committed rows"
            in "\n".join(describe_missing(study, root)))
    assert main(["study", "import", "umaze-v2-hold", "--root", str(root)]) == 0
    assert "umaze-v2-hold: 84 evaluations in docs/results/umaze-v2-hold/results.csv, 84 new" in capsys.readouterr().out
    m = missing(study, root)
    assert sum(m.evaluations.values()) == 0 and m.wanted == {} and m.trains == ()  # nothing to train for
    assert not any(line.startswith("  committed:") for line in describe_missing(study, root))
    assert main(["study", "import", "umaze-v2-hold", "--root", str(root)]) == 0
    assert ", 0 new" in capsys.readouterr().out
    assert main(["study", "import", "headline", "--root", str(root)]) == 2  # reads others' rows, has none of its own
    assert "headline has no committed rows to import" in capsys.readouterr().err


@pytest.mark.slow
def test_study_report_check_passes_on_the_committed_tree(capsys):
    assert main(["study", "report", "--check", "--root", str(REPO)]) == 0
    # every report the study files declare, every bench page beside its JSON, the README's blocks among the checked
    declared = {line.split("=", 1)[1].strip() for path in (REPO / "studies").glob("*.toml")
                for line in path.read_text().splitlines() if line.startswith("output =")}
    benches = list((REPO / "docs" / "results").rglob("bench.json"))
    said = re.fullmatch(r"(\d+) reports, \d+ provenance files, the generated blocks in (.*) and (\d+) bench pages "
                        r"match their studies and benches\n", capsys.readouterr().out)
    assert said and (int(said[1]), int(said[3])) == (len(declared), len(benches)), said
    assert {"README.md", "docs/results/README.md"} <= set(said[2].split(", "))
    # a generator's name (as the markers and the errors say it) selects the studies whose reports it makes
    assert main(["study", "report", "cddb", "--check", "--root", str(REPO)]) == 0
    assert "1 reports" in capsys.readouterr().out


def _docs_copy(tmp_path) -> Path:
    root = tmp_path / "repo"
    shutil.copytree(REPO / "studies", root / "studies")
    shutil.copytree(REPO / "docs" / "results", root / "docs" / "results", ignore=shutil.ignore_patterns("*.png"))
    return root


@pytest.mark.parametrize("study, run", [("umaze-v2-hold", "umaze-ddpm-N16-hold0.5-H128-cpu-small-s0"),
                                        ("ogbench-planners", "ddpm-s0")])
def test_study_report_check_fails_when_a_study_no_longer_declares_how_its_rows_were_trained(tmp_path, capsys, study,
                                                                                        run):
    """A grid study's rows and a command study's JSONs against the study file: a preset default that moves under
    a study that does not pin it shows as here, a field the study now sets otherwise."""
    root = _docs_copy(tmp_path)
    path = root / "studies" / f"{study}.toml"
    path.write_text(path.read_text().replace("[training]\n", "[training]\nbatch_size = 64\n", 1))
    assert main(["study", "report", study, "--check", "--root", str(root)]) == 2
    err = capsys.readouterr().err
    assert f"error: studies/{study}.toml: run {run}: rows trained with batch_size 32 (the study now: 64)" in err


def test_study_report_check_fails_when_a_committed_number_is_edited(tmp_path, capsys):
    root = _docs_copy(tmp_path)
    findings = root / "docs" / "results" / "findings.md"
    text = findings.read_text()
    number = next(w for w in text.split() if w[0].isdigit() and "." in w)
    findings.write_text(text.replace(number, "99.9", 1))
    assert main(["study", "report", "findings", "--check", "--root", str(root)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: docs/results/findings.md differs from what findings generates "
                   "(run bridgeplan study report findings)"]
    assert findings.read_text() != text  # --check writes nothing
    assert main(["study", "report", "findings", "--root", str(root)]) == 0
    assert findings.read_text() == text
    assert main(["study", "report", "findings", "--check", "--root", str(root)]) == 0
    # a bench's page is held to its JSON, as `bridgeplan bench` wrote both
    bench = root / "docs" / "results" / "bench.md"
    text = bench.read_text()
    number = next(w for w in text.split() if w[0].isdigit() and "." in w)
    bench.write_text(text.replace(f" {number} ", " 0.1 ", 1))
    capsys.readouterr()
    assert main(["study", "report", "--check", "--root", str(root)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: docs/results/bench.md differs from what docs/results/bench.json generates (run bridgeplan study "
        "report)"]
    assert main(["study", "report", "--root", str(root)]) == 0
    assert bench.read_text() == text and "wrote docs/results/bench.md" in capsys.readouterr().out


def test_the_readme_headline_block_is_generated_and_checked(tmp_path, capsys):
    """The README's headline table sits between markers that `study report` rewrites and `--check` verifies."""
    from bridgeplan.studies.generators import markers

    root = _docs_copy(tmp_path)
    readme = root / "README.md"
    text = (REPO / "README.md").read_text()
    begin, end = markers("headline")
    block = text.split(begin, 1)[1].split(end, 1)[0]
    assert "| medium | single-task |" in block
    number = next(w for w in block.split() if w[0].isdigit() and "." in w)
    readme.write_text(text.replace(block, block.replace(number, "99.9", 1)))
    assert main(["study", "report", "--check", "--root", str(root)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: README.md differs from what headline generates (run bridgeplan study report headline)"]
    assert main(["study", "report", "headline", "--root", str(root)]) == 0
    assert readme.read_text() == text and "wrote README.md" in capsys.readouterr().out
    readme.write_text(text.replace(end, ""))  # a block that never closes: one error line, nothing written
    assert main(["study", "report", "headline", "--root", str(root)]) == 2
    assert "never closes" in capsys.readouterr().err
    assert readme.read_text() == text.replace(end, "")


def test_the_headline_reads_the_stores_its_study_uses():
    """Each maze's headline rows come from studies headline.toml declares (so `study list` and the reports'
    dependencies say where they come from), and every store read exists: a renamed folder is not skipped quietly."""
    from tests.reports import report

    headline = report("headline")

    studies = load_studies(REPO)
    used = {REPO / "docs" / "results" / studies[name].data_dir / "results.csv" for name in studies["headline"].uses}
    for maze in headline.MAZES:
        paths = headline.paths(REPO / "docs" / "results", maze)
        assert all(p.exists() for p in paths) and set(paths) <= used, maze
    assert [p.parent.name for p in headline.paths(REPO / "docs" / "results", "large")] == [
        "large-v2-batch256-controllers"]


def test_study_report_check_fails_when_a_report_is_missing(tmp_path, capsys):
    root = _docs_copy(tmp_path)
    (root / "docs" / "results" / "controllers.md").unlink()
    assert main(["study", "report", "controllers", "--check", "--root", str(root)]) == 2
    assert "docs/results/controllers.md differs" in capsys.readouterr().err


def test_study_list(capsys):
    assert main(["study", "list", "--root", str(REPO)]) == 0
    lines = {line.split("\t")[0]: line.split("\t")[1:] for line in capsys.readouterr().out.strip().splitlines()}
    assert {"findings", "prior-curves", "controllers", "medium-v2-curves", "umaze-v2-curves"} <= set(lines)
    assert lines["findings"][0] == "studies/findings.toml"
    assert lines["findings"][1].endswith("; docs/results/findings.md")  # a report that feeds no block elsewhere
    assert "docs/results/cddb.md (feeds docs/results/README.md)" in lines["cddb"][1]
    assert lines["medium-v2-hold"][1] == "docs/results/medium-v2-hold/results.csv (nfe-curves, closed-loop, candidates)"


GOOD = TINY_STUDY.replace("{steps}", "2").replace("{seeds}", "[0]") + """
[methods.ddpm]
process = "ddpm"

[[experiments]]
name = "tiny"
series = [{{ method = "ddpm", nfe = [1, 6] }}]
"""

BAD = [
    ("colour = 1\n", "colour: unknown key"),
    ("[training]\nstep = 3\n", "training.step: unknown key"),
    ("[training]\nsteps = -3\n", "training.steps: must be positive"),
    ('[dataset]\nmaze = "maze9"\n', "dataset.maze: unknown environment 'maze9'"),
    ('[dataset]\nmaze = "umaze"\ngenerator = "ogbench"\n',
     "dataset.generator: umaze is a Maze2D environment: its data is made by 'expert', not 'ogbench'"),
    ('[dataset]\nmaze = "umaze"\n[[experiments]]\ngrid = "nfe99"\n', "experiments[0].grid: unknown grid"),
    ('[dataset]\nmaze = "umaze"\n[[experiments]]\ngrid = "nfe1"\nprocess = "vae"\n',
     "experiments[0]: unknown process 'vae'"),
    ('[dataset]\nmaze = "umaze"\n[[experiments]]\ngrid = "nfe1"\nparams = { beta_mx = 0.3 }\n',
     "experiments[0].params:"),
    ('[dataset]\nmaze = "umaze"\n[[experiments]]\nname = "x"\nseries = [{ method = "ddpm", nfe = [1] }]\n',
     "experiments[0].series[0].method: unknown method 'ddpm'"),
    ('[dataset]\nmaze = "umaze"\n[methods.d]\nprocess = "ddpm"\n[[experiments]]\nname = "x"\n'
     'series = [{ method = "d", nfe = [99] }]\n', "experiments[0]: experiment x: series"),
    ('[[reports]]\ngenerator = "tables"\n', "reports[0].generator: unknown generator 'tables'"),
    ('[dataset]\nmaze = "umaze"\n[[experiments]]\ngrid = "bridge-nfe"\n[[reports]]\ngenerator = "controllers"\n',
     "reports[0].generator: controllers reads DDPM (N=16), which neither bad nor the studies it uses "
     "(none) train"),
    ('uses = ["nobody"]\n', "uses[0]: unknown study 'nobody'"),
    *[('[dataset]\nmaze = "umaze"\n[methods.d]\nprocess = "ddpm"\n[[experiments]]\nname = "x"\n'
        f'series = [{{ method = "d", nfe = [1], {series} }}]\n', message) for series, message in [
        ('correction = ["none", "dynamics=-1"]', "experiments[0].series[0].correction[1]: the step size of the "
                                                  "dynamics correction must be a finite number >= 0"),
        ('correction = ["wiggle=1e-4"]', "experiments[0].series[0].correction[0]: unknown residual 'wiggle'"),
        ('correction = ["dynamics"]', "experiments[0].series[0].correction[0]: --correction takes RESIDUAL=STEP"),
        ('correction = ["conditions=1e-4"]', "experiments[0].series[0].correction[0]: the conditions correction in "
                                             "x0 form"),
        ('correction = ["dynamics=1e-4", "dynamics=1e-4"]', "experiments[0].series[0].correction: a correction is "
                                                            "listed twice"),
        ('correction = []', "experiments[0].series[0].correction: expected"),
        ('correction = ["dynamics=1e-4"], correction_form = "dpe"', "experiments[0].series[0].correction_form: "
                                                                    "expected one of x0, deep, got 'dpe'"),
        ('correction_form = "deep"', "experiments[0].series[0].correction_form: needs correction"),
    ]],
    ("this is not toml\n", "(syntax)"),
]


@pytest.mark.parametrize("text, message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_a_bad_study_is_one_error_line_and_nothing_written(tmp_path, capsys, text, message):
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    shutil.copytree(REPO / "studies" / "reports", root / "studies" / "reports")  # the generators a report names
    (root / "studies" / "bad.toml").write_text(text)
    for command in (["list"], ["report", "--check"], ["run", "bad", "--dry-run"], ["run", "bad"]):
        assert main(["study", *command, "--root", str(root)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: studies/bad.toml: ") and message in err[0], err
    assert sorted(p.name for p in root.rglob("*") if "reports" not in p.parts) == ["bad.toml", "studies"]


def test_a_tiny_study_dry_run_then_runs_at_the_quick_scale(tiny_dataset, tmp_path, capsys):
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(GOOD.format(dataset=tiny_dataset))
    study = parse_study(root / "studies" / "tiny.toml")
    assert study.methods[0].process == "ddpm" and study.experiments[0].series[0].nfe == (1, 6)
    assert dict(study.training.overrides)["model"] == {"dim": 8, "dim_mults": (1, 2)}

    assert main(["study", "run", "tiny", "--dry-run", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert "(committed scale)" in out and "(absent)" in out
    assert "  train umaze-ddpm-N6-H32-cpu-small-s0: 2 steps (0 of 2 done)" in out
    assert "  evaluate tiny: 4 evaluations x 4 episodes" in out  # 2 snapshots x NFE 1, 6
    assert "  total: 1 runs to train, 4 evaluations" in out
    assert not (root / "results").exists()

    assert main(["study", "run", "tiny", "--quick", "--dry-run", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert QUICK_NOTE in out and "2 evaluations" in out  # quick: 1 step, one snapshot
    assert main(["study", "run", "tiny", "--quick", "--no-progress", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert "tiny: 2 new results" in out and QUICK_NOTE in out
    assert (root / "results" / "quick" / "tiny" / "results.sqlite").exists()
    assert not (root / "results" / "tiny").exists()
    assert sum(missing(study, root, Scale("quick")).evaluations.values()) == 0
    assert main(["study", "run", "tiny", "--quick", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 0 new results" in capsys.readouterr().out  # resumable: nothing left to do


def test_study_export_then_report_writes_the_committed_folder(tiny_dataset, tmp_path, capsys):
    """`study export`: the store's evaluations, a report and a figure into docs/results/NAME, then the reports
    regenerated, its provenance among them (the study file's hash, the code versions), which `--check` holds to the
    study file."""
    import json

    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    file = root / "studies" / "tiny.toml"
    file.write_text(GOOD.format(dataset=tiny_dataset))
    assert main(["study", "export", "tiny", "--root", str(root)]) == 2  # nothing run yet
    assert "no results store at" in capsys.readouterr().err and not (root / "docs").exists()
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert main(["study", "export", "tiny", "--root", str(root)]) == 0
    folder = root / "docs" / "results" / "tiny"
    out = capsys.readouterr().out
    assert "wrote docs/results/tiny/results.csv" in out and "wrote docs/results/tiny/study.json" in out
    rows = list(csv.DictReader((folder / "results.csv").open()))
    assert len(rows) == 4 and {r["experiments"] for r in rows} == {"tiny"}
    assert "## tiny" in (folder / "report.md").read_text() and (folder / "tiny.png").read_bytes()[:4] == b"\x89PNG"
    # on another machine: the committed rows imported, `study run` trains and evaluates nothing
    shutil.copytree(root / "results", tmp_path / "results-before")
    shutil.rmtree(root / "results")
    assert main(["study", "import", "tiny", "--root", str(root)]) == 0
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 0 new results" in capsys.readouterr().out and not (root / "results" / "tiny" / "runs").exists()
    shutil.rmtree(root / "results")
    shutil.copytree(tmp_path / "results-before", root / "results")
    # an evaluation JSON imported as a row of an experiment that declares it; one it does not declare is refused
    run = root / "results" / "tiny" / "runs" / "umaze-ddpm-N6-H32-cpu-small-s0"
    for nfe in (1, 2):
        assert main(["eval", str(run), "--nfe", str(nfe), "--episodes", "4", "--seed", "0", "--snapshot", "2",
                     "--device", "cpu", "--out", str(tmp_path / f"nfe{nfe}.json")]) == 0
    capsys.readouterr()
    assert main(["study", "import", "tiny", "--experiment", "tiny", "--eval-json", str(tmp_path / "nfe1.json"),
                 "--root", str(root)]) == 0
    assert "tiny: 1 evaluations in 1 evaluation JSONs, 0 new" in capsys.readouterr().out  # the same as stored
    assert main(["study", "import", "tiny", "--experiment", "tiny", "--eval-json", str(tmp_path / "nfe2.json"),
                 "--root", str(root)]) == 2
    assert "nfe2.json: not an evaluation that tiny of studies/tiny.toml declares" in capsys.readouterr().err
    assert main(["study", "import", "tiny", "--experiment", "nope", "--eval-json", str(tmp_path / "nfe1.json"),
                 "--root", str(root)]) == 2
    assert "has no experiment 'nope'" in capsys.readouterr().err
    assert main(["study", "report", "--check", "--root", str(root)]) == 0  # the export wrote the provenance
    record = json.loads((folder / "study.json").read_text())
    assert record["study"] == "studies/tiny.toml" and record["evaluations"] == 4 and record["training_seeds"] == [0]
    assert record["code_versions"] == [rows[0]["code_version"]] and record["code_versions"][0].startswith("0.1.0")
    assert main(["study", "report", "--check", "--root", str(root)]) == 0
    file.write_text(file.read_text().replace("episodes = 4", "episodes = 5"))  # the study changed, its rows not
    assert main(["study", "report", "--check", "--root", str(root)]) == 2
    assert "docs/results/tiny/study.json differs" in capsys.readouterr().err


def test_study_run_says_what_next_and_a_quick_run_shows_its_rows_beside_the_committed(tiny_dataset, tmp_path,
                                                                                      capsys):
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(GOOD.format(dataset=tiny_dataset))
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "next: `bridgeplan study export tiny` writes these rows into docs/results" in capsys.readouterr().out
    assert main(["study", "export", "tiny", "--root", str(root)]) == 0
    committed = {int(r["nfe"]): r for r in csv.DictReader((root / "docs/results/tiny/results.csv").open())
                 if r["step"] == "2"}
    capsys.readouterr()
    assert main(["study", "run", "tiny", "--quick", "--no-progress", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert "tiny at the quick scale, beside its committed rows [QUICK SCALE" in out
    assert "next: `bridgeplan report --results results/quick/tiny`" in out
    quick = {int(r["nfe"]): r for r in ResultsStore(root / "results/quick/tiny/results.sqlite").rows()}
    assert {r["step"] for r in quick.values()} == {1}  # a tenth of the steps: one snapshot
    best = max(quick, key=lambda nfe: quick[nfe]["score_minari"])  # one seed, no validation split: on test
    row = next(line for line in out.splitlines() if line.startswith("| umaze | single-task | tracked |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == f"DDPM, NFE {best}"
    assert cells[4] == f"{quick[best]['score_minari']:.1f} ({quick[best]['success_rate']:.2f}), 1 seeds"
    assert cells[5] == (f"{float(committed[best]['score_minari']):.1f} "
                        f"({float(committed[best]['success_rate']):.2f}), 1 seeds")


CORRECTED = GOOD.replace("steps = 2\ncheckpoint_every = 1", "steps = 1\ncheckpoint_every = 1").replace(
    'nfe = [1, 6] }}', 'nfe = [1], correction = ["none", "dynamics=1e-4"] }}')


def test_a_corrected_series_is_listed_apart_in_the_dry_run(tmp_path, capsys):
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(CORRECTED.format(dataset="no-such-dataset"))
    study = parse_study(root / "studies" / "tiny.toml")
    from bridgeplan.consistency import Correction
    from bridgeplan.studies.plan import build_experiment

    assert study.experiments[0].series[0].correction == (None, Correction((("dynamics", 1e-4),)))
    series = build_experiment(study, 0).series
    assert [(s.correction, s.sampling_tag()) for s in series] == [(None, ""), (Correction((("dynamics", 1e-4),)),
                                                                               "cddb-x0 dynamics=0.0001")]
    assert main(["study", "run", "tiny", "--dry-run", "--root", str(root)]) == 0
    out = capsys.readouterr().out.splitlines()
    at = out.index("  evaluate tiny: 2 evaluations x 4 episodes")
    assert out[at + 1:at + 3] == ["    uncorrected: 1 evaluations", "    cddb-x0 dynamics=0.0001: 1 evaluations"]


def test_a_tiny_corrected_sweep_stores_the_correction_and_resumes(tiny_dataset, tmp_path, capsys, monkeypatch):
    """The corrected row's sampler names the correction, and the runner's and the plan's "missing" keys are the
    row's: a corrected series added to a study whose uncorrected row is stored is missing (and then run), and a
    further run evaluates nothing (not even to find the row already stored)."""
    import bridgeplan.evaluate
    from bridgeplan.experiments.store import ResultsStore

    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    file = root / "studies" / "tiny.toml"
    file.write_text(CORRECTED.format(dataset=tiny_dataset).replace('"none", "dynamics=1e-4"', '"none"'))
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 1 new results" in capsys.readouterr().out

    file.write_text(CORRECTED.format(dataset=tiny_dataset))
    study = parse_study(file)
    assert missing(study, root).corrections == Counter({("tiny", "cddb-x0 dynamics=0.0001"): 1})
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 1 new results" in capsys.readouterr().out
    rows = ResultsStore(root / "results" / "tiny" / "results.sqlite").rows()
    assert sorted((r["nfe"], r["step"], r["sampler"]) for r in rows) == [(1, 1, ""), (1, 1, "cddb-x0 dynamics=0.0001")]
    assert sum(missing(study, root).evaluations.values()) == 0

    calls = []
    real = bridgeplan.evaluate.evaluate_planner
    monkeypatch.setattr(bridgeplan.evaluate, "evaluate_planner", lambda *a, **k: calls.append(1) or real(*a, **k))
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 0 new results" in capsys.readouterr().out and calls == []


def test_training_rate_comes_from_the_committed_throughput_bench(tmp_path):
    import json

    from bridgeplan import config as cfg
    from bridgeplan.studies.plan import THROUGHPUT_BENCH, TRAIN_STEPS_PER_SECOND, training_rate

    config = cfg.preset_config("medium", "cpu-small", batch_size=32)
    rate, source = training_rate(tmp_path, "medium", config, cpu="A")
    assert rate == TRAIN_STEPS_PER_SECOND and "assumed" in source  # no bench committed
    row = {"preset": "cpu-small", "maze": "medium", "batch": 32, "grad_accum": 1, "precision": "fp32",
           "implementation": "bridgeplan", "threads": 1, "busy_cores": 1, "windows_per_s": 1120.0}
    others = [row | {"busy_cores": 0, "windows_per_s": 9e9}, row | {"maze": "large", "windows_per_s": 9e9},
              row | {"implementation": "reference", "windows_per_s": 9e9}]
    (tmp_path / THROUGHPUT_BENCH).parent.mkdir(parents=True)
    (tmp_path / THROUGHPUT_BENCH).write_text(json.dumps({"throughput": [*others, row]}))
    rate, source = training_rate(tmp_path, "medium", config, cpu="A")
    assert rate == 1120.0 / 32 and "a core busy" in source  # 35 steps/s: two jobs of a sweep, one thread each
    assert "made on an unrecorded CPU" in source
    rate, _ = training_rate(tmp_path, "medium", cfg.replace(config, batch_size=256), cpu="A")
    assert rate == TRAIN_STEPS_PER_SECOND  # no figure at that batch
    slower = tmp_path / "docs" / "results" / "throughput-slower" / "bench.json"  # another CPU's bench
    slower.parent.mkdir(parents=True)
    slower.write_text(json.dumps({"machine": {"cpu": "B (avx2)"}, "throughput": [row | {"windows_per_s": 320.0}]}))
    rate, source = training_rate(tmp_path, "medium", config, cpu="B (avx2)")
    assert rate == 320.0 / 32 and source.startswith("docs/results/throughput-slower/bench.json, made on B (avx2)")
    assert training_rate(tmp_path, "medium", config, cpu="A")[0] == 1120.0 / 32  # not this CPU's: the default
    rate, _ = training_rate(tmp_path, "medium", cfg.replace(config, batch_size=256), cpu="B (avx2)")
    assert rate == TRAIN_STEPS_PER_SECOND  # neither bench has it
    # a bench's two-jobs figure, the other core training, before its throughput table's spinning core
    pair = {"preset": "cpu-small", "maze": "medium", "batch": 32, "precision": "fp32", "steps_per_s": 30.5}
    slower.write_text(json.dumps({"machine": {"cpu": "B (avx2)"}, "throughput": [row | {"windows_per_s": 320.0}],
                                  "side_by_side": [pair | {"other_core": "quiet", "steps_per_s": 99.0},
                                                   pair | {"maze": "large", "other_core": "training"},
                                                   pair | {"other_core": "training"}]}))
    rate, source = training_rate(tmp_path, "medium", config, cpu="B (avx2)")
    assert rate == 30.5 and source.endswith("one thread, beside a second training job")
    assert training_rate(tmp_path, "large", config, cpu="B (avx2)")[0] == 30.5
    assert training_rate(tmp_path, "umaze", config, cpu="B (avx2)")[0] == TRAIN_STEPS_PER_SECOND


def test_a_run_trained_here_sets_its_own_rate_in_the_dry_run(tmp_path):
    """A run's rate is what this study's training measured (GCBC/GCIQL's metrics, a planner's checkpoint), the run's
    own where it has begun, else its other training seeds' median; a run with none (or of another name) has no
    figure."""
    from bridgeplan.checkpoint import save_checkpoint
    from bridgeplan.studies.plan import measured_rate

    def metrics(run: str, *lines: tuple[int, float]) -> None:
        (tmp_path / run).mkdir()
        (tmp_path / run / "metrics.jsonl").write_text("".join(
            json.dumps({"step": step, "loss": 1.0, "elapsed_seconds": seconds}) + "\n" for step, seconds in lines))

    assert measured_rate(tmp_path / "gciql-s1") is None  # nothing trained here
    metrics("gciql-s0", (500, 100.0), (20000, 5000.0))
    metrics("gciql-s2", (1000, 500.0))
    metrics("gciql-big-s0", (100, 1.0))  # another run whose name begins alike: not a seed of gciql
    rate, source = measured_rate(tmp_path / "gciql-s1")
    assert rate == pytest.approx((4.0 + 2.0) / 2) and source == "measured by 2 other training seeds here"
    rate, source = measured_rate(tmp_path / "gciql-s2")  # begun: its own figure, the last line's
    assert rate == pytest.approx(2.0) and "this run's" in source
    assert measured_rate(tmp_path / "gcbc-s0") is None
    # a planner's (or prior's) run: its checkpoint's steps over its elapsed seconds
    (tmp_path / "low-bridge-s0").mkdir()
    save_checkpoint(tmp_path / "low-bridge-s0" / "checkpoint.pt",
                    {"kind": "planner", "config": {}, "step": 5000, "elapsed_seconds": 125.0})
    assert measured_rate(tmp_path / "low-bridge-s1") == (40.0, "measured by 1 other training seed here")
    (tmp_path / "low-bridge-s2").mkdir()
    (tmp_path / "low-bridge-s2" / "checkpoint.pt").write_bytes(b"not a checkpoint")  # unreadable: no figure
    assert measured_rate(tmp_path / "low-bridge-s2") == (40.0, "measured by 1 other training seed here")


@pytest.mark.parametrize("name, folders", [("large-hierarchy", ["large-hierarchy/*", "large-hierarchy-flat/*"]),
                                           ("ogbench-planners", ["ogbench-medium-navigate/*"]),
                                           # ogbench-large-navigate's folder holds two studies' runs
                                           ("ogbench-large-navigate", ["ogbench-large-navigate/[!h]*"]),
                                           ("ogbench-large-hierarchy", ["ogbench-large-navigate/hierarchy-*"]),
                                           *((f"ogbench-{d}", [f"ogbench-{d}/*"])
                                             for d in ("medium-stitch", "large-stitch", "giant-navigate",
                                                       "giant-stitch")),
                                           ("ogbench-calibration", ["ogbench-gcbc", "ogbench-oracle"]),
                                           ("large-stitch-hierarchy", ["large-stitch-hierarchy/*",
                                                                       "large-stitch-hierarchy-flat/*"]),
                                           *((f"ogbench-calibration-{d}", [f"ogbench-gcbc-{d}"])
                                             for d in ("large-navigate", "giant-navigate", "medium-stitch",
                                                       "large-stitch", "giant-stitch"))])
def test_a_command_study_declares_exactly_its_committed_jsons(name, folders, tmp_path, capsys, monkeypatch):
    """The study file encodes the campaign: the JSONs its evaluations write are the committed ones, none more; with
    them imported, the dry run trains and evaluates nothing."""

    study = load_studies(REPO)[name]
    declared = {j.path for j in jobs(study, REPO / "no-such-dir", REPO / "docs" / "results", quick=False)}
    committed = {p for folder in folders for p in (REPO / "docs" / "results").glob(f"{folder}/*.json")}
    assert declared == committed and len(declared) >= 3
    root = _docs_copy(tmp_path)
    assert len(missing(study, root).jsons) == len(declared)  # a fresh checkout: everything to compute
    note = f"{len(declared)} of the {len(declared)} evaluation JSONs to make are committed in docs/results"
    assert any(note in line for line in describe_missing(study, root))  # the dry run says so, and how to reuse them
    monkeypatch.setattr("bridgeplan.studies.plan.ensure_dataset", lambda *a, **k: None)  # the run: its note, not
    monkeypatch.setattr("bridgeplan.studies.plan.evaluation_units", lambda *a, **k: [])  # its work
    assert main(["study", "run", name, "--root", str(root)]) == 0
    assert f"note: {name}: {note}" in capsys.readouterr().err
    assert main(["study", "import", name, "--root", str(root)]) == 0
    assert f"{name}: {len(declared)} evaluation JSONs copied into" in capsys.readouterr().out
    m = missing(study, root)
    assert m.jsons == () and m.trains == ()
    assert not any(line.startswith("  committed:") for line in describe_missing(study, root))


TINY_HIERARCHY = """
[dataset]
maze = "umaze"
path = "{dataset}"

[training]
steps = 2
checkpoint_every = 2
seeds = [0]
diffusion_steps = 4
batch_size = 4
device = "cpu"
model = {{ dim = 8, dim_mults = [1, 2] }}

[evaluation]
episodes = 3

[runs.high]
process = "ddpm"
horizon = 8
stride = 12

[runs.low]
process = "flow"
prior = "coarse"
horizon = 16
stride = 4
subgoal_every = 3

[[evaluations]]
command = "hierarchy eval"
runs = ["high", "low"]
args = {{ nfe_high = 2, nfe_low = 1, lookahead = 1.5 }}
out = "tiny-hierarchy/nfe2/{{tasks}}-seed{{eval_seed}}.json"
splits = ["test", "validation"]

[[evaluations]]
command = "eval"
runs = ["high"]
args = {{ nfe = 2, replan_every = 24, controller = "pursuit" }}
out = "tiny-hierarchy-flat/{{tasks}}-seed{{eval_seed}}.json"
task_sets = ["single", "multi"]

[[evaluations]]
command = "graph"
runs = ["low"]
args = {{ nfe_low = 1, keep = 20 }}
out = "tiny-hierarchy/graph/{{tasks}}-seed{{eval_seed}}.json"
"""


@pytest.mark.slow
def test_a_tiny_command_study_trains_its_runs_then_writes_its_jsons_once(tiny_dataset, tmp_path, capsys,
                                                                        monkeypatch):
    import json

    import bridgeplan.studies.jobs
    import bridgeplan.studies.plan

    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(TINY_HIERARCHY.format(dataset=tiny_dataset))
    assert main(["study", "run", "tiny", "--dry-run", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert "  train high-s0: 2 steps (0 of 2 done)" in out and "  train low-s0: 2 steps (0 of 2 done)" in out
    assert "  hierarchy eval: 2 evaluation JSONs" in out and "  eval: 2 evaluation JSONs" in out
    assert "  graph: 1 evaluation JSONs" in out
    # Units (seed, runs read): the hierarchy's (high, low), the flat eval's (high), the graph's (low); two workers
    # share the runs, each trained once under its lock.
    assert [(seed, [j.runs for j in unit]) for seed, unit in work_units(jobs(load_studies(root)["tiny"], root, root,
                                                                             quick=False))] == [
        (0, [("high", "low")] * 2), (0, [("high",)] * 2), (0, [("low",)])]
    assert main(["study", "run", "tiny", "--no-progress", "--workers", "2", "--root", str(root)]) == 0
    assert "tiny: 5 new results" in capsys.readouterr().out
    results = root / "results" / "tiny"
    test, validation = (json.loads((results / "tiny-hierarchy" / "nfe2" / f"single-seed{s}.json").read_text())
                        for s in (0, 1000))
    assert (test["seed"], validation["seed"], test["episodes"]) == (0, 1000, 3)
    assert (test["high"]["run"], test["low"]["run"], test["high"]["nfe"], test["low"]["nfe"]) == ("high-s0", "low-s0",
                                                                                                   2, 1)
    graph = json.loads((results / "tiny-hierarchy" / "graph" / "single-seed0.json").read_text())
    assert graph["high"]["graph"]["keep"] == 20 and graph["low"]["run"] == "low-s0" and graph["episodes"] == 3
    multi = json.loads((results / "tiny-hierarchy-flat" / "multi-seed0.json").read_text())
    assert multi["multi_task"] and multi["execution"]["replan_every"] == 24 and multi["nfe"] == 2
    assert (root / "results" / "tiny" / "runs" / "low-s0" / "checkpoint.pt").exists()
    calls, datasets = [], []
    real = bridgeplan.studies.jobs.run_job
    monkeypatch.setattr(bridgeplan.studies.jobs, "run_job", lambda *a: calls.append(a) or real(*a))
    real_dataset = bridgeplan.studies.plan.ensure_dataset
    monkeypatch.setattr(bridgeplan.studies.plan, "ensure_dataset", lambda *a, **k: datasets.append(a) or
                        real_dataset(*a, **k))
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    out = capsys.readouterr().out
    assert "tiny: 0 new results" in out and calls == [] and datasets == []  # nothing run again, no dataset made
    (results / "tiny-hierarchy-flat" / "single-seed0.json").unlink()
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 1 new results" in capsys.readouterr().out and len(calls) == 1  # only what is missing
    assert main(["study", "export", "tiny", "--root", str(root)]) == 0  # the JSONs where the reports read them
    for path in ("tiny-hierarchy/nfe2/single-seed0.json", "tiny-hierarchy/nfe2/single-seed1000.json",
                 "tiny-hierarchy-flat/single-seed0.json", "tiny-hierarchy-flat/multi-seed0.json"):
        assert (root / "docs" / "results" / path).read_text() == (results / path).read_text()


def test_the_dry_run_times_a_json_by_the_committed_ones_of_its_command(tmp_path):
    """An evaluation JSON to make is estimated at the median seconds its command's committed JSONs record (OGBench's
    ``protocol_seconds``), not at the assumed seconds per episode; a command whose JSONs record none keeps those."""
    from bridgeplan.studies.plan import EVAL_SECONDS_PER_EPISODE, measured_json_seconds

    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(TINY_HIERARCHY.format(dataset="d"))
    study = load_studies(root)["tiny"]
    docs = root / "docs" / "results"
    assert measured_json_seconds(study, root) == {}
    for name, seconds in (("single", 10.0), ("multi", 40.0)):
        (docs / "tiny-hierarchy-flat").mkdir(parents=True, exist_ok=True)
        (docs / "tiny-hierarchy-flat" / f"{name}-seed0.json").write_text(json.dumps({"protocol_seconds": seconds}))
    (docs / "tiny-hierarchy" / "nfe2").mkdir(parents=True)
    (docs / "tiny-hierarchy" / "nfe2" / "single-seed0.json").write_text(json.dumps({"episodes": 3}))  # no seconds
    (docs / "unrelated.json").write_text(json.dumps({"protocol_seconds": 1e6}))  # not this study's
    assert measured_json_seconds(study, root) == {"eval": 25.0}
    m = missing(study, root)
    assert sorted(j.command for j in m.jsons) == ["eval", "eval", "graph", "hierarchy eval", "hierarchy eval"]
    assert m.eval_seconds(measured_json_seconds(study, root)) == pytest.approx(
        2 * 25.0 + 3 * m.episodes * EVAL_SECONDS_PER_EPISODE)
    assert any(line.startswith("  eval: 2 evaluation JSONs") and line.endswith(", 0.4 min each (the committed "
                                                                                "ones' median)")
               for line in describe_missing(study, root))


@pytest.mark.parametrize("evaluation, message", [
    ('command = "render"\nruns = ["high"]\nout = "x.json"', "evaluations[0].command: unknown command 'render'"),
    ('command = "eval"\nruns = ["nope"]\nout = "x.json"', "evaluations[0].runs: unknown run 'nope'"),
    ('command = "hierarchy eval"\nruns = ["high"]\nout = "x.json"', "evaluations[0].runs: hierarchy eval takes 2"),
    ('command = "eval"\nruns = ["high"]\nout = "x.json"\nargs = { nfee = 2 }',
     "evaluations[0].args: unrecognized option 'nfee' (valid: arrival, candidates, compile, controller,"),
    # an NFE the run's process cannot take (diffusion_steps = 4): refused before anything is trained
    ('command = "eval"\nruns = ["high"]\nout = "x.json"\nargs = { nfe = 5 }',
     "evaluations[0].args.nfe: high: nfe must be in 1..4 for DDPM with 4 steps, got 5"),
    ('command = "hierarchy eval"\nruns = ["high", "low"]\nout = "x.json"\nargs = { nfe_high = 4, nfe_low = 0 }',
     "evaluations[0].args.nfe_low: low: nfe must be"),
    ('command = "hierarchy eval"\nruns = ["high", "low"]\nout = "x.json"\nargs = { nfe_high = 9 }',
     "evaluations[0].args.nfe_high: high: nfe must be in 1..4"),
    ('command = "graph"\nruns = ["low"]\nout = "x.json"\nargs = { nfe_low = 5 }',
     "evaluations[0].args.nfe_low: low: nfe must be"),
    ('command = "eval"\nruns = ["high"]\nout = "x.json"\nargs = { seed = 2 }', "evaluations[0].args.seed: set by"),
    ('command = "eval"\nruns = ["high"]\nout = "{step}.json"', "evaluations[0].out: names only"),
    ('command = "graph"\nruns = []\nout = "x.json"\nargs = { keep = 0.5 }', "evaluations[0].args: "),
    ('command = "graph"\nruns = ["high", "low"]\nout = "x.json"', "graph takes 0 or 1 run"),
    ('command = "oracle"\nruns = []\nout = "x.json"\nargs = { maze = "umaze" }\ntask_sets = ["multi", "triple"]',
     "evaluations[0].task_sets: expected a list of single, multi"),
    ('command = "eval"\nruns = ["high"]\nout = "x.json"\nsplits = ["test", "validation"]',
     "evaluations[0].out: x.json is written twice (by evaluations[0] and [0]"),
    ('command = "eval"\nruns = ["high"]\nout = "x.json"\n[[evaluations]]\ncommand = "eval"\nruns = ["low"]\n'
     'out = "x.json"', "evaluations[1].out: x.json is written twice (by evaluations[0] and [1]"),
])
def test_a_bad_command_evaluation_is_one_error_line(tmp_path, capsys, evaluation, message):
    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    text = TINY_HIERARCHY.format(dataset="d").split("[[evaluations]]")[0] + "[[evaluations]]\n" + evaluation + "\n"
    (root / "studies" / "bad.toml").write_text(text)
    assert main(["study", "run", "bad", "--dry-run", "--root", str(root)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: studies/bad.toml: ") and message in err[0], err


OGBENCH_SPLITS = """
[dataset]
generator = "ogbench"
maze = "pointmaze-medium-navigate-v0"
path = "d.npz"
{evaluation}
[runs.flow]
process = "flow"
horizon = 10
stride = 4

[[evaluations]]
command = "{command}"
runs = ["flow"]
args = {{ {args} }}
out = "x/{{eval_seed}}.json"
task_seed = 0
splits = ["test", "validation"]
"""


@pytest.mark.parametrize("evaluation, tasks", [("", "6,7,8,9,10"),
                                               ('[evaluation]\nvalidation = "test-tasks-reseeded"\n', None)])
def test_an_ogbench_validation_split_runs_the_validation_tasks_unless_pinned(tmp_path, evaluation, tasks):
    path = tmp_path / "s.toml"
    path.write_text(OGBENCH_SPLITS.format(evaluation=evaluation, command="eval", args="nfe = 1"))
    test, validation = (job.options() for job in jobs(parse_study(path), tmp_path / "results", tmp_path / "out",
                                                      quick=False))
    assert test.tasks.tasks is None and test.tasks.seed == 0 and validation.tasks.seed == 1000
    assert validation.tasks.tasks == tasks  # None: the earlier draw, the test tasks with other noise


def test_the_committed_ogbench_studies_pin_the_validation_draw_their_rows_were_made_with():
    """Studies whose validation rows are committed (their folders under docs/results) and were made before the
    validation tasks existed (no row on them) keep the earlier draw; a study without rows yet, or whose rows are on
    the validation tasks, takes the tasks."""
    studies = load_studies(REPO)

    def on_validation_tasks(folder: Path) -> bool:
        return any(int(t) > 5 for f in folder.rglob("*.json") for t in json.loads(f.read_text()).get("tasks", {}))

    committed = {s.name: [REPO / "docs" / "results" / e.out.split("/")[0] for e in s.evaluations
                          if "validation" in e.splits and (REPO / "docs" / "results" / e.out.split("/")[0]).is_dir()]
                 for s in studies.values() if s.dataset and s.dataset.family.validation_tasks}
    pinned = [name for name, folders in committed.items() if folders and not any(map(on_validation_tasks, folders))]
    assert len(pinned) == 7
    assert all(studies[name].evaluation.validation == "test-tasks-reseeded" for name in pinned)
    assert studies["manip-cube-single"].evaluation.validation == "other-tasks" and committed["manip-cube-single"]


def test_a_policys_evaluation_refuses_a_plans_option_when_the_study_is_read(tmp_path, capsys):
    """``eval`` of a GCBC/GCIQL run with a plan's option (an NFE, a controller) is refused as the file is read, not
    after its policy has trained."""
    (tmp_path / "studies").mkdir()
    text = OGBENCH_SPLITS.format(evaluation="", command="eval", args='nfe = 4, controller = "pursuit"')
    (tmp_path / "studies" / "g.toml").write_text(text.replace('process = "flow"', 'trainer = "gcbc"\nmaze = "medium"')
                                                 .replace("horizon = 10\nstride = 4\n", ""))
    assert main(["study", "run", "g", "--dry-run", "--root", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip() == ("error: studies/g.toml: evaluations[0].args.controller: run 'flow' is a "
                                               "GCBC/GCIQL policy: a plan's option does not apply")


TINY_CALIBRATION = """
[dataset]
generator = "ogbench"
maze = "pointmaze-medium-navigate-v0"
path = "{dataset}"

[training]
steps = 4
checkpoint_every = 4
prior_steps = 3
seeds = [0]
model = {{ dim = 8, dim_mults = [1, 2] }}  # the planners' (GCBC's own fields are its run's)
device = "cpu"

[runs.gcbc]
trainer = "gcbc"
maze = "medium"
batch_size = 8
hidden_dims = [8, 8]
log_every = 2
device = "cpu"

[[evaluations]]
command = "eval"
runs = ["gcbc"]
args = {{ snapshot = 4, episodes = 1 }}
out = "cal/gcbc-step4.json"
task_seed = 0

[[evaluations]]
command = "oracle"
runs = []
args = {{ maze = "pointmaze-medium-navigate-v0", episodes = 1, tasks = "1" }}
out = "cal/oracle-medium.json"
task_seed = 0

[[evaluations]]
command = "graph"
runs = []
args = {{ episodes = 1, tasks = "1", controller = "pursuit", keep = 5 }}
out = "cal/graph.json"
task_seed = 0

[runs.low]
process = "flow"
prior = "coarse"
horizon = 10
stride = 4
subgoal_every = 3

[[evaluations]]
command = "graph"
runs = ["low"]
args = {{ episodes = 1, tasks = "1", controller = "pursuit", keep = 5, replan_every = 12, nfe_low = 1 }}
out = "cal/graph-low.json"
task_seed = 0

[runs.flow-learned]
process = "flow"
prior = "learned"
horizon = 10
stride = 4

[[evaluations]]
command = "eval"
runs = ["flow-learned"]
args = {{ episodes = 1, tasks = "1", nfe = 1, no_floor = true }}
out = "cal/flow-learned.json"
task_seed = 0
"""


def test_a_tiny_calibration_study_trains_gcbc_and_writes_the_protocol_jsons(tmp_path, capsys):
    """GCBC runs (trainer = "gcbc"), the oracle (no run, the maze a positional argument) and the dataset graph (no
    run, the study's dataset given by the runner; then with a low level, given as --low) in a command study."""
    import json

    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    assert main(["data", "generate", "--maze", "pointmaze-medium-navigate-v0", "--episodes", "4",
                 "--episode-steps", "40", "--out", str(tmp_path), "--no-progress"]) == 0
    (root / "studies" / "cal.toml").write_text(
        TINY_CALIBRATION.format(dataset=tmp_path / "pointmaze-medium-navigate-v0.npz"))
    capsys.readouterr()
    assert main(["study", "run", "cal", "--dry-run", "--root", str(root)]) == 0
    prior = "pointmaze-medium-navigate-v0-prior-learned-H10k4-s0"
    said = capsys.readouterr().out
    assert f"  train {prior}: 3 steps (0 of 3 done)" in said  # the learned run's prior
    # GCBC's rate is not the planners' bench figure: not estimated until one of its seeds trains here
    assert "  train gcbc-s0: 4 steps (0 of 4 done), not estimated (a GCBC/GCIQL run" in said
    assert "(the 1 GCBC/GCIQL run not estimated)" in said
    assert main(["study", "run", "cal", "--no-progress", "--root", str(root)]) == 0
    out = capsys.readouterr()
    assert "cal: 5 new results" in out.out and "episode/s" not in out.err  # --no-progress reaches the commands
    learned = json.loads((root / "results" / "cal" / "cal" / "flow-learned.json").read_text())
    assert learned["config"]["prior"] == "learned" and learned["config"]["prior_run"] == prior  # by name, no path
    assert load_checkpoint(root / "results" / "cal" / "runs" / prior / "checkpoint.pt")["step"] == 3
    gcbc = json.loads((root / "results" / "cal" / "cal" / "gcbc-step4.json").read_text())
    assert (gcbc["run"], gcbc["step"], gcbc["train_seed"], gcbc["episodes_per_task"]) == ("gcbc-s0", 4, 0, 1)
    (oracle,) = json.loads((root / "results" / "cal" / "cal" / "oracle-medium.json").read_text())["rows"]
    assert oracle["policy"] == "oracle" and oracle["maze"] == "medium" and oracle["episodes"] == 1
    graph = json.loads((root / "results" / "cal" / "cal" / "graph.json").read_text())
    assert graph["kind"] == "graph" and graph["config"]["dataset"] == "pointmaze-medium-navigate-v0"
    assert graph["episodes"] == 1
    assert graph["graph"]["keep"] == 5 and graph["config"]["dataset_identity"].startswith("pointmaze-medium-navigate")
    low = json.loads((root / "results" / "cal" / "cal" / "graph-low.json").read_text())
    assert low["run"].endswith("low-s0") and low["low"]["subgoal_every"] == 3 and low["nfe"] == 1
    assert main(["study", "run", "cal", "--no-progress", "--root", str(root)]) == 0
    assert "cal: 0 new results" in capsys.readouterr().out


def test_every_committed_evaluation_reads_the_same_through_the_cli():
    """A study's evaluation fills the options dataclass its command's flags fill: each committed job, written as the
    command line a user would type, parses into the options the runner calls the command with."""
    from bridgeplan.cli import build_parser
    from bridgeplan.eval_commands import STUDY_COMMANDS
    from bridgeplan.options import leaves, options_from_args

    parser = build_parser()
    checked = Counter()
    for study in load_studies(REPO).values():
        for job in jobs(study, Path("results"), Path("out"), quick=False):
            spec = STUDY_COMMANDS[job.command]
            given = dict(job.args) | dict(zip(spec.runs, job.run_dirs)) | {"dataset": "data.npz"}
            positional, flags = [], []
            for leaf in leaves(spec.options):
                value = given.get(leaf.name)
                if leaf.positional:
                    positional += [str(v) for v in (value if isinstance(value, list) else [value])]
                elif value is True:
                    flags.append(leaf.flag)
                elif value not in (None, False):
                    flags += [leaf.flag, str(value)]
            options = options_from_args(spec.options, parser.parse_args([*job.command.split(), *positional, *flags]))
            assert options == job.options(Path("data.npz"), progress=True), (study.name, job.path)
            checked[job.command] += 1
    assert set(checked) == set(STUDY_COMMANDS) and sum(checked.values()) > 500, checked


def test_a_run_that_two_experiments_and_both_splits_show_is_one_unit_trained_in_the_stages(tiny_dataset, tmp_path,
                                                                                          capsys):
    """One unit of work per trained run: two experiments (one in both splits) that show the same DDPM run make one
    unit, which trains it in [training]'s stages (a first pass of 2 steps snapshotted at each, then on to 4 every 2,
    as the committed runs were) and then evaluates it for every experiment and split."""
    from bridgeplan.experiments.runner import grid_units
    from bridgeplan.paths import snapshot_steps
    from bridgeplan.studies.plan import sweeps

    root = tmp_path / "repo"
    (root / "studies").mkdir(parents=True)
    (root / "studies" / "tiny.toml").write_text(
        TINY_STUDY.replace("{steps}", "4").replace("{seeds}", "[0]").replace(
            "checkpoint_every = 1", "checkpoint_every = 2\nstages = [[2, 1]]").format(dataset=tiny_dataset) + """
[methods.ddpm]
process = "ddpm"

[[experiments]]
name = "a"
series = [{ method = "ddpm", nfe = [1] }]
splits = ["test", "validation"]

[[experiments]]
name = "b"
series = [{ method = "ddpm", nfe = [6] }]
last_snapshot_only = true
""")
    study = parse_study(root / "studies" / "tiny.toml")
    plan = sweeps(study, root)
    (unit,) = grid_units([(sweep.settings, [sweep.experiment]) for sweep in plan], plan[0].stages[:-1], False)
    work, _, seed, _, stages = unit.args
    assert len(work) == 3 and seed == 0 and stages == ((2, 1),)
    assert main(["study", "run", "tiny", "--no-progress", "--root", str(root)]) == 0
    assert "tiny: 5 new results" in capsys.readouterr().out
    run = root / "results" / "tiny" / "runs" / "umaze-ddpm-N6-H32-cpu-small-s0"
    assert snapshot_steps(run) == [1, 2, 4]  # every step of the first pass, then every 2
    rows = ResultsStore(root / "results" / "tiny" / "results.sqlite").rows()
    shown = sorted((r["split"], r["nfe"], r["step"]) for r in rows)
    # a: every snapshot on the test episodes, the last on the validation ones; b: the last snapshot
    assert shown == [("test", 1, 1), ("test", 1, 2), ("test", 1, 4), ("test", 6, 4), ("validation", 1, 4)]
