"""Shipped planners: trained weights that come with the package, so that a planner plans untrained.

One small checkpoint per planner in this folder (``NAME.pt``: a planner's EMA weights in float32, the config, the
normalizer and the training step, no optimizer state; or a GCBC/GCIQL run's policy alone, the low level of the
dataset graph built over the user's own generated data, checked against the data it was scored on) and
``manifest.json``, which names for each: its maze and method, the study file that trained and evaluated it, the run,
the code version that trained it, the step and the file's sha256. The files and the manifest are made by
``bridgeplan planners export`` (``bridgeplan.studies.ship``) from a study's runs, never written by hand; their scores
are the study's committed rows (``docs/results/shipped/``, reported in docs/results/shipped.md by ``bridgeplan study
report shipped``).

A shipped planner's name goes wherever a run directory does (``bridgeplan eval medium``, ``bridgeplan render
medium``, ``PlannerPolicy.from_run("medium")``): :func:`bridgeplan.runs.resolve_run` resolves it, checking the
file against the manifest's sha256. What a command writes beside a run (``eval/``, ``render/``) goes under
``runs/shipped/NAME`` of the current directory for a shipped planner (:func:`output_dir`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from bridgeplan.errors import BridgeplanError

DIR = Path(__file__).resolve().parent
"""Where the shipped files are (inside the installed package)."""
MANIFEST = "manifest.json"
OUTPUT_ROOT = Path("runs") / "shipped"
"""Where commands write what belongs beside a shipped planner's run (relative to the current directory)."""
STUDY = "shipped"
"""The study whose ``uses`` are the studies that train the shipped planners (studies/shipped.toml)."""


@dataclass(frozen=True)
class ShippedPlanner:
    """One manifest entry."""

    name: str
    maze: str
    method: str
    """The run's label (``DDPM``, ``flow (line)``)."""
    process: str
    """The planner's process (``ddpm``, ``flow``), or the policy's agent (``gcbc``, ``gciql``)."""
    prior: str
    """The planner's prior (empty for a policy)."""
    study: str
    """The study file that trained and evaluated it (relative to the repository root)."""
    rows: str
    """Its committed evaluations (relative to the repository root)."""
    run: str
    """The run's name in the study's results."""
    seed: int
    step: int
    code_version: str
    """The code that trained it (``0.1.0+SHA``)."""
    dataset: str
    parameters: int
    file: str
    bytes: int
    sha256: str
    kind: str = "planner"
    """``planner`` (a diffusion planner: ``bridgeplan eval NAME``) or ``policy`` (a GCBC/GCIQL policy: ``bridgeplan
    graph --low NAME`` plans with the dataset graph over it, ``bridgeplan eval NAME`` scores it alone)."""
    dataset_identity: str = ""
    """A policy's: the identity of the data its rows' graph was built over (the user's data must be the same)."""

    @property
    def path(self) -> Path:
        return DIR / self.file


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def manifest(directory: Path | None = None) -> dict[str, ShippedPlanner]:
    """The shipped planners by name (none when the folder has no manifest); ``directory`` default :data:`DIR`."""
    path = Path(directory or DIR) / MANIFEST
    if not path.exists():
        return {}
    try:
        entries = json.loads(path.read_text())["planners"]
        return {e["name"]: ShippedPlanner(**e) for e in entries}
    except (ValueError, KeyError, TypeError) as e:
        raise BridgeplanError(f"the shipped planners' manifest {path} is unreadable: {e}") from None


def names() -> list[str]:
    return list(manifest())


def get(name: str) -> ShippedPlanner | None:
    return manifest().get(name)


def verified_path(entry: ShippedPlanner) -> Path:
    """The entry's file, after checking its sha256 against the manifest's."""
    if not entry.path.exists():
        raise BridgeplanError(f"shipped planner {entry.name!r}: its file {entry.path} is missing from the package")
    digest = sha256(entry.path)
    if digest != entry.sha256:
        raise BridgeplanError(f"shipped planner {entry.name!r}: {entry.path} has sha256 {digest[:12]}..., the "
                              f"manifest says {entry.sha256[:12]}... (a damaged install?)")
    return entry.path


def output_dir(name: str) -> Path:
    """Where ``eval``/``render`` write for shipped planner ``name`` (``runs/shipped/NAME``)."""
    return OUTPUT_ROOT / name


def unknown_message(run: str | Path) -> str:
    shipped = names()
    return (f"no checkpoint or run directory {str(run)!r}, and no shipped planner of that name (shipped: "
            f"{', '.join(shipped) or 'none'}; see `bridgeplan planners list`)")
