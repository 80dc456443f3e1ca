"""Case files named on the command line: files, folders (their ``*.h5``) and glob patterns."""

from __future__ import annotations

import glob
from pathlib import Path

CASE_SUFFIXES = (".h5", ".hdf5")


def is_many(items) -> bool:
    """True when the arguments name a batch: several, a folder, or a glob pattern."""
    items = list(items)
    return len(items) > 1 or any(Path(i).is_dir() or glob.has_magic(str(i)) for i in items)


def collect_case_paths(items) -> list[Path]:
    """Absolute case paths, in argument order then name order, without repeats.

    Raises
    ------
    ValueError
        When an argument matches no case file, or two cases share a file name (their
        outputs would collide).
    """
    out: list[Path] = []
    for item in items:
        p = Path(item)
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.suffix in CASE_SUFFIXES and f.is_file())
        elif glob.has_magic(str(item)):
            found = sorted(Path(f) for f in glob.glob(str(item)) if Path(f).is_file())
        elif p.is_file():
            found = [p]
        else:
            raise ValueError(f"case: {item}: no such file, folder or matching pattern")
        if not found:
            raise ValueError(f"case: {item}: matches no case file (expected {' or '.join(CASE_SUFFIXES)} files)")
        out.extend(f.resolve() for f in found)
    out = list(dict.fromkeys(out))
    stems: dict[str, Path] = {}
    for f in out:
        if f.stem in stems:
            raise ValueError(f"case: {stems[f.stem]} and {f} share the name {f.stem!r}; their outputs would collide")
        stems[f.stem] = f
    return out
