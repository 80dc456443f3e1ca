"""A run as its instrument would have recorded it with another sound speed: the salinity fix of a
file whose salinity setting was wrong, and the injection of a sound-speed error, one operation.

Doppler radials and travel-time ranges are both proportional to the sound speed the instrument
assumed, so a factor f on it multiplies every bottom-track and water radial, every slant range and
every cell's distance below the transducer; a water depth derived from the ranges is derived again.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..models.sound_speed import sound_speed_m_s
from .case import Case

SALINITY_RANGE_PSU = (0.0, 45.0)  # the formula's range


def rescale_sound_speed(case: Case, factor: float) -> Case:
    """``case`` recorded with the instrument's sound speed times ``factor`` (see module docstring)."""
    if not np.isfinite(factor) or factor <= 0:
        raise ValueError(f"sound speed factor: expected a finite positive number, got {factor!r}")
    p, w = case.pings, case.water
    out = case.with_recorded_pings(dataclasses.replace(p, bt_radial_m_s=p.bt_radial_m_s * factor,
                                                       bt_range_m=None if p.bt_range_m is None else p.bt_range_m * factor))
    out = out.replace(instrument=dataclasses.replace(case.instrument, sound_speed_m_s=case.instrument.sound_speed_m_s * factor))
    if w is not None:
        z = case.environment.transducer_depth_m
        out = out.replace(water=dataclasses.replace(w, radial_m_s=w.radial_m_s * factor,
                                                    cell_depth_m=z + (w.cell_depth_m - z) * factor))
    return out


def with_salinity(case: Case, salinity_psu: float) -> tuple[Case, str]:
    """``case`` as recorded with ``salinity_psu`` as the salinity setting (the sound speed from the
    recorded temperature, :func:`~adcpdyn.models.sound_speed.sound_speed_m_s`), and a note of what
    changed. Needs the instrument's temperature and salinity setting (``/instrument`` attributes
    ``temperature_c``, ``salinity_psu``, written by the TRDI importer)."""
    lo, hi = SALINITY_RANGE_PSU
    if not (np.isfinite(salinity_psu) and lo <= salinity_psu <= hi):
        raise ValueError(f"--salinity-psu: expected a salinity within {lo:g}-{hi:g} ppt, got {salinity_psu!r}")
    ins = case.instrument
    if ins.temperature_c is None or ins.salinity_psu is None:
        raise ValueError(f"--salinity-psu: {case.name} records no temperature and salinity setting "
                         "(/instrument temperature_c, salinity_psu) to recompute its sound speed from")
    z = case.environment.transducer_depth_m
    old, new = (sound_speed_m_s(ins.temperature_c, s, z) for s in (ins.salinity_psu, salinity_psu))
    factor = new / old
    out = rescale_sound_speed(case, factor)
    out = out.replace(instrument=dataclasses.replace(out.instrument, salinity_psu=float(salinity_psu)))
    note = (f"salinity setting {ins.salinity_psu:g} -> {salinity_psu:g} ppt at {ins.temperature_c:.2f} deg C: sound speed "
            f"{old:.1f} -> {new:.1f} m/s (Medwin); every radial, slant range and cell distance x {factor:.6f}")
    return out, note
