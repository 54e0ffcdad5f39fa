"""Issue 44's 22 bad inputs: each is one ``error:`` line on stderr and exit 2, before any work is done (nothing
printed on stdout, no file written or left behind), never a traceback and never accepted. Every case is the real
CLI, in this process, on the tiny dataset and runs of conftest."""

from __future__ import annotations

import os
import shutil
import sqlite3
import tempfile
from pathlib import Path

import pytest

from bridgeplan.cli import main
from bridgeplan.experiments.store import ResultsStore
from tests.test_experiments import tiny_study
from tests.test_train import train_args

OGBENCH = "pointmaze-medium-navigate-v0"


def files(directory: Path) -> dict[str, bytes | None]:
    """Every file's bytes (folders as None) under ``directory``, SQLite's side files aside."""
    return {str(p.relative_to(directory)): None if p.is_dir() else p.read_bytes()
            for p in sorted(Path(directory).rglob("*")) if not p.name.endswith(("-wal", "-shm"))}


def refused(capsys, *args, watch: Path) -> str:
    """Run the CLI on ``args``: one ``error:`` line, exit 2, nothing on stdout and nothing changed under ``watch``;
    returns the line."""
    before = files(watch)
    capsys.readouterr()
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), err
    assert out == "", out  # no work began: no table, no "wrote"
    assert files(watch) == before
    return lines[0]


