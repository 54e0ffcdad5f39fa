"""Report generators: each turns committed results under docs/results into one Markdown file.

A generator is a module with ``render(root) -> str`` (``root``: the docs/results folder; the text without its
final newline) and ``READS``, the trained methods (:class:`~bridgeplan.analysis.keys.MethodKey` at their
default sampler, open loop, single-task) it reads: a study whose report names a generator must train them, or
use studies that do.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Generator:
    name: str
    module: str
    output: str
    """Its default output file, relative to docs/results."""
    description: str
    feeds: tuple[str, ...]
    """The README/docs files that cite the report's tables (relative to the repository root)."""

    def load(self):
        return importlib.import_module(self.module)

    def render(self, root: Path) -> str:
        """The report's text, ending in a newline, from the results under ``root`` (docs/results)."""
        return self.load().render(Path(root)) + "\n"

    def reads(self):
        return self.load().READS


GENERATORS = {g.name: g for g in [
    Generator("findings", "bridgeplan.studies.reports.findings", "findings.md",
              "each finding per maze and task set, paired over seeds, with its verdict; the score-95 goal",
              ("README.md", "docs/results/README.md")),
    Generator("prior-curves", "bridgeplan.studies.reports.prior_curves", "prior-curves.md",
              "flow matching, the I2SB and the consistent bridge from each prior across training, against DDPM",
              ("README.md", "docs/results/README.md")),
    Generator("controllers", "bridgeplan.studies.reports.controllers", "controllers.md",
              "tracking against pursuit at each lookahead, open loop and replanned, per maze and task set",
              ("README.md", "docs/results/README.md")),
    Generator("wallclock", "bridgeplan.studies.reports.wallclock", "throughput-wallclock.md",
              "training settings at equal minutes of training: score, success and windows/s, paired over seeds",
              ("README.md",)),
    Generator("cddb", "bridgeplan.studies.reports.cddb", "cddb.md",
              "CDDB consistency corrections of the consistent bridge and flow against DDPM's best, chosen on "
              "validation", ("README.md",)),
]}
