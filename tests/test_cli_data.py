"""The `bridgeplan data` and `bridgeplan reference` commands, and their one-line errors."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from bridgeplan.cli import main
from bridgeplan.envs.maze2d.datasets import CACHE_NAME
from bridgeplan.envs.maze2d.generate import DATA_VERSION
from bridgeplan.envs.maze2d.minari_io import METADATA_FILE, VERSION_KEY


def _error(capsys, argv) -> str:
    """Run ``main(argv)``, expect exit code 2 and exactly one ``error:`` line on stderr."""
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


def test_generate_info_force(tmp_path, capsys):
    out = tmp_path / "u"
    assert main(["data", "generate", "--maze", "umaze", "--steps", "1500", "--seed", "3", "--out", str(out),
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "transitions: 1500" in printed and f"wrote {out}" in printed
    assert main(["data", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["maze"] == "umaze" and info["transitions"] == 1500 and info["segments"] == 1
    assert info["data_version"] == DATA_VERSION and 0.2 < info["actions_at_bounds"] < 0.5
    before = sorted(p.name for p in out.rglob("*"))
    line = _error(capsys, ["data", "generate", "--maze", "umaze", "--steps", "10", "--out", str(out),
                           "--no-progress"])
    assert "already exists; pass --force" in line
    assert sorted(p.name for p in out.rglob("*")) == before
    assert main(["data", "generate", "--maze", "umaze", "--steps", "700", "--out", str(out), "--force",
                 "--no-progress", "--workers", "2"]) == 0
    assert "transitions: 700" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["u"]


def test_default_location(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("BRIDGEPLAN_DATASETS", raising=False)
    assert main(["data", "generate", "--maze", "open", "--steps", "300", "--no-progress"]) == 0
    assert (tmp_path / "datasets" / "open-300" / "data" / "main_data.hdf5").exists()
    monkeypatch.setenv("BRIDGEPLAN_DATASETS", str(tmp_path / "elsewhere"))
    assert main(["data", "generate", "--maze", "open", "--steps", "300", "--no-progress"]) == 0
    assert (tmp_path / "elsewhere" / "open-300").is_dir()


@pytest.mark.parametrize("maze, under", [("umaze", "umaze-1000-v2"),
                                         ("pointmaze-medium-navigate-v0", "ogbench/pointmaze-medium-navigate-v0.npz"),
                                         ("cube-single-play-v0", "ogbench/cube-single-play-v0.npz")])
def test_a_studys_dataset_lies_where_datasets_are_put(tmp_path, monkeypatch, maze, under):
    """A study's default dataset is where ``data generate`` puts one: ``datasets/`` under the repository root, or
    under ``$BRIDGEPLAN_DATASETS`` where set (a dataset made once, found by every checkout)."""
    from bridgeplan.studies.spec import Dataset

    monkeypatch.delenv("BRIDGEPLAN_DATASETS", raising=False)
    assert Dataset(maze=maze, steps=1000).directory() == f"datasets/{under}"
    monkeypatch.setenv("BRIDGEPLAN_DATASETS", str(tmp_path / "shared"))
    assert Dataset(maze=maze, steps=1000).directory() == str(tmp_path / "shared" / under)


@pytest.mark.parametrize("argv, message", [
    (["--maze", "maze9"], "unknown environment 'maze9': Maze2D: open, umaze, medium, large; OGBench pointmaze: "
                          "pointmaze-{medium,large,giant,teleport}-{navigate,stitch}-v0; OGBench manipulation: "
                          "{cube-single,cube-double,scene,puzzle-3x3,puzzle-4x4}-play-v0; user-declared: the path "
                          "of a spec file NAME.toml (docs/usage.md: your own environment)"),
    (["--maze", "umaze", "--steps", "0"], "--steps must be positive, got 0"),
    (["--maze", "umaze", "--steps", "-5"], "--steps must be positive, got -5"),
    (["--maze", "umaze", "--workers", "0"], "--workers must be positive, got 0"),
])
def test_generate_rejects_bad_input(tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    line = _error(capsys, ["data", "generate", "--no-progress", "--out", str(tmp_path / "ds"), *argv])
    assert line == f"error: {message}"
    assert list(tmp_path.iterdir()) == []


def test_info_rejects_bad_files(tmp_path, capsys, tiny_dataset):
    assert "no dataset at" in _error(capsys, ["data", "info", str(tmp_path / "missing")])
    assert "not a Minari dataset" in _error(capsys, ["data", "info", str(tmp_path)])
    foreign = tmp_path / "maze2d-umaze-v1.hdf5"
    foreign.write_bytes(b"\x89PNG not a dataset")
    assert "not an hdf5 file" in _error(capsys, ["data", "info", str(foreign)])
    # a truncated Minari dataset (copied without its cache)
    broken = tmp_path / "broken"
    shutil.copytree(tiny_dataset, broken)
    (broken / CACHE_NAME).unlink()
    data = broken / "data" / "main_data.hdf5"
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    assert "truncated" in _error(capsys, ["data", "info", str(broken)])
    assert not (broken / CACHE_NAME).exists()
    (broken / "data" / "metadata.json").unlink()
    assert "not a Minari dataset" in _error(capsys, ["data", "info", str(broken)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken", "maze2d-umaze-v1.hdf5"]


def test_reference_commands(capsys):
    assert main(["reference", "show"]) == 0
    shown = capsys.readouterr().out
    for name in ("open", "umaze", "medium", "large", "minari", "d4rl"):
        assert name in shown
    assert main(["reference", "measure", "--maze", "umaze", "--episodes", "4"]) == 0
    assert "umaze" in capsys.readouterr().out
    line = _error(capsys, ["reference", "measure", "--episodes", "0"])
    assert line == "error: --episodes must be positive, got 0"
    assert "unknown maze" in _error(capsys, ["reference", "measure", "--maze", "x"])



def test_output_into_a_closed_pipe_ends_quietly():
    """`bridgeplan reference show | head -0`: the reader gone, the command stops with no traceback (exit 141)."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-m", "bridgeplan.cli", "reference", "show"], stdout=write,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert done.returncode == 141
    assert done.stderr == ""

def test_info_on_an_old_dataset(tiny_dataset, tmp_path, capsys):
    """A dataset of the generator before data versions: info works, with one warning line on stderr."""
    old = tmp_path / "old"
    shutil.copytree(tiny_dataset, old)
    (old / CACHE_NAME).unlink()
    meta = json.loads((old / METADATA_FILE).read_text())
    del meta[VERSION_KEY]
    (old / METADATA_FILE).write_text(json.dumps(meta))
    capsys.readouterr()
    assert main(["data", "info", str(old), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["data_version"] == 1
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"warning: {old} was made by an older bridgeplan data")
    assert main(["data", "info", str(old)]) == 0
    captured = capsys.readouterr()
    assert "data_version: 1" in captured.out and "actions_at_bounds:" in captured.out
    assert len(captured.err.strip().splitlines()) == 1
