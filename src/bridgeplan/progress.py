"""The commands' progress bars (tqdm): none under ``--no-progress``; on a terminal redrawn as tqdm does; into a file
(a log under nohup or a batch scheduler) at most once a minute, where ten redraws a second would grow the log by
megabytes an hour."""

from __future__ import annotations

import sys

LOG_REDRAW_SECONDS = 60.0
"""Seconds between two redraws of a bar whose stderr is not a terminal."""


def progress_bar(progress: bool, **kwargs):
    """A ``tqdm`` bar of ``kwargs`` (``total``, ``desc``, ``unit``, ...), disabled where not ``progress``."""
    from tqdm import tqdm

    if not sys.stderr.isatty():
        kwargs["mininterval"] = max(kwargs.get("mininterval", 0.1), LOG_REDRAW_SECONDS)
    return tqdm(disable=not progress, **kwargs)
