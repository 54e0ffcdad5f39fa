"""Runs that survive being killed: SIGKILL during training and during a sweep, two sweeps on one
store, and damaged files. Every command is the real CLI in a subprocess, with tiny settings."""

from __future__ import annotations

import importlib.util
import json
import os
import random
import re
import shutil
import signal
import sqlite3
import struct
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

import bridgeplan
from bridgeplan.config import PriorTrainConfig
from bridgeplan.envs.maze2d.datasets import CACHE_NAME, read_cache
from bridgeplan.envs.maze2d.info import summarize
from bridgeplan.experiments.store import KEY
from bridgeplan.locks import run_lock
from tests.test_experiments import tiny_study
from tests.test_train import train_args

ENV = {**os.environ, "PYTHONPATH": str(Path(bridgeplan.__file__).resolve().parents[1]),
       "OMP_NUM_THREADS": "1", "MUJOCO_GL": "egl"}
TIMEOUT = 120.0

TRAIN_STEPS = 40  # checkpoint (and snapshot) every step, so writes take much of the time
SWEEP_STEPS = 4  # snapshots 1..4
SWEEP_ROWS = 8  # bridge-vs-ddpm: 2 runs x 4 snapshots, one NFE each


def _argv(args) -> list[str]:
    return [sys.executable, "-m", "bridgeplan.cli", *map(str, args)]


def cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run(_argv(args), env=ENV, capture_output=True, text=True, timeout=TIMEOUT)


def ok(*args) -> str:
    r = cli(*args)
    assert r.returncode == 0, r.stderr
    return r.stdout


def error_line(*args) -> str:
    """Run the CLI; expect exit code 2 and one ``error:`` line on stderr (no traceback)."""
    r = cli(*args)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    return lines[0]


def wait_for(condition, timeout: float = TIMEOUT) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"not met in {timeout} s"
        time.sleep(0.01)


