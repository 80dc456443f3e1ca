"""Site-dependent corrections of a case: the magnetic declination where and when it was measured."""

from __future__ import annotations

import datetime as dt

import numpy as np

from ..models.geomagnetism import magnetic_declination_rad
from .case import Case, parse_utc


def case_site(case: Case) -> tuple[float, float, dt.datetime] | None:
    """(median latitude, median longitude (degrees), UTC at mid-run) of a case, or None
    when it has no ``/position`` or no ``time_origin_utc``."""
    if case.position is None or case.time_origin_utc is None:
        return None
    lat = float(np.median(case.position.latitude_deg))
    lon = np.asarray(case.position.longitude_deg, dtype=float)
    lon0 = lon[0]  # the median about the first fix: a track across +-180 degrees stays together
    lon = float(np.mod(lon0 + np.median(np.mod(lon - lon0 + 180.0, 360.0) - 180.0) + 180.0, 360.0) - 180.0)
    t = case.pings.time_s
    mid = 0.5 * (float(t[0]) + float(t[-1]))
    return lat, lon, parse_utc(case.time_origin_utc) + dt.timedelta(seconds=mid)


def case_declination(case: Case) -> tuple[float | None, str]:
    """Magnetic declination (radians, east positive) at a case's median position and
    mid-run UTC time, IGRF-14, with a note saying where and when; ``(None, reason)``
    when the case lacks a position or a UTC time origin."""
    site = case_site(case)
    if site is None:
        missing = [what for what, absent in (("/position (GNSS fixes)", case.position is None),
                                             ('/.attrs["time_origin_utc"] (the clock\'s UTC)',
                                              case.time_origin_utc is None)) if absent]
        return None, "declination not computed: the case has no " + " and no ".join(missing)
    lat, lon, when = site
    value = magnetic_declination_rad(lat, lon, when)
    return value, (f"IGRF-14 declination {np.rad2deg(value):+.2f} deg (east positive) at {lat:.5f} N, "
                   f"{lon:.5f} E on {when:%Y-%m-%d %H:%M} UTC (median fix, mid-run)")
