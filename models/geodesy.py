"""Latitude and longitude <-> a local tangent plane (north, east in metres) on the WGS84 ellipsoid.

Over a river section or a GNSS track (kilometres), the plane through a reference point
with the ellipsoid's meridian and prime-vertical radii of curvature there is exact to
well below GNSS noise; it is the one conversion used by the GNSS importer (velocities
from differenced fixes) and the simulator (positions of a simulated track).
"""

from __future__ import annotations

import numpy as np

WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3


def radii_of_curvature_m(latitude_rad):
    """(meridian radius M, prime-vertical radius N) of WGS84 at a latitude, metres."""
    s2 = np.sin(latitude_rad) ** 2
    r_n = WGS84_A / np.sqrt(1 - WGS84_E2 * s2)
    r_m = r_n * (1 - WGS84_E2) / (1 - WGS84_E2 * s2)
    return r_m, r_n


def local_north_east_m(latitude_deg, longitude_deg, latitude0_deg, longitude0_deg):
    """(north, east) metres of points from the reference point (latitude0, longitude0)."""
    lat0 = np.deg2rad(latitude0_deg)
    r_m, r_n = radii_of_curvature_m(lat0)
    return (np.deg2rad(latitude_deg - latitude0_deg) * r_m,
            np.deg2rad(longitude_deg - longitude0_deg) * r_n * np.cos(lat0))


def latitude_longitude_deg(north_m, east_m, latitude0_deg, longitude0_deg):
    """Inverse of :func:`local_north_east_m`: (latitude, longitude) degrees, longitude in [-180, 180)."""
    lat0 = np.deg2rad(latitude0_deg)
    r_m, r_n = radii_of_curvature_m(lat0)
    lat = latitude0_deg + np.rad2deg(np.asarray(north_m, dtype=float) / r_m)
    lon = longitude0_deg + np.rad2deg(np.asarray(east_m, dtype=float) / (r_n * np.cos(lat0)))
    return lat, np.mod(lon + 180.0, 360.0) - 180.0
