"""A pool's workers end with the command that started them, even when it is killed without stopping its pool."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bridgeplan.errors import BridgeplanError
from bridgeplan.workers import doing, run_spawned

PARENT = """
import multiprocessing as mp, sys, time
from bridgeplan.workers import exit_with_parent
if __name__ == "__main__":
    pool = mp.get_context("spawn").Pool(1, initializer=exit_with_parent if sys.argv[1] == "watched" else None)
    worker = pool.apply(__import__("os").getpid)
    pool.apply_async(time.sleep, (120,))
    time.sleep(1.5)  # the worker inside its task (an idle one would see its task pipe close and exit anyway)
    print(worker, flush=True)
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _orphan_after_parent_killed(mode: str, wait_seconds: float) -> bool:
    """Start a parent with a one-worker pool, SIGKILL the parent, then whether its worker still lives after
    ``wait_seconds``."""
    parent = subprocess.Popen([sys.executable, "-c", PARENT, mode], stdout=subprocess.PIPE, text=True)
    worker = int(parent.stdout.readline())
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + wait_seconds
    while _alive(worker) and time.monotonic() < deadline:
        time.sleep(0.2)
    alive = _alive(worker)
    if alive:
        os.kill(worker, signal.SIGKILL)
    return alive


@pytest.mark.skipif(sys.platform != "linux", reason="re-parenting of orphans as Linux does it")
def test_a_worker_exits_when_its_parent_is_killed():
    assert not _orphan_after_parent_killed("watched", wait_seconds=10)
    assert _orphan_after_parent_killed("unwatched", wait_seconds=1.5)  # what happened before: an orphan trains on


def _square_or_refuse(x: int, folder: str) -> int:
    if x < 0:
        raise BridgeplanError(f"refused {x}")
    (Path(folder) / f"{x}.done").touch()
    return x * x


def test_run_spawned_answers_in_order_and_raises_a_workers_error_after_the_others(tmp_path):
    assert run_spawned(_square_or_refuse, [(3, str(tmp_path)), (2, str(tmp_path))], 2, ["a", "b"]) == [9, 4]
    with pytest.raises(BridgeplanError, match="^refused -1$"):
        run_spawned(_square_or_refuse, [(-1, str(tmp_path)), (5, str(tmp_path))], 1, ["a", "b"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["2.done", "3.done", "5.done"]  # the other call ran


def test_run_spawned_says_what_each_worker_does_and_when_it_ends(tmp_path, capsys):
    run_spawned(_say_and_square, [(3,), (2,)], 2, ["a", "b"], progress=True)
    lines = capsys.readouterr().err.splitlines()
    assert any(line.endswith("] a: squaring 3") for line in lines), lines
    assert sum("ended)" in line for line in lines) == 2 and lines[-1].endswith("done (2 of 2 ended)")
    run_spawned(_say_and_square, [(3,)], 1, ["a"])  # without progress: silent
    assert capsys.readouterr().err == ""


def _say_and_square(x: int) -> int:
    doing(f"squaring {x}")
    return x * x
