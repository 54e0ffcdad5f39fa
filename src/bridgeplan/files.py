"""Writing files so that a reader never sees half of one, and naming the code that wrote them."""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

from bridgeplan.errors import BridgeplanError


def check_writable(path: Path | str, what: str = "output", folder: bool = False) -> Path:
    """Refuse (:class:`BridgeplanError`, the CLI's one ``error:`` line) an output path that cannot be written, before
    any work is done: a file where a folder is wanted (or the other way round), a folder below a file, a folder
    that does not take files (read-only, no permission). Creates nothing: the nearest existing folder is probed
    with a temporary file, removed at once (named as an atomic write's, ``.*.tmp``: what a process killed in
    between leaves is what a run's next trainer knows to remove). Returns ``path``."""
    path = Path(path)
    if folder and path.exists() and not path.is_dir():
        raise BridgeplanError(f"cannot write the {what} {path}: it is a file, not a folder")
    if not folder and path.is_dir():
        raise BridgeplanError(f"cannot write the {what} {path}: it is a folder, not a file")
    existing = path if folder else path.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise BridgeplanError(f"cannot write the {what} {path}: {existing} is a file, not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".bridgeplan-probe.", suffix=".tmp", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise BridgeplanError(f"cannot write the {what} {path}: {e.strerror or e} in {existing}") from None
    return path


def atomic_write_bytes(path: Path, write) -> None:
    """Call ``write(file)`` on a temporary file beside ``path``, then rename it onto ``path``; a file system that
    refuses (no permission, a file where a folder should be, a full disk) is one :class:`BridgeplanError` that names
    ``path``, and leaves nothing behind."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as e:
        raise BridgeplanError(f"cannot write {path}: {e.strerror or e}") from None
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise BridgeplanError(f"cannot write {path}: {e.strerror or e}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, lambda f: f.write(text.encode()))


CODE_PATHS = ("src", "pyproject.toml", "scripts", "studies")
"""What makes a result, relative to the repository root: the package, the study files that declare the campaigns
and the setup scripts. Their outputs (reports, CSVs, figures under docs/results) are not code: a campaign that
writes its report between two of its evaluations does not make the second one's code dirty."""


COPIED_FROM_ENV = "BRIDGEPLAN_COPIED_FROM"
"""Environment variable: the commit a copy of the tree without ``.git`` was made from (``scripts/gpu-check.sh``
passes it); such a copy's code version reads ``<version>+<commit>.copy``."""


def code_version() -> str:
    """The git commit of the code (with ``.dirty`` for uncommitted changes to :data:`CODE_PATHS`, a new file not yet
    added among them: a module the code imports is code, tracked or not; git's ignored files are not), or the
    package version."""
    from bridgeplan import __version__

    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        root = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=here, capture_output=True,
                              text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=normal", "--", *CODE_PATHS],
                               cwd=root, capture_output=True, text=True, timeout=5).stdout.strip()
        return f"{__version__}+{sha}{'.dirty' if dirty else ''}"
    except (OSError, subprocess.SubprocessError):
        # a copy of the tree without its git directory (a device machine's): the commit it says it was copied from
        copied = os.environ.get(COPIED_FROM_ENV, "")
        return f"{__version__}+{copied}.copy" if copied else __version__
