"""One checkpoint file that resumes everything, written atomically (temporary name, then rename)."""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import torch

from bridgeplan.errors import BridgeplanError

CHECKPOINT_NAME = "checkpoint.pt"
CONFIG_NAME = "config.json"


def code_version() -> str:
    """The git commit of the code (with ``+dirty`` for uncommitted changes), or the package version."""
    from bridgeplan import __version__

    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return f"{__version__}+{sha}{'.dirty' if dirty else ''}"
    except (OSError, subprocess.SubprocessError):
        return __version__


def atomic_write_bytes(path: Path, write) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it onto ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, lambda f: f.write(text.encode()))


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    atomic_write_bytes(path, lambda f: torch.save(state, f))


def load_checkpoint(path: Path) -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_checkpoint`; a run directory finds its checkpoint."""
    path = Path(path)
    if path.is_dir():
        path = path / CHECKPOINT_NAME
    if not path.exists():
        raise BridgeplanError(f"no checkpoint at {path}")
    try:
        _verify_crcs(path)
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # torch raises many types for a truncated or foreign file
        first_line = (str(e).strip().splitlines() or [""])[0]  # torch adds lines of advice
        raise BridgeplanError(f"cannot read checkpoint {path} (truncated or corrupted?): "
                              f"{type(e).__name__}: {first_line}") from None
    if not isinstance(state, dict) or "config" not in state or "kind" not in state:
        raise BridgeplanError(f"{path} is not a bridgeplan checkpoint")
    return state


def _verify_crcs(path: Path) -> None:
    """Check every record of the checkpoint (a zip) against its CRC-32: ``torch.load`` does not, and
    would load a flipped bit in the weights silently."""
    with zipfile.ZipFile(path) as z:
        bad = z.testzip()
    if bad is not None:
        raise zipfile.BadZipFile(f"bad CRC-32 for {bad}")


def write_config(run_dir: Path, config: dict[str, Any]) -> None:
    atomic_write_text(Path(run_dir) / CONFIG_NAME, json.dumps(config, indent=2) + "\n")
