"""Writing files so that a reader never sees half of one, and naming the code that wrote them."""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path


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


CODE_PATHS = ("src", "pyproject.toml", "scripts", "studies")
"""What makes a result, relative to the repository root: the package, the study files that declare the campaigns
and the setup scripts. Their outputs (reports, CSVs, figures under docs/results) are not code: a campaign that
writes its report between two of its evaluations does not make the second one's code dirty."""


COPIED_FROM_ENV = "BRIDGEPLAN_COPIED_FROM"
"""Environment variable: the commit a copy of the tree without ``.git`` was made from (``scripts/gpu-check.sh``
passes it); such a copy's code version reads ``<version>+<commit>.copy``."""


def code_version() -> str:
    """The git commit of the code (with ``.dirty`` for uncommitted changes to :data:`CODE_PATHS`), or the
    package version."""
    from bridgeplan import __version__

    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        root = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=here, capture_output=True,
                              text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS],
                               cwd=root, capture_output=True, text=True, timeout=5).stdout.strip()
        return f"{__version__}+{sha}{'.dirty' if dirty else ''}"
    except (OSError, subprocess.SubprocessError):
        # a copy of the tree without its git directory (a device machine's): the commit it says it was copied from
        copied = os.environ.get(COPIED_FROM_ENV, "")
        return f"{__version__}+{copied}.copy" if copied else __version__
