"""Magnetic declination from the International Geomagnetic Reference Field (IGRF-14).

A compass reads the heading from magnetic north; true heading = magnetic heading +
declination D, with D = atan2(B_east, B_north) of the main field at the site (east
positive). The field comes from ``ppigrf`` (pure Python, IGRF-14 coefficients, valid
1900-2030 with the predictive secular variation after 2025). The declination is a
property of the site and the date, not of the instrument; local crustal anomalies and
a disturbed field (storms) are not in the model (typically well under 0.5 degrees).
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np

IGRF_FIRST_UTC = dt.datetime(1900, 1, 1)
IGRF_END_UTC = dt.datetime(2030, 1, 1)  # end of IGRF-14's secular variation


def _naive_utc(when_utc) -> dt.datetime:
    if not isinstance(when_utc, dt.datetime):
        raise TypeError(f"when_utc: expected a datetime, got {type(when_utc).__name__}")
    if when_utc.tzinfo is not None:
        when_utc = when_utc.astimezone(dt.timezone.utc).replace(tzinfo=None)
    return when_utc


def magnetic_field_enu_nt(latitude_deg: float, longitude_deg: float, when_utc: dt.datetime,
                          height_m: float = 0.0) -> np.ndarray:
    """IGRF-14 main field (east, north, up) in nT at a geodetic position and a UTC time.

    Parameters
    ----------
    latitude_deg, longitude_deg : float
        WGS84 geodetic latitude (|lat| < 90: the declination is undefined at the poles)
        and longitude (east positive), degrees.
    when_utc : datetime
        UTC time (a naive datetime is taken as UTC), 1900-01-01 to 2030-01-01.
    height_m : float
        Height above the ellipsoid.

    Raises
    ------
    ValueError
        A position or time outside the model's domain (one line naming the argument).
    """
    lat, lon, h = float(latitude_deg), float(longitude_deg), float(height_m)
    if not (math.isfinite(lat) and abs(lat) < 90.0):
        raise ValueError(f"latitude_deg: expected a finite latitude with |latitude| < 90 "
                         f"(the declination is undefined at the poles), got {latitude_deg!r}")
    if not math.isfinite(lon):
        raise ValueError(f"longitude_deg: expected a finite longitude, got {longitude_deg!r}")
    if not math.isfinite(h):
        raise ValueError(f"height_m: expected a finite height, got {height_m!r}")
    when = _naive_utc(when_utc)
    if not IGRF_FIRST_UTC <= when < IGRF_END_UTC:
        raise ValueError(f"when_utc: expected a time in IGRF-14's span {IGRF_FIRST_UTC:%Y-%m-%d} to "
                         f"{IGRF_END_UTC:%Y-%m-%d}, got {when.isoformat()}")
    import ppigrf  # imported here: it loads pandas

    east, north, up = ppigrf.igrf(lon, lat, h / 1e3, when)
    return np.array([float(np.ravel(east)[0]), float(np.ravel(north)[0]), float(np.ravel(up)[0])])


def magnetic_declination_rad(latitude_deg: float, longitude_deg: float, when_utc: dt.datetime,
                             height_m: float = 0.0) -> float:
    """Declination D = atan2(B_east, B_north) (radians, east positive): true = magnetic + D.

    See :func:`magnetic_field_enu_nt` for the arguments and errors.
    """
    east, north, _ = magnetic_field_enu_nt(latitude_deg, longitude_deg, when_utc, height_m)
    return float(math.atan2(east, north))