def kill_when(args, condition, timeout: float = TIMEOUT) -> bool:
    """Start the CLI and SIGKILL it as soon as ``condition()`` holds: True if killed, False if it
    finished (successfully) first."""
    proc = subprocess.Popen(_argv(args), env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + timeout
        while proc.poll() is None:
            if condition():
                proc.kill()
                proc.wait()
                return True
            assert time.monotonic() < deadline, f"{args[0]}: condition not met in {timeout} s"
            time.sleep(0.001)  # short: a checkpoint's temporary file lives for milliseconds
        assert proc.returncode == 0, proc.stderr.read()
        return False
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        proc.stderr.close()


def temporaries(directory: Path, prefix: str = ".") -> list[str]:
    """Files an atomic write (``.NAME.RANDOM.tmp``) left in ``directory``."""
    try:
        return [n for n in os.listdir(directory) if n.startswith(prefix) and n.endswith(".tmp")]
    except FileNotFoundError:
        return []


def after(condition, seconds: float):
    """A condition that holds ``seconds`` after ``condition`` first did."""
    since = None

    def check() -> bool:
        nonlocal since
        if since is None and condition():
            since = time.monotonic()
        return since is not None and time.monotonic() - since >= seconds
    return check


def assert_same_state(a: dict, b: dict, where: str) -> None:
    """Bit-identical nested state: every tensor by torch.equal, everything else by ==."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            assert_same_state(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same_state(x, y, f"{where}[{i}]")
    elif isinstance(a, torch.Tensor):
        assert isinstance(b, torch.Tensor) and a.dtype == b.dtype and torch.equal(a, b), where
    else:
        assert a == b, where


def load(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=False)


def assert_run_matches(run: Path, reference: Path) -> None:
    """Same model, EMA, optimizer and RNG states, and the same EMA snapshots at the same steps."""
    got, want = load(run / "checkpoint.pt"), load(reference / "checkpoint.pt")
    for key in ("step", "model", "ema", "optimizer", "generator", "torch_rng"):
        assert_same_state(got[key], want[key], key)
    names = sorted(p.name for p in (reference / "snapshots").iterdir())
    assert sorted(p.name for p in (run / "snapshots").iterdir()) == names
    for name in names:
        got, want = load(run / "snapshots" / name), load(reference / "snapshots" / name)
        assert got["step"] == want["step"]
        assert_same_state(got["ema"], want["ema"], name)


@pytest.fixture(scope="module")
def reference_run(tiny_dataset, tmp_path_factory) -> Path:
    """An uninterrupted run of TRAIN_STEPS steps with a checkpoint and a snapshot at every step."""
    run = tmp_path_factory.mktemp("reference") / "run"
    ok(*train_args(tiny_dataset, run, TRAIN_STEPS, "--checkpoint-every", "1"))
    return run


@pytest.mark.slow
def test_training_killed_at_any_moment_resumes_bit_identical(tiny_dataset, tmp_path, reference_run):
    run = tmp_path / "run"
    ckpt, snapshots = run / "checkpoint.pt", run / "snapshots"
    rng = random.Random(0)

    def wrote_checkpoint_since(t_ns: int):
        return lambda: ckpt.exists() and ckpt.stat().st_mtime_ns > t_ns

    # (name, condition of the moment to kill at, given the attempt's start time)
    moments = [
        ("before its first checkpoint", lambda t: lambda: (run / "config.json").exists()),
        ("writing checkpoint.pt", lambda t: lambda: bool(temporaries(run, ".checkpoint.pt."))),
        ("writing a snapshot", lambda t: lambda: bool(temporaries(snapshots))),
        ("writing checkpoint.pt", lambda t: lambda: bool(temporaries(run, ".checkpoint.pt."))),
        ("writing a snapshot", lambda t: lambda: bool(temporaries(snapshots))),
        *[("at random", lambda t, s=rng.uniform(0.0, 0.3): after(wrote_checkpoint_since(t), s)) for _ in range(3)],
    ]
    killed, mid_write, fresh_restarts = 0, {"checkpoint.pt": 0, "snapshot": 0}, 0
    for name, moment in moments:
        resume = ckpt.exists()
        if not resume and killed > 0:  # killed before its first checkpoint: nothing to --resume
            line = error_line(*train_args(tiny_dataset, run, TRAIN_STEPS, "--checkpoint-every", "1", "--resume"))
            assert "killed before its first checkpoint: start it again without --resume" in line
            fresh_restarts += 1
        args = train_args(tiny_dataset, run, TRAIN_STEPS, "--checkpoint-every", "1", *(["--resume"] if resume else []))
        assert kill_when(args, moment(time.time_ns())), f"training finished before it could be killed {name}"
        killed += 1
        # a temporary file left behind proves the kill landed inside that write
        mid_write["checkpoint.pt"] += bool(temporaries(run, ".checkpoint.pt."))
        mid_write["snapshot"] += bool(temporaries(snapshots))
    assert mid_write["checkpoint.pt"] >= 1 and mid_write["snapshot"] >= 1, mid_write
    assert fresh_restarts >= 1
    ok(*train_args(tiny_dataset, run, TRAIN_STEPS, "--checkpoint-every", "1", "--resume"))
    assert not temporaries(run) and not temporaries(snapshots)  # leftovers of killed writes removed
    assert_run_matches(run, reference_run)
    print(f"training: {killed} kills survived, {sum(mid_write.values())} inside a write ({mid_write})")

    # a run written before snapshots were saved ahead of the checkpoint may lack the snapshot of its
    # checkpoint's step; --resume writes it again from the checkpoint
    last = snapshots / f"step_{TRAIN_STEPS:08d}.pt"
    last.unlink()
    ok(*train_args(tiny_dataset, run, TRAIN_STEPS, "--checkpoint-every", "1", "--resume"))
    assert_run_matches(run, reference_run)


def store_rows(results: Path) -> dict[tuple, dict]:
    """The store's rows by key, read without writing to it (an absent store: no rows)."""
    db = results / "results.sqlite"
    if not db.exists():
        return {}
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=60.0) as con:
        con.row_factory = sqlite3.Row
        rows = [dict(r) for r in con.execute("SELECT * FROM evaluations")]
    con.close()
    return {tuple(r[k] for k in KEY): r for r in rows}


