"""Magnetic declination (IGRF-14 through ppigrf) and the declination of a case."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from test_case_io import make_case

from adcpdyn.cases.case import Position
from adcpdyn.cases.site import case_declination, case_site
from adcpdyn.models.geomagnetism import magnetic_declination_rad

DECLINATION_TOL_DEG = 0.5  # WMM and IGRF are separate models of the same main field: they agree to ~0.1 deg

# NOAA NCEI / BGS, "WMM2020 Test Values" (WMM2020testvalues.pdf, published with the World Magnetic
# Model 2020): declination at height 0 for decimal years 2020.0 and 2022.5. An independent model and
# an independent computation of the same main field.
WMM2020_TEST_VALUES = [
    (dt.datetime(2020, 1, 1), 80.0, 0.0, -1.28),
    (dt.datetime(2020, 1, 1), 0.0, 120.0, 0.16),
    (dt.datetime(2020, 1, 1), -80.0, 240.0, 69.36),
    (dt.datetime(2022, 7, 2, 12), 80.0, 0.0, 0.01),
    (dt.datetime(2022, 7, 2, 12), 0.0, 120.0, -0.06),
    (dt.datetime(2022, 7, 2, 12), -80.0, 240.0, 69.13),
]


@pytest.mark.parametrize("when, lat, lon, published_deg", WMM2020_TEST_VALUES)
def test_declination_matches_published_values(when, lat, lon, published_deg):
    assert abs(np.rad2deg(magnetic_declination_rad(lat, lon, when)) - published_deg) < DECLINATION_TOL_DEG


def test_sign_east_positive():
    """Alaska has an easterly declination, New England a westerly one (isogonic charts)."""
    when = dt.datetime(2020, 1, 1)
    assert magnetic_declination_rad(64.56, -149.07, when) > np.deg2rad(10)
    assert magnetic_declination_rad(44.92, -66.99, when) < -np.deg2rad(10)


@pytest.mark.slow  # 7 s: `make test-slow`, CI's second step
def test_finite_everywhere_and_periodic_in_longitude():
    when = dt.datetime(2015, 3, 1)
    for lat in np.linspace(-89.5, 89.5, 13):
        for lon in np.linspace(-180.0, 180.0, 13):
            d = magnetic_declination_rad(lat, lon, when)
            assert np.isfinite(d) and abs(d) <= np.pi
            assert d == pytest.approx(magnetic_declination_rad(lat, lon + 360.0, when), abs=1e-9)


@pytest.mark.parametrize("lat, lon", [(64.56, -149.07), (44.92, -66.99), (51.5, -0.13), (-33.87, 151.21)])
def test_changes_slowly_with_date(lat, lon):
    """Secular variation away from the magnetic poles: well under half a degree a year, 2010-2026."""
    years = np.arange(2010, 2027)
    d = np.rad2deg([magnetic_declination_rad(lat, lon, dt.datetime(int(y), 1, 1)) for y in years])
    assert np.max(np.abs(np.diff(d))) < 0.5
    day = magnetic_declination_rad(lat, lon, dt.datetime(2022, 8, 19, 0))
    assert abs(magnetic_declination_rad(lat, lon, dt.datetime(2022, 8, 19, 23)) - day) < np.deg2rad(1e-3)


def test_time_zone_is_converted():
    aware = dt.datetime(2022, 8, 19, 12, 14, tzinfo=dt.timezone(dt.timedelta(hours=-8)))
    assert magnetic_declination_rad(64.5, -149.0, aware) == magnetic_declination_rad(64.5, -149.0,
                                                                                    dt.datetime(2022, 8, 19, 20, 14))


@pytest.mark.parametrize("args, field", [((90.0, 0.0, dt.datetime(2020, 1, 1)), "latitude_deg"),
                                         ((float("nan"), 0.0, dt.datetime(2020, 1, 1)), "latitude_deg"),
                                         ((10.0, float("inf"), dt.datetime(2020, 1, 1)), "longitude_deg"),
                                         ((10.0, 0.0, dt.datetime(2031, 1, 1)), "when_utc"),
                                         ((10.0, 0.0, dt.datetime(1899, 1, 1)), "when_utc")])
def test_outside_the_model_rejected(args, field):
    with pytest.raises(ValueError, match=f"^{field}: expected"):
        magnetic_declination_rad(*args)


def test_case_declination_at_median_fix_and_mid_run():
    case = make_case()  # pings 0..19 s
    none, why = case_declination(case)
    assert none is None and "/position" in why and "time_origin_utc" in why
    t = np.linspace(0.0, 19.0, 5)
    pos = Position(time_s=t, latitude_deg=np.array([64.0, 64.1, 64.2, 64.9, 65.0]),
                   longitude_deg=np.array([179.9, 179.95, -179.99, -179.9, 179.8]))
    none, why = case_declination(case.replace(position=pos))
    assert none is None and "time_origin_utc" in why and "/position" not in why
    case = case.replace(position=pos, time_origin_utc="2020-01-01T23:59:50.5Z")
    lat, lon, when = case_site(case)
    assert lat == 64.2 and lon == pytest.approx(179.95)  # the median across the date line
    assert when == dt.datetime(2020, 1, 2, 0, 0, 0, tzinfo=dt.timezone.utc)  # 9.5 s after 23:59:50.5
    value, note = case_declination(case)
    assert value == magnetic_declination_rad(64.2, 179.95, dt.datetime(2020, 1, 2))
    assert "IGRF-14" in note and "64.20000 N" in note
