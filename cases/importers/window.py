"""Selection of a time window and decimation of pings at import (long files calibrate slowly)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Window:
    """Which pings to import.

    Parameters
    ----------
    start_s, end_s : float, optional
        Keep pings with start_s <= t - t_first <= end_s (seconds from the file's first ping).
    every : int
        Keep every ``every``-th ping of those (1: all).
    """

    start_s: float | None = None
    end_s: float | None = None
    every: int = 1

    def __post_init__(self):
        if int(self.every) < 1:
            raise ValueError(f"every: expected an integer >= 1, got {self.every}")
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise ValueError(f"end_s: expected > start_s ({self.start_s}), got {self.end_s}")


def select(t_abs: np.ndarray, window: Window, source: str) -> tuple[np.ndarray, str]:
    """Mask of kept pings (finite, strictly increasing times inside the window) and a note."""
    t = np.asarray(t_abs, dtype=np.float64)
    ok = np.isfinite(t)
    if not ok.any():
        raise ValueError(f"{source}: time: expected finite ping times, got none")
    running = np.maximum.accumulate(np.where(ok, t, -np.inf))
    ok &= np.concatenate([[True], t[1:] > running[:-1]])
    rel = t - t[ok][0]
    if window.start_s is not None:
        ok &= rel >= window.start_s
    if window.end_s is not None:
        ok &= rel <= window.end_s
    idx = np.flatnonzero(ok)[:: int(window.every)]
    if idx.size < 2:
        raise ValueError(f"{source}: selection: expected at least 2 pings, got {idx.size} "
                         f"(start_s={window.start_s}, end_s={window.end_s}, every={window.every})")
    keep = np.zeros(t.size, dtype=bool)
    keep[idx] = True
    dropped = int(np.isfinite(t).sum() - (np.isfinite(t) & (np.concatenate([[True], t[1:] > running[:-1]]))).sum())
    note = (f"pings from {window.start_s if window.start_s is not None else 0} s to "
            f"{window.end_s if window.end_s is not None else 'end'}, every {window.every}; "
            f"{idx.size} of {t.size} kept; {dropped} with non-increasing times dropped")
    return keep, note