def check_store(results: Path, train_steps: int) -> dict[tuple, dict]:
    """No orphan row: each names a finished run and one of its snapshots; no duplicate keys; the
    database passes SQLite's integrity check. Returns the rows by key."""
    db = results / "results.sqlite"
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as con:
        assert con.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
        keys = ", ".join(KEY)
        duplicates = f"SELECT {keys}, COUNT(*) FROM evaluations GROUP BY {keys} HAVING COUNT(*) > 1"
        assert con.execute(duplicates).fetchall() == []
    con.close()
    rows = store_rows(results)
    for r in rows.values():
        run = results / "runs" / r["run_name"]
        assert load(run / "checkpoint.pt")["step"] == train_steps, f"{run} evaluated before it finished"
        assert (run / "snapshots" / f"step_{r['step']:08d}.pt").exists(), f"orphan row {r}"
    return rows


def count_lost(before: dict, after: dict) -> int:
    return sum(k not in after for k in before)


def count_redone(before: dict, after: dict) -> int:
    """Rows evaluated again: INSERT OR REPLACE would give them a new id and creation time."""
    return sum(k in after and (after[k]["id"], after[k]["created"]) != (r["id"], r["created"])
               for k, r in before.items())


def sweep(grid: str, dataset: str, root: Path) -> tuple[list, Path]:
    """`study run` of a tiny study of ``grid`` under ``root``, and its results directory."""
    return tiny_study(root, dataset, grid, steps=SWEEP_STEPS)


@pytest.fixture(scope="module")
def finished_sweep(tiny_dataset, tmp_path_factory) -> Path:
    """The results directory of an uninterrupted bridge-vs-ddpm sweep."""
    args, results = sweep("bridge-vs-ddpm", tiny_dataset, tmp_path_factory.mktemp("sweep"))
    assert f"{SWEEP_ROWS} new results" in ok(*args)
    return results


