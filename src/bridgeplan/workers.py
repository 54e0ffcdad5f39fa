"""Worker processes of the local pools (a study's seeds, a sweep's jobs, a dataset's streams) end with their parent.

A pool's workers are spawned processes of their own: when the command that started them is killed without the time
to stop its pool (SIGTERM from a scheduler, SIGKILL), they would train on as orphans, holding their runs' locks and
both cores, beside the command run next. Each worker watches its parent instead, and exits once it is gone."""

from __future__ import annotations

import os
import threading
import time

PARENT_POLL_SECONDS = 1.0


def exit_with_parent(poll_seconds: float = PARENT_POLL_SECONDS) -> None:
    """A pool's initializer: a daemon thread that ends this process when its parent has gone (the parent id
    changes when the process is re-parented)."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_seconds)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
