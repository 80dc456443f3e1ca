"""The optional position group, the case clock's UTC origin and the per-ping bed velocity in /truth."""

from __future__ import annotations

import dataclasses
import datetime as dt

import h5py
import numpy as np
import pytest
from test_case_io import N, assert_same, make_case

from adcpdyn.cases.case import Position, format_utc, parse_utc
from adcpdyn.cases.checks import CaseFormatError
from adcpdyn.cases.io import read_case, write_case

P = 7


def with_site(case):
    t = np.linspace(-0.5, 19.5, P)
    truth = dataclasses.replace(case.truth, moving_bed_velocity_m_s=np.tile([0.05, -0.2, 0.0], (N, 1)))
    return case.replace(position=Position(time_s=t, latitude_deg=64.5620123456789 + 1e-6 * t,
                                          longitude_deg=-149.0660987654321 - 2e-6 * t),
                        time_origin_utc="2022-08-19T20:14:21.250000Z", truth=truth)


@pytest.fixture
def site_file(tmp_path):
    path = tmp_path / "site.h5"
    write_case(with_site(make_case()), path)
    return path


def test_round_trip_bit_for_bit(tmp_path):
    case = with_site(make_case())
    write_case(case, tmp_path / "a.h5")
    back = read_case(tmp_path / "a.h5")
    assert_same(case, back)
    assert back.position.latitude_deg.dtype == np.float64  # float64 keeps GNSS to the millimetre
    with h5py.File(tmp_path / "a.h5") as f:
        assert "position" in f and f.attrs["time_origin_utc"] == "2022-08-19T20:14:21.250000Z"
        assert f["truth/moving_bed_velocity_m_s"].shape == (N, 3)


def test_absent_by_default(tmp_path):
    write_case(make_case(), tmp_path / "b.h5")
    back = read_case(tmp_path / "b.h5")
    assert back.position is None and back.time_origin_utc is None and back.truth.moving_bed_velocity_m_s is None
    with h5py.File(tmp_path / "b.h5") as f:
        assert "position" not in f and "time_origin_utc" not in f.attrs


def test_utc_text():
    when = parse_utc("2022-08-19T20:14:21Z")
    assert when == dt.datetime(2022, 8, 19, 20, 14, 21, tzinfo=dt.timezone.utc)
    assert parse_utc("2022-08-19T12:14:21-08:00") == when  # an offset is converted
    assert parse_utc("2022-08-19T20:14:21") == when  # no offset: UTC
    assert parse_utc(format_utc(when)) == when
    assert format_utc(dt.datetime(2010, 9, 23, 1, 2, 3, 500000)) == "2010-09-23T01:02:03.500000Z"


def _set(path, index, value):
    def edit(f):
        a = f[path][()].copy()
        a[index] = value
        del f[path]
        f[path] = a
    return edit


def _attr(value):
    def edit(f):
        f.attrs["time_origin_utc"] = value
    return edit


def _drop(path):
    def edit(f):
        del f[path]
    return edit


MALFORMED = {
    "latitude beyond 90": (_set("position/latitude_deg", 2, 95.0), "/position/latitude_deg", "|latitude| <= 90"),
    "longitude beyond 180": (_set("position/longitude_deg", 0, 200.0), "/position/longitude_deg", "|longitude| <= 180"),
    "latitude NaN": (_set("position/latitude_deg", 1, np.nan), "/position/latitude_deg", "finite"),
    "time not increasing": (_set("position/time_s", 3, 0.0), "/position/time_s", "strictly increasing"),
    "longitude wrong length": (lambda f: (_drop("position/longitude_deg")(f),
                                          f["position"].create_dataset("longitude_deg", data=np.zeros(P - 1))),
                               "/position/longitude_deg", f"P={P}"),
    "missing latitude": (_drop("position/latitude_deg"), "/position/latitude_deg", "missing"),
    "time origin not ISO": (_attr("19/08/2022 20:14"), '/.attrs["time_origin_utc"]', "ISO 8601"),
    "time origin a number": (_attr(3.0), '/.attrs["time_origin_utc"]', "string"),
    "bed velocity wrong shape": (lambda f: (_drop("truth/moving_bed_velocity_m_s")(f),
                                            f["truth"].create_dataset("moving_bed_velocity_m_s", data=np.zeros((N, 2)))),
                                 "/truth/moving_bed_velocity_m_s", "(N, 3)"),
}


@pytest.mark.parametrize("kind", list(MALFORMED))
def test_malformed_rejected_in_one_line(site_file, kind):
    edit, field, words = MALFORMED[kind]
    with h5py.File(site_file, "r+") as f:
        edit(f)
    with pytest.raises(CaseFormatError) as info:
        read_case(site_file)
    msg = str(info.value)
    assert msg.startswith(f"{site_file}: {field}: "), msg
    assert words in msg and "\n" not in msg


def test_invalid_in_memory_not_written(tmp_path):
    bad = with_site(make_case())
    bad = bad.replace(position=dataclasses.replace(bad.position, latitude_deg=bad.position.latitude_deg + 30.0))
    with pytest.raises(CaseFormatError, match=r"^.*: /position/latitude_deg: expected degrees"):
        write_case(bad, tmp_path / "x.h5")
    assert not (tmp_path / "x.h5").exists()