@pytest.mark.slow
def test_sweep_killed_mid_way_loses_and_redoes_nothing(tiny_dataset, tmp_path, finished_sweep):
    args, results = sweep("bridge-vs-ddpm", tiny_dataset, tmp_path)
    moments = [  # (while, condition)
        ("training the first run", lambda: any((results / "runs").glob("*/checkpoint.pt"))),
        ("evaluating the first run", lambda: len(store_rows(results)) >= 1),
        ("training the second run", lambda: len(store_rows(results)) >= SWEEP_ROWS // 2),
        ("evaluating the second run", lambda: len(store_rows(results)) >= SWEEP_ROWS // 2 + 1),
    ]
    kills, lost, redone = 0, 0, 0
    before: dict[tuple, dict] = {}
    for name, moment in moments:
        assert kill_when(args, moment), f"the sweep finished before it could be killed {name}"
        kills += 1
        rows = check_store(results, train_steps=4)
        lost, redone = lost + count_lost(before, rows), redone + count_redone(before, rows)
        before = rows
    out = ok(*args)
    rows = check_store(results, train_steps=4)
    assert f"{SWEEP_ROWS - len(before)} new results" in out  # only what was missing was evaluated
    lost, redone = lost + count_lost(before, rows), redone + count_redone(before, rows)
    assert (lost, redone) == (0, 0)
    # the same numbers as the uninterrupted sweep: killed training resumed exactly
    reference = store_rows(finished_sweep)
    assert rows.keys() == reference.keys() and len(rows) == SWEEP_ROWS
    measured = ("score_minari", "score_d4rl", "success_rate", "floor_minari", "step", "seed")
    for key, row in rows.items():
        assert {m: row[m] for m in measured} == {m: reference[key][m] for m in measured}, key
    print(f"sweep: {kills} kills survived, {lost} rows lost, {redone} redone")


@pytest.mark.slow
def test_parallel_sweep_matches_the_sequential_one_and_exits_cleanly(tiny_dataset, tmp_path, finished_sweep):
    args, results = sweep("bridge-vs-ddpm", tiny_dataset, tmp_path)
    r = cli(*args, "--workers", "2")
    assert r.returncode == 0, r.stderr
    # workers killed by the pool instead of exiting leave semaphores the resource tracker warns about
    assert "leaked" not in r.stderr and "Warning" not in r.stderr, r.stderr
    rows, reference = store_rows(results), store_rows(finished_sweep)
    assert rows.keys() == reference.keys() and len(rows) == SWEEP_ROWS
    measured = ("score_minari", "success_rate", "floor_minari")
    for key, row in rows.items():
        assert {m: row[m] for m in measured} == {m: reference[key][m] for m in measured}, key


@pytest.mark.slow
def test_two_sweeps_share_one_store(tiny_dataset, tmp_path):
    # the same grid twice: both want to train the learned prior and the same four runs, and to
    # evaluate the same snapshots
    args, results = tiny_study(tmp_path, tiny_dataset, "nfe1")
    prior = results / "runs" / PriorTrainConfig(maze="umaze", horizon=32, seed=0).run_name()
    logs = [tmp_path / f"sweep{i}.err" for i in range(2)]
    procs = []
    try:
        # hold the prior's lock, as a trainer would, until both sweeps wait for it: they contend
        # for sure, whatever their start-up times
        with run_lock(prior):
            for log in logs:
                with open(log, "w") as err:
                    procs.append(subprocess.Popen(_argv(args), env=ENV, stdout=subprocess.PIPE, stderr=err,
                                                  text=True))
            wait_for(lambda: all("waiting for" in log.read_text() for log in logs))
        outs = [p.communicate(timeout=TIMEOUT)[0] for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()
    assert [p.returncode for p in procs] == [0, 0], [log.read_text() for log in logs]
    rows = check_store(results, train_steps=2)
    assert len(rows) == 4 * 2  # 4 series x 2 snapshots, each once
    # each row is reported as new by the one sweep that stored it, even when both evaluated it
    added = [int(re.search(r"tiny: (\d+) new results", out).group(1)) for out in outs]
    assert sum(added) == len(rows), outs
    runs = sorted((results / "runs").iterdir())
    assert len(runs) == 5  # the prior and four planners
    logged = importlib.util.find_spec("tensorboard") is not None  # an optional extra: without it, no logs
    for run in runs:
        # one TensorBoard log per training: each run was trained by one sweep, once
        assert len(list((run / "tensorboard").iterdir())) == 1 if logged else not (run / "tensorboard").exists(), run
        assert sorted(p.name for p in (run / "snapshots").iterdir())[-1] == "step_00000002.pt"


def flip_weight_byte(path: Path) -> None:
    """Flip one byte in the middle of the largest tensor of a torch checkpoint (a zip of records)."""
    with zipfile.ZipFile(path) as z:
        info = max((i for i in z.infolist() if "/data/" in i.filename), key=lambda i: i.file_size)
    data = bytearray(path.read_bytes())
    name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26:info.header_offset + 30])
    offset = info.header_offset + 30 + name_len + extra_len + info.file_size // 2
    data[offset] ^= 0xFF
    path.write_bytes(bytes(data))


def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def files(directory: Path, skip: tuple[str, ...] = ()) -> dict[str, bytes]:
    """Every file's bytes but SQLite's side files (an open, even read-only, may create them empty)."""
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*"))
            if p.is_file() and p.name not in skip and not p.name.endswith(("-wal", "-shm"))}


