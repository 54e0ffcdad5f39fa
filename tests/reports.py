"""This repository's report generators (``studies/reports/`` at its root), as the tests read them."""

from __future__ import annotations

from pathlib import Path

from bridgeplan.studies import generators

REPO = Path(__file__).resolve().parents[1]
GENERATORS = generators.load(REPO)


def report(name: str):
    """The module of generator ``name`` (``cddb``, ``ogbench-planners``)."""
    return GENERATORS[name].load()