@pytest.fixture
def read_only(tmp_path) -> Path:
    """A folder that takes no files: read-only for a user; for root (whom permissions do not stop), a folder of a
    file system that takes none (sysfs)."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        fd, probe = tempfile.mkstemp(dir=folder)
    except OSError:
        yield folder
        folder.chmod(0o755)
        return
    os.close(fd)
    os.unlink(probe)
    try:
        fd, probe = tempfile.mkstemp(dir="/sys")
        os.close(fd)
        os.unlink(probe)
    except OSError:
        yield Path("/sys")
        folder.chmod(0o755)
        return
    pytest.skip("no folder that refuses files here (root, and /sys takes them)")


@pytest.fixture
def a_file(tmp_path) -> Path:
    path = tmp_path / "a-file"
    path.write_text("not a folder\n")
    return path


EVAL = ["--episodes", "2", "--device", "cpu"]


# --- unwritable outputs (tracebacks before) -----------------------------------------------------------------------

def test_1_eval_out_in_a_read_only_folder(capsys, tmp_path, tiny_runs, read_only):
    line = refused(capsys, "eval", tiny_runs["ddpm"], *EVAL, "--out", read_only / "e.json", watch=tmp_path)
    assert str(read_only / "e.json") in line and "cannot write" in line


def test_2_eval_out_below_a_file(capsys, tmp_path, tiny_runs, a_file):
    line = refused(capsys, "eval", tiny_runs["ddpm"], *EVAL, "--out", a_file / "e.json", watch=tmp_path)
    assert f"{a_file} is a file, not a folder" in line


def test_3_train_run_dir_in_a_read_only_folder(capsys, tmp_path, tiny_dataset, read_only):
    line = refused(capsys, *train_args(tiny_dataset, read_only / "run", 2), watch=tmp_path)
    assert "run directory" in line and str(read_only / "run") in line


def test_4_train_run_dir_that_is_a_file(capsys, tmp_path, tiny_dataset, a_file):
    line = refused(capsys, *train_args(tiny_dataset, a_file, 2), watch=tmp_path)
    assert f"{a_file}: it is a file, not a folder" in line


def test_5_data_generate_out_in_a_read_only_folder(capsys, tmp_path, read_only):
    line = refused(capsys, "data", "generate", "--maze", "umaze", "--steps", "500", "--no-progress", "--out",
                   read_only / "d", watch=tmp_path)
    assert "cannot write" in line and str(read_only) in line


def test_6_data_generate_out_below_a_file(capsys, tmp_path, a_file):
    line = refused(capsys, "data", "generate", "--maze", "umaze", "--steps", "500", "--no-progress", "--out",
                   a_file / "d", watch=tmp_path)
    assert f"{a_file} is a file, not a folder" in line


def test_7_data_generate_ogbench_out_in_a_read_only_folder(capsys, tmp_path, read_only):
    line = refused(capsys, "data", "generate", "--maze", OGBENCH, "--episodes", "1", "--episode-steps", "10",
                   "--no-progress", "--out", read_only / "og", watch=tmp_path)
    assert "cannot write" in line and str(read_only) in line


def test_8_data_generate_ogbench_out_that_is_a_file(capsys, tmp_path, a_file):
    line = refused(capsys, "data", "generate", "--maze", OGBENCH, "--episodes", "1", "--episode-steps", "10",
                   "--no-progress", "--out", a_file, watch=tmp_path)
    assert f"{a_file}: it is a file, not a folder" in line


def test_9_study_run_into_a_results_path_that_is_a_file(capsys, tmp_path, tiny_dataset):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    results.parent.write_text("a file where results/ goes\n")
    line = refused(capsys, *args, watch=tmp_path)
    assert f"{results.parent} is a file, not a folder" in line


def test_10_study_run_into_a_read_only_results_folder(capsys, tmp_path, tiny_dataset, read_only):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    (tmp_path / "results").symlink_to(read_only)
    line = refused(capsys, *args, watch=tmp_path)
    assert "cannot write the results folder" in line


def test_11_study_export_into_a_committed_folder_that_is_a_file(capsys, tmp_path, tiny_dataset):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    ResultsStore(results / "results.sqlite").add(
        {"run_name": "r", "maze": "umaze", "process": "ddpm", "prior": "gaussian", "diffusion_steps": 6, "seed": 0,
         "step": 1, "nfe": 1, "sampler": "", "execution": "", "multi_task": 0, "episodes": 4, "eval_seed": 0},
        ["nfe1"])
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "results").write_text("a file where docs/results/ goes\n")
    line = refused(capsys, "study", "export", "tiny", "--root", tmp_path, watch=tmp_path)
    assert "docs/results is a file, not a folder" in line


def test_12_a_study_file_not_utf8_is_reported_as_itself_and_stops_no_other(capsys, tmp_path, tiny_dataset):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    (tmp_path / "studies" / "latin1.toml").write_bytes('title = "caf\xe9"\n'.encode("latin-1"))
    line = refused(capsys, "study", "run", "latin1", "--dry-run", "--root", tmp_path, watch=tmp_path)
    assert line.startswith("error: studies/latin1.toml: (encoding): not UTF-8") and "byte 12" in line
    # the other study is untouched by it: its dry run works, and listing every study names the broken one
    assert main([*args, "--dry-run"]) == 0
    assert "study tiny" in capsys.readouterr().out
    assert main(["study", "list", "--root", str(tmp_path)]) == 2
    out, err = capsys.readouterr()
    assert out.startswith("tiny\t") and err.strip().splitlines() == [line]


# --- bad inputs that were accepted ---------------------------------------------------------------------------------

def _study(root: Path, name: str, text: str) -> None:
    (root / "studies").mkdir(exist_ok=True)
    (root / "studies" / f"{name}.toml").write_text(text)


USES_TINY = '[[reports]]\ngenerator = "controllers"\n'


def test_13_a_study_that_uses_itself(capsys, tmp_path, tiny_dataset):
    tiny_study(tmp_path, tiny_dataset, "nfe1")
    _study(tmp_path, "me", 'uses = ["me"]\n')
    line = refused(capsys, "study", "run", "me", "--dry-run", "--root", tmp_path, watch=tmp_path)
    assert line == "error: studies/me.toml: uses: a study cannot read its own results: me -> me"


def test_14_studies_that_use_each_other(capsys, tmp_path, tiny_dataset):
    tiny_study(tmp_path, tiny_dataset, "nfe1")
    _study(tmp_path, "a", 'uses = ["b"]\n')
    _study(tmp_path, "b", 'uses = ["tiny", "a"]\n')
    line = refused(capsys, "study", "run", "a", "--dry-run", "--root", tmp_path, watch=tmp_path)
    assert line == "error: studies/a.toml: uses: a study cannot read its own results: a -> b -> a"
    line = refused(capsys, "study", "report", "b", "--check", "--root", tmp_path, watch=tmp_path)
    assert line == "error: studies/b.toml: uses: a study cannot read its own results: b -> a -> b"
    assert main(["study", "run", "tiny", "--dry-run", "--root", str(tmp_path)]) == 0  # the others still run


def test_15_an_empty_study_file(capsys, tmp_path):
    _study(tmp_path, "empty", "# nothing yet\n")
    line = refused(capsys, "study", "run", "empty", "--dry-run", "--root", tmp_path, watch=tmp_path)
    assert line.startswith("error: studies/empty.toml: (file): empty")


def test_16_an_infinite_lookahead(capsys, tmp_path, tiny_runs):
    line = refused(capsys, "eval", tiny_runs["ddpm"], *EVAL, "--controller", "pursuit", "--lookahead", "inf",
                   watch=tmp_path)
    assert line == "error: --lookahead must be a finite distance > 0 (in position), got inf"
    line = refused(capsys, "graph", "--maze", OGBENCH, "--controller", "pursuit", "--lookahead", "inf",
                   watch=tmp_path)
    assert "got inf" in line


def test_17_an_unknown_backend_in_a_dry_run(capsys, tmp_path, tiny_dataset):
    args, _ = tiny_study(tmp_path, tiny_dataset, "nfe1")
    line = refused(capsys, *args, "--dry-run", "--backend", "slurm", watch=tmp_path)
    assert line == "error: unknown backend 'slurm': choose from local, ray"


def test_18_an_empty_results_store(capsys, tmp_path, tiny_dataset):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    results.mkdir(parents=True)
    (results / "results.sqlite").write_bytes(b"")
    for dry in (["--dry-run"], []):
        line = refused(capsys, *args, *dry, watch=tmp_path)
        assert line.startswith(f"error: results store {results / 'results.sqlite'} is empty (0 bytes)")


def _stored(results: Path) -> Path:
    store = ResultsStore(results / "results.sqlite")
    for step in range(1, 40):  # enough rows for the table to take pages beyond its root
        store.add({"run_name": "r", "maze": "umaze", "process": "ddpm", "prior": "gaussian", "diffusion_steps": 6,
                   "seed": 0, "step": step, "nfe": 1, "sampler": "", "execution": "", "multi_task": 0,
                   "episodes": 4, "eval_seed": 0, "config": "x" * 400}, ["nfe1"])
    return store.path


def flip_page_type(data: bytearray, page_size: int) -> None:
    data[page_size] ^= 0xFF  # the second page's b-tree type byte


def zero_schema_version(data: bytearray, page_size: int) -> None:
    data[60:64] = bytes(4)  # the header's user_version: read as an old, empty store before


@pytest.mark.parametrize("damage", [flip_page_type, zero_schema_version])
def test_19_a_corrupted_results_store_in_a_dry_run(capsys, tmp_path, tiny_dataset, damage):
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    path = _stored(results)
    with sqlite3.connect(path) as db:
        (page_size,) = db.execute("PRAGMA page_size").fetchone()
    data = bytearray(path.read_bytes())
    damage(data, page_size)
    path.write_bytes(bytes(data))
    line = refused(capsys, *args, "--dry-run", watch=tmp_path)
    assert str(path) in line and ("corrupted" in line or "malformed" in line)


def test_20_resume_past_a_truncated_snapshot(capsys, tmp_path, tiny_dataset, tiny_runs):
    run = tmp_path / "run"
    shutil.copytree(tiny_runs["ddpm"], run)
    snapshot = run / "snapshots" / "step_00000002.pt"
    snapshot.write_bytes(snapshot.read_bytes()[: snapshot.stat().st_size // 2])
    line = refused(capsys, *train_args(tiny_dataset, run, 5, "--checkpoint-every", "2", "--resume"), watch=tmp_path)
    assert line.startswith(f"error: cannot read snapshot {snapshot} (truncated or corrupted?)")


def test_21_a_graph_without_joins(capsys, tmp_path, tiny_runs):
    for flags in (["--neighbours", "0"], ["--radius", "0"]):
        line = refused(capsys, "graph", "--maze", OGBENCH, *flags, watch=tmp_path)
        assert "no joins between episodes" in line
        line = refused(capsys, "graph", "--low", tiny_runs["ddpm"], *flags, watch=tmp_path)
        assert "no joins between episodes" in line


def test_22_a_missing_low_run_is_reported_first(capsys, tmp_path):
    # no --replan-every (which a low level needs) and no dataset file: the run named is what is reported
    line = refused(capsys, "graph", "--maze", OGBENCH, "--low", tmp_path / "nowhere", watch=tmp_path)
    assert f"no checkpoint or run directory {str(tmp_path / 'nowhere')!r}" in line


def test_23_a_negative_seed(capsys, tmp_path, tiny_runs, tiny_dataset):
    line = refused(capsys, "eval", tiny_runs["ddpm"], *EVAL, "--seed", "-1", watch=tmp_path)
    assert line == "error: the tasks' seed must be >= 0, got -1"
    line = refused(capsys, *train_args(tiny_dataset, tmp_path / "run", 2), "--seed", "-1", watch=tmp_path)
    assert line == "error: seed must be >= 0, got -1"
    line = refused(capsys, "gcbc", "train", tmp_path / "data.npz", "--run-dir", tmp_path / "gcbc", "--seed", "-1",
                   watch=tmp_path)
    assert line == "error: seed must be >= 0, got -1"
    line = refused(capsys, "data", "generate", "--maze", "umaze", "--steps", "100", "--seed", "-1", "--out",
                   tmp_path / "data", watch=tmp_path)
    assert line == "error: --seed must be >= 0, got -1"