@pytest.mark.parametrize("damage", [truncate, flip_weight_byte])
def test_damaged_checkpoint_and_snapshot(tiny_dataset, tiny_runs, tmp_path, damage):
    run = tmp_path / "run"
    shutil.copytree(tiny_runs["ddpm"], run)
    ckpt, snapshot = run / "checkpoint.pt", run / "snapshots" / "step_00000002.pt"
    if damage is flip_weight_byte:
        intact = load(tiny_runs["ddpm"] / "checkpoint.pt")
        damage(ckpt)
        # the damage torch.load alone does not notice: other weights, no error
        assert any(not torch.equal(v, load(ckpt)["model"][k]) for k, v in intact["model"].items())
    else:
        damage(ckpt)
    damage(snapshot)
    before = files(run)
    line = error_line(*train_args(tiny_dataset, run, 5, "--checkpoint-every", "2", "--resume"))
    assert str(ckpt) in line and "truncated or corrupted" in line
    assert files(run) == before  # nothing overwritten, nothing added
    assert str(ckpt) in error_line("eval", run, "--episodes", "2", "--device", "cpu")
    assert str(snapshot) in error_line("eval", run, "--snapshot", "2", "--episodes", "2", "--device", "cpu")
    assert files(run) == before


def flip_middle_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", [truncate, flip_middle_byte])
def test_damaged_dataset_cache_is_rebuilt(tiny_dataset, tmp_path, damage):
    # the cache is a copy of the source data: rebuilt from the source, not an error
    dataset = tmp_path / "dataset"
    shutil.copytree(tiny_dataset, dataset)  # copy2: the source's mtime, so the intact cache is valid
    cache, source = dataset / CACHE_NAME, dataset / "data" / "main_data.hdf5"
    intact = read_cache(source, cache)
    assert intact is not None
    damage(cache)
    assert read_cache(source, cache) is None
    info = json.loads(ok("data", "info", dataset, "--json"))
    expected = json.loads(json.dumps(summarize(intact)))
    assert info.pop("source") == str(dataset) and info == {k: v for k, v in expected.items() if k != "source"}
    rebuilt = read_cache(source, cache)
    assert rebuilt is not None and np.array_equal(rebuilt.states, intact.states)


def flip_page_type(path: Path) -> None:
    """Make the second page of an SQLite file an invalid b-tree page (its type byte)."""
    data = bytearray(path.read_bytes())
    page_size = struct.unpack(">H", data[16:18])[0]
    data[page_size] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", [truncate, flip_page_type])
def test_damaged_store(tiny_dataset, tmp_path, finished_sweep, damage):
    args, results = sweep("bridge-vs-ddpm", tiny_dataset, tmp_path)
    shutil.copytree(finished_sweep, results)
    db = results / "results.sqlite"
    damage(db)
    before = files(results)
    assert str(db) in error_line("report", "--results", results)
    assert str(db) in error_line(*args)
    assert files(results) == before  # no training, no evaluation, the store as it was


def test_sweep_over_damaged_run(tiny_dataset, tmp_path, finished_sweep):
    args, results = sweep("bridge-vs-ddpm", tiny_dataset, tmp_path)
    shutil.copytree(finished_sweep, results)
    ckpt = next((results / "runs").glob("*/checkpoint.pt"))
    truncate(ckpt)
    # a run whose evaluations are all stored is not opened again: take one of its evaluations out, so it must be
    with sqlite3.connect(results / "results.sqlite") as con:
        (last,) = con.execute("SELECT MAX(id) FROM evaluations WHERE run_name = ?", (ckpt.parent.name,)).fetchone()
        con.execute("DELETE FROM memberships WHERE evaluation = ?", (last,))
        con.execute("DELETE FROM evaluations WHERE id = ?", (last,))
    con.close()
    before, rows = files(results, skip=("results.sqlite",)), store_rows(results)
    assert str(ckpt) in error_line(*args)
    # opening the store may rewrite its header: its rows must be the same
    assert files(results, skip=("results.sqlite",)) == before and store_rows(results) == rows


