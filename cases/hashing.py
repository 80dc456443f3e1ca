"""SHA-256 of files, for provenance (imports record the instrument file's, exports name their sources')."""

from __future__ import annotations

import hashlib


def sha256_of(path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
