"""Provenance: SHA-256 of files (imports record the instrument file's, exports name their sources') and
the installed adcpdyn's version."""

from __future__ import annotations

import hashlib


def sha256_of(path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def adcpdyn_version() -> str:
    """The installed adcpdyn's version (``importlib.metadata``), or ``unknown``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("adcpdyn")
    except PackageNotFoundError:
        return "unknown"
