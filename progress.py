"""Whether progress may be shown on stderr (progress bars and progress lines).

``ADCPDYN_PROGRESS=0`` silences every one of them, ``ADCPDYN_PROGRESS=1`` turns the command's
progress lines on even when stderr is not a terminal; otherwise they show on a terminal only.
Results never go to stderr, so a script reading stdout sees the same either way.
"""

from __future__ import annotations

import os

ENV = "ADCPDYN_PROGRESS"


def _setting() -> str:
    return os.environ.get(ENV, "").strip()


def progress_silenced() -> bool:
    """``ADCPDYN_PROGRESS=0``: no progress bar or line anywhere."""
    return _setting() == "0"


def progress_enabled(fd: int = 2) -> bool:
    """Progress on descriptor ``fd``: as ``ADCPDYN_PROGRESS=1|0`` says, else when ``fd`` is a terminal."""
    if _setting() in ("0", "1"):
        return _setting() == "1"
    try:
        return os.isatty(fd)
    except OSError:
        return False


def progress_bar_enabled() -> bool:
    """A tqdm bar on ``sys.stderr``: only on a terminal, and never with ``ADCPDYN_PROGRESS=0``
    (a bar written into a file or a held descriptor is noise, not progress)."""
    import sys

    try:
        return (not progress_silenced()) and sys.stderr.isatty()
    except (AttributeError, ValueError):  # stderr closed or replaced by an object without isatty
        return False
