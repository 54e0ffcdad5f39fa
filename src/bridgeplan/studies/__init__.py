"""Studies: one declarative file per campaign (``studies/NAME.toml`` at the repository root) and the commands
that run it and regenerate its reports.

- :mod:`~bridgeplan.studies.spec`: the file format, parsed into frozen dataclasses (:class:`Study`);
- :mod:`~bridgeplan.studies.plan`: the study as sweeps of the experiments runner, what is missing from its
  store and what that costs, the quick scale;
- :mod:`~bridgeplan.studies.generators`: what a report generator is, and loading a repository's own
  (``studies/reports/`` at its root: the generators of its committed reports from its results under docs/results).

The repository root (``--root``; default: the git top-level of the current directory, else the current
directory) holds ``studies/`` and ``docs/results/``.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from bridgeplan.errors import BridgeplanError
from bridgeplan.studies import generators
from bridgeplan.studies.plan import check_reports, check_study
from bridgeplan.studies.spec import Study, StudyError, read_study

__all__ = ["Studies", "Study", "StudyError", "broken_error", "find_root", "load_studies", "parse_study", "select"]


def find_root(root: str | Path | None = None) -> Path:
    """The repository root: ``root`` if given, else the git top-level of the current directory, else the
    current directory; it must hold ``studies/``."""
    if root is None:
        try:
            root = subprocess.run(["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True,
                                  timeout=5, check=True).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            root = "."
    root = Path(root).resolve()
    if not (root / "studies").is_dir():
        raise BridgeplanError(f"no studies/ folder in {root}; give the repository root with --root")
    return root


def parse_study(path: Path | str, shown: Path | str | None = None, generators: dict | None = None) -> Study:
    """The study in ``path``, read (:func:`~bridgeplan.studies.spec.read_study`; its reports' ``generators``, a
    repository's) and checked on its own: its grids, preset and runs against its maze
    (:func:`~bridgeplan.studies.plan.check_study`)."""
    study = read_study(path, shown, generators or {})
    check_study(study)
    return study


class Studies(dict):
    """The studies of a repository by name, and in :attr:`broken` the files that are not studies (that do not parse,
    or whose ``uses`` name a broken study or form a cycle), each with its error: one broken file stops only the
    commands that need it."""

    def __init__(self) -> None:
        super().__init__()
        self.broken: dict[str, BridgeplanError] = {}
        """Each broken study file (as its errors show it) and its error."""
        self.broken_names: dict[str, str] = {}
        """The name of each broken study that parsed (broken by its ``uses``), and its file."""


def load_studies(root: Path) -> Studies:
    """Every study of ``root/studies``, parsed and checked against each other (``uses``, reports' methods)."""
    studies = Studies()
    reports = generators.load(root)
    for path in sorted((Path(root) / "studies").glob("*.toml")):
        try:
            study = parse_study(path, shown=path.relative_to(root), generators=reports)
            if study.name in studies:
                raise StudyError(study.file, "name", f"{study.name!r} is also the name of {studies[study.name].file}")
        except BridgeplanError as e:
            studies.broken[str(path.relative_to(root))] = e
            continue
        studies[study.name] = study
    while True:  # a study that uses a broken one is broken in its turn
        errors = {}
        for study in studies.values():
            try:
                check_reports(study, studies, reports)
            except BridgeplanError as e:
                errors[study.name] = e
        if not errors:
            return studies
        for name, error in errors.items():
            studies.broken[str(studies[name].file)] = error
            studies.broken_names[name] = str(studies.pop(name).file)


def broken_error(studies: dict[str, Study], name: str, root: Path) -> BridgeplanError | None:
    """The error of the broken study file that ``name`` (a study's name, or its file) means; None if none."""
    broken = getattr(studies, "broken", {})
    if name in getattr(studies, "broken_names", {}):
        return broken[studies.broken_names[name]]
    for file, error in broken.items():
        if name in (Path(file).stem, file) or Path(name).resolve() == (Path(root) / file).resolve():
            return error
    return None


def select(studies: dict[str, Study], names: list[str], root: Path) -> list[Study]:
    """The studies named (by name, by file, or by a report generator's name: the studies whose reports it makes,
    as the generated blocks' markers name them), all when none is."""
    if not names:
        return list(studies.values())
    out = []
    for name in names:
        match = [s for s in studies.values() if name in (s.name, str(s.file), str((root / s.file).resolve()))
                 or Path(name).resolve() == (root / s.file).resolve()]
        match = match or [s for s in studies.values() if any(r.generator == name for r in s.reports)]
        if not match:
            raise broken_error(studies, name, root) or BridgeplanError(
                f"unknown study {name!r}: choose from {', '.join(studies)}")
        out.append(match[0])
    return out
