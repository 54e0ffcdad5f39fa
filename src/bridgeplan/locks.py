"""One process at a time per run directory: an advisory ``fcntl.flock`` on ``RUN/.lock``.

The kernel drops the lock when its process dies, even by SIGKILL, so a killed run never leaves a
stale lock behind. The lock is re-entrant within a process, so a caller holding it (a sweep that
checks how far a run got, then trains it) can call code that takes it again (training). The lock
file is never deleted: a process waiting on a deleted file would lock an inode nobody else sees.
"""

from __future__ import annotations

import fcntl
import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

LOCK_NAME = ".lock"

_held: dict[Path, tuple[int, int]] = {}  # lock file -> (descriptor, depth) in this process


@contextmanager
def run_lock(run_dir: Path) -> Iterator[None]:
    """Hold the lock of ``run_dir`` (created if missing) for the ``with`` block; waits for another holder."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    path = (run_dir / LOCK_NAME).resolve()
    if path in _held:
        fd, depth = _held[path]
        _held[path] = (fd, depth + 1)
    else:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                print(f"waiting for {run_dir}: another process is training it", file=sys.stderr, flush=True)
                fcntl.flock(fd, fcntl.LOCK_EX)
        except BaseException:
            os.close(fd)
            raise
        _held[path] = (fd, 1)
    try:
        yield
    finally:
        fd, depth = _held.pop(path)
        if depth > 1:
            _held[path] = (fd, depth - 1)
        else:
            os.close(fd)  # closing the only descriptor releases the flock
