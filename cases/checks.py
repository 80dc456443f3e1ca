"""What every check of a case says when it fails: :class:`CaseFormatError`, one line
``<file>: <HDF5 path>: expected ..., got ...``, and the :class:`Checker` that writes it for the
validator (:mod:`.validation`) and the reader (:mod:`.io`) alike. Attributes are named as
``/group.attrs["name"]`` (the root group as ``/.attrs["name"]``).
"""

from __future__ import annotations

import json
import math
import re

import numpy as np

VESSEL_FIELDS = (
    "length_m",
    "beam_m",
    "height_m",
    "mass_kg",
    "draft_m",
    "displaced_volume_m3",
)
SOUND_SPEED_INPUTS = ("temperature_c", "salinity_psu")  # optional /instrument attributes (not in the format: ignored if unreadable)


class CaseFormatError(ValueError):
    """A case file (or in-memory case) does not follow the case format.

    The message is a single line naming the file, the offending field and what was
    expected versus found.
    """


def one_line(text: str) -> str:
    return re.sub(r"\s*[\r\n]+\s*", " ", text)


def number_text(x) -> str:
    """Shortest exact text of a number (``repr`` of the float)."""
    return repr(float(x))


def quoted(x) -> str:
    """A value for a message: strings in double quotes, numpy scalars as plain numbers."""
    if isinstance(x, str):
        return json.dumps(x)
    if isinstance(x, np.generic):
        return repr(x.item())
    return repr(x)


def attr_name(group_name: str, name: str) -> str:
    return f'{group_name}.attrs["{name}"]'


class Checker:
    def __init__(self, source: str):
        self.source = source

    def fail(self, field: str, msg: str):
        raise CaseFormatError(one_line(f"{self.source}: {field}: {msg}"))

    def array(self, x, field: str) -> np.ndarray:
        try:
            a = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError):
            self.fail(field, f"expected a numeric array, got {type(x).__name__}")
        return a

    def shape(self, x, field: str, expected: tuple, spec: str | None = None,
              origin: str = "") -> np.ndarray:
        a = self.array(x, field)
        if a.shape != tuple(expected):
            spec = spec or str(tuple(expected))
            where = f" {origin}" if origin else ""
            self.fail(field, f"expected shape {spec}{where}, got {a.shape}")
        return a

    @staticmethod
    def _index(a: np.ndarray, mask: np.ndarray) -> str:
        idx = np.argwhere(mask)[0]
        return str(int(idx[0])) if a.ndim == 1 else str(tuple(int(i) for i in idx))

    def finite(self, a: np.ndarray, field: str, what: str = "values") -> None:
        bad = ~np.isfinite(a)
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected finite {what}, got {a[bad][0]} at index {i}")

    def no_inf(self, a: np.ndarray, field: str) -> None:
        bad = np.isinf(a)
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected finite values or NaN, got {a[bad][0]} at index {i}")

    def times(self, x, field: str, letter: str) -> np.ndarray:
        a = self.array(x, field)
        if a.ndim != 1:
            self.fail(field, f"expected shape ({letter},), got {a.shape}")
        if a.size == 0:
            self.fail(field, f"expected at least one sample ({letter} >= 1), got 0")
        self.finite(a, field, "times")
        bad = np.flatnonzero(~(np.diff(a) > 0))
        if bad.size:
            i = int(bad[0]) + 1
            self.fail(field, f"expected strictly increasing times, got {number_text(a[i])} at "
                             f"index {i} after {number_text(a[i - 1])} at index {i - 1}")
        return a

    def scalar(self, x, field: str) -> float:
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.number)):
            self.fail(field, f"expected a number, got {quoted(x)}")
        return float(x)

    def positive(self, x, field: str) -> float:
        v = self.scalar(x, field)
        if not (math.isfinite(v) and v > 0):
            self.fail(field, f"expected a finite value > 0, got {number_text(v)}")
        return v

    def non_negative(self, x, field: str) -> float:
        v = self.scalar(x, field)
        if not (math.isfinite(v) and v >= 0):
            self.fail(field, f"expected a finite value >= 0, got {number_text(v)}")
        return v

    def max_abs(self, a: np.ndarray, field: str, limit: float, what: str) -> None:
        bad = np.abs(a) > limit
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected radians with {what}, got {number_text(a[bad][0])} "
                             f"at index {i} (degrees?)")

    def within(self, a: np.ndarray, field: str, low: float, high: float, what: str) -> None:
        """Every finite value within [low, high]; NaN passes (missing)."""
        bad = np.isfinite(a) & ((a < low) | (a > high))
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected {what}, got {number_text(a[bad][0])} at index {i}")

    def string(self, x, field: str) -> str:
        if not isinstance(x, str):
            self.fail(field, f"expected a string, got {quoted(x)}")
        return x

    def instance(self, x, cls, field: str) -> None:
        if not isinstance(x, cls):
            self.fail(field, f"expected {cls.__name__}, got {type(x).__name__}")
