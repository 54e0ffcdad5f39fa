"""One checkpoint file that resumes everything, written atomically (temporary name, then rename)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import torch

from bridgeplan.errors import BridgeplanError
from bridgeplan.files import atomic_write_bytes, atomic_write_text
from bridgeplan.paths import checkpoint_path, config_path


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    atomic_write_bytes(path, lambda f: torch.save(state, f))


def load_checkpoint(path: Path) -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_checkpoint`; a run directory finds its checkpoint."""
    path = Path(path)
    if path.is_dir():
        path = checkpoint_path(path)
    if not path.exists():
        raise BridgeplanError(f"no checkpoint at {path}")
    try:
        _verify_crcs(path)
        state = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # torch raises many types for a truncated or foreign file
        raise _unreadable(path, "checkpoint", e) from None
    if not isinstance(state, dict) or "config" not in state or "kind" not in state:
        raise BridgeplanError(f"{path} is not a bridgeplan checkpoint")
    return state


def check_checkpoint_file(path: Path, what: str = "checkpoint") -> None:
    """Refuse a truncated or corrupted checkpoint or snapshot file (every record against its CRC-32) without
    loading its tensors: what ``train --resume`` checks of the snapshots it would otherwise leave damaged."""
    try:
        _verify_crcs(path)
    except Exception as e:  # zipfile raises several types for a truncated file
        raise _unreadable(path, what, e) from None


def _unreadable(path: Path, what: str, e: Exception) -> BridgeplanError:
    first_line = (str(e).strip().splitlines() or [""])[0]  # torch adds lines of advice
    advice = ("; delete it and resume (its step is then not evaluated, unless it is the checkpoint's, which resume "
              "writes again), or train the run afresh") if what == "snapshot" else ""
    return BridgeplanError(f"cannot read {what} {path} (truncated or corrupted?): {type(e).__name__}: "
                           f"{first_line}{advice}")


def _verify_crcs(path: Path) -> None:
    """Check every record of the checkpoint (a zip) against its CRC-32: ``torch.load`` does not, and
    would load a flipped bit in the weights silently."""
    with zipfile.ZipFile(path) as z:
        bad = z.testzip()
    if bad is not None:
        raise zipfile.BadZipFile(f"bad CRC-32 for {bad}")


def write_config(run_dir: Path, config: dict[str, Any]) -> None:
    atomic_write_text(config_path(run_dir), json.dumps(config, indent=2) + "\n")