def test_code_version_is_dirty_for_code_not_for_reports(tmp_path):
    """A checkout whose only changes are a campaign's own outputs (reports under docs/results) records its
    commit; a change to the package or to a study file marks the version ``.dirty``."""
    import bridgeplan

    repo = tmp_path / "repo"
    shutil.copytree(Path(bridgeplan.__file__).parent, repo / "src" / "bridgeplan",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (repo / "docs" / "results" / "umaze").mkdir(parents=True)
    (repo / "docs" / "results" / "umaze" / "report.md").write_text("old\n")
    (repo / "studies").mkdir()
    (repo / "studies" / "x.toml").write_text("title = 'x'\n")
    (repo / ".gitignore").write_text("__pycache__/\n")  # as the repository's: importing the code writes them
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(repo)]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "c"], check=True)

    def version() -> str:
        code = "from bridgeplan.files import code_version; print(code_version())"
        return subprocess.run([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": str(repo / "src")},
                              capture_output=True, text=True, check=True).stdout.strip()

    sha = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    assert version() == f"{bridgeplan.__version__}+{sha}"
    (repo / "docs" / "results" / "umaze" / "report.md").write_text("new\n")
    assert version() == f"{bridgeplan.__version__}+{sha}"
    (repo / "studies" / "x.toml").write_text("title = 'changed'\n")
    assert version() == f"{bridgeplan.__version__}+{sha}.dirty"
    subprocess.run([*git, "checkout", "-q", "--", "studies/x.toml"], check=True)
    (repo / "src" / "bridgeplan" / "files.py").write_text((repo / "src" / "bridgeplan" / "files.py").read_text() + "\n")
    assert version() == f"{bridgeplan.__version__}+{sha}.dirty"
    subprocess.run([*git, "checkout", "-q", "--", "src/bridgeplan/files.py"], check=True)
    (repo / "docs" / "results" / "new-campaign.md").write_text("new\n")  # an untracked output: not code
    (repo / "src" / "bridgeplan" / "__pycache__").mkdir(exist_ok=True)
    (repo / "src" / "bridgeplan" / "__pycache__" / "x.pyc").write_bytes(b"")  # ignored by git: not code either
    assert version() == f"{bridgeplan.__version__}+{sha}"
    (repo / "src" / "bridgeplan" / "new_module.py").write_text("X = 1\n")  # code not yet added: code
    assert version() == f"{bridgeplan.__version__}+{sha}.dirty"


def _spawned_children(pid: int) -> list[int]:
    """The processes ``pid`` spawned to work (multiprocessing's spawn), not its resource tracker."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            cmdline = Path(f"/proc/{entry}/cmdline").read_bytes()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid and b"spawn_main" in cmdline:
            found.append(int(entry))
    return found


def test_data_generation_whose_worker_is_killed_ends_with_one_error(tmp_path):
    """A Maze2D generation worker killed (as the out-of-memory killer would): the command ends with one error line,
    exit 2, and writes nothing (a process pool's broken-pool traceback before)."""
    out = tmp_path / "u"
    proc = subprocess.Popen(_argv(["data", "generate", "--maze", "umaze", "--steps", "50000000", "--workers", "2",
                                   "--out", out, "--no-progress"]),
                            env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: len(_spawned_children(proc.pid)) == 2 or proc.poll() is not None)
        workers = _spawned_children(proc.pid)
        assert workers, "the command ended before its workers started"
        os.kill(workers[0], signal.SIGKILL)
        _, stderr = proc.communicate(timeout=TIMEOUT)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    lines = stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, stderr
    assert lines[0].startswith("error: a worker generating umaze's streams ended without answering"), stderr
    assert not out.exists() and os.listdir(tmp_path) == []
