"""The one exception type for user mistakes: the CLI prints its message on one line and exits 2; warnings are one
line too."""

import warnings


class BridgeplanError(Exception):
    """A user-facing error (bad input, missing file, incompatible checkpoint)."""


def one_line_warnings() -> None:
    """Warnings as one ``warning:`` line each, without gymnasium-robotics' (its environments' registration notes)."""
    warnings.filterwarnings("ignore", module="gymnasium_robotics")
    warnings.formatwarning = _one_line_warning


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


def check_choice(what: str, value, choices) -> None:
    """A :class:`BridgeplanError` naming the choices unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise BridgeplanError(f"unknown {what} {value!r}: choose from {', '.join(map(str, choices))}")
