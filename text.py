"""Terminal text a hydrographer reads at a glance: fixed-width tables no wider than
:data:`TABLE_WIDTH` characters, a unit under every number column, the abbreviations explained
under the table, noise levels with their units, and prose lines wrapped to the same width.

A table too wide for :data:`TABLE_WIDTH` is printed as blocks of columns, each block
repeating the first column, rather than wrapped by the terminal.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass
from typing import Callable

import numpy as np

TABLE_WIDTH = 100  # characters: every line a table prints
GAP = "  "  # between columns (one space when that is what fits the width)
NOT_A_NUMBER = "n/a"

NOISE_UNITS = {"bt": "m/s", "reference": "m/s", "vertical": "m/s", "range": "m", "motion": "m/s/sqrt(s)"}
ANGLE_GROUPS = ("heading", "pitch", "roll")  # noise levels held in radians, printed in degrees


@dataclass(frozen=True)
class Column:
    """One number column: its header, its unit (printed under the header), how a value is written.

    ``scale`` multiplies the stored value (e.g. 1000 for m/s shown in mm/s); ``decimals`` are the
    digits after the point, at most; with ``significant`` the column keeps only as many as give its
    largest value that many significant digits (0.390 m and 1035 m, never 1034.567 m); ``spec``, a
    format specification (``".3g"``, ``".1e"``, ``"d"``), replaces both.
    """

    key: str
    head: str
    unit: str
    decimals: int = 1
    scale: float = 1.0
    significant: int | None = None
    spec: str | None = None

    def value(self, raw) -> float:
        try:
            return float(raw) * self.scale
        except (TypeError, ValueError):
            return float("nan")

    def decimals_for(self, raws) -> int:
        """The digits after the point for a column of these (stored) values."""
        if self.significant is None:
            return self.decimals
        big = max((abs(v) for v in map(self.value, raws) if math.isfinite(v)), default=0.0)
        if big == 0.0:
            return self.decimals
        return int(min(self.decimals, max(0, self.significant - 1 - math.floor(math.log10(big)))))

    def text(self, raw, decimals: int | None = None) -> str:
        v = self.value(raw)
        if not math.isfinite(v):
            return NOT_A_NUMBER
        if self.spec == "d":
            return f"{round(v):d}"
        if self.spec is not None:
            return f"{v:{self.spec}}"
        return f"{v:.{self.decimals if decimals is None else decimals}f}"


def text_table(rows: dict, columns: list, first: str = "method", legend: str = "",
               width: int = TABLE_WIDTH, cell: Callable | None = None) -> str:
    """Rows (name -> {key: value}) as right-aligned columns under a header and a unit line.

    Columns are two spaces apart, one when that makes the table fit in ``width`` characters;
    columns that still do not fit go to a further block below, which repeats the first column; ``legend`` (the abbreviations in words) is wrapped to ``width`` under the
    table. ``cell(column, name, value)`` may replace a cell's text (default :meth:`Column.text`).
    """
    if width < 20:
        raise ValueError(f"width: expected at least 20 characters, got {width}")
    names = [str(n) for n in rows]
    name_w = max([len(first)] + [len(n) for n in names])
    cells = {}
    for c in columns:
        raws = [r.get(c.key) for r in rows.values()]
        decimals = c.decimals_for(raws)
        cells[c.key] = [cell(c, n, v) if cell else c.text(v, decimals) for n, v in zip(names, raws)]
    widths = {c.key: max([len(c.head), len(c.unit)] + [len(t) for t in cells[c.key]]) for c in columns}
    total = name_w + sum(widths.values())
    gap = GAP if total + len(GAP) * len(columns) <= width or total + len(columns) > width else " "  # narrower, not split
    blocks, block, used = [], [], name_w
    for c in columns:
        need = len(gap) + widths[c.key]
        if block and used + need > width:
            blocks.append(block)
            block, used = [], name_w
        block.append(c)
        used += need
    if block:
        blocks.append(block)
    out = []
    for k, block in enumerate(blocks):
        if k:
            out.append("")
        out.append(f"{first:<{name_w}}" + "".join(f"{gap}{c.head:>{widths[c.key]}}" for c in block))
        out.append(f"{'':<{name_w}}" + "".join(f"{gap}{c.unit:>{widths[c.key]}}" for c in block))
        for i, n in enumerate(names):
            out.append(f"{n:<{name_w}}" + "".join(f"{gap}{cells[c.key][i]:>{widths[c.key]}}" for c in block))
    if legend:
        out += textwrap.wrap(legend, width=width, subsequent_indent="  ")
    return "\n".join(line.rstrip() for line in out)


def prose(line: str, width: int = TABLE_WIDTH, indent: str = "    ") -> str:
    """A line of words wrapped to ``width`` characters, its continuation lines indented, words
    (numbers, names, paths) never split: a headline's value stays on its first line."""
    if len(line) <= width:
        return line
    return "\n".join(textwrap.wrap(line, width=width, subsequent_indent=indent, break_long_words=False,
                                    break_on_hyphens=False))


def noise_level_text(key: str, value: float) -> str:
    """One noise level with its unit: ``bt 0.0637 m/s``, ``heading 0.5 deg`` (held in radians);
    a run's prefix (``run01/bt``) is kept."""
    group = key.rpartition("/")[2]
    if group in ANGLE_GROUPS:
        return f"{key} {np.degrees(value):.3g} deg"
    return f"{key} {value:.3g} {NOISE_UNITS.get(group, '')}".rstrip()


def noise_levels_line(sigma: dict) -> str:
    """The noise levels with their units: angles in degrees, velocities in m/s, ranges in m."""
    return "noise levels (one standard deviation): " + ", ".join(
        noise_level_text(k, v) for k, v in sigma.items() if v is not None)
