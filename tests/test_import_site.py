"""Positions, the UTC clock origin, heading settings and declination of imported real files."""

from __future__ import annotations

import datetime as dt

import h5py
import numpy as np
import pytest
from conftest import real
from test_import import needs_reader

from adcpdyn.cases.case import parse_utc
from adcpdyn.cases.importers import write_imported
from adcpdyn.cases.io import read_case
from adcpdyn.cases.site import case_declination

DECLINATION_TOL_DEG = 0.1


# Sites and dates from PROVENANCE.md; figures a colleague computed independently for these files.
@needs_reader
@pytest.mark.parametrize("name, lat, lon, date, declination_deg", [
    ("RiverPro_test01.PD0", 64.562, -149.066, dt.date(2022, 8, 19), 15.6),   # Tanana River near Nenana, AK
    ("winriver02_transect.PD0", 64.56, -149.06, dt.date(2010, 9, 23), 20.0),  # Tanana River, AK
    ("winriver01.PD0", 44.92, -66.99, dt.date(2017, 4, 5), -16.75),          # Western Passage, Eastport, ME
])
def test_declination_of_real_files(imported, name, lat, lon, date, declination_deg):
    case, attrs = imported(name)
    pos = case.position
    assert pos is not None and pos.latitude_deg.dtype == np.float64
    assert abs(np.median(pos.latitude_deg) - lat) < 0.01 and abs(np.median(pos.longitude_deg) - lon) < 0.01
    # fixes on the case clock: within the pings (5 s margin), same clock as the reference velocity
    assert pos.time_s[0] >= -5.0 and pos.time_s[-1] <= case.pings.time_s[-1] + 5.0
    origin = parse_utc(case.time_origin_utc)
    assert origin.date() == date
    offset = attrs["/provenance"]["clock_offset_s"]
    adcp0 = np.datetime64(attrs["/provenance"]["time_origin_adcp_clock"]).astype("datetime64[ns]").astype(np.int64) / 1e9
    assert abs(origin.timestamp() - (adcp0 + offset)) < 1e-3  # UTC zero = first ping's ADCP time + clock offset
    value, note = case_declination(case)
    assert abs(np.rad2deg(value) - declination_deg) < DECLINATION_TOL_DEG, note


@needs_reader
def test_file_without_gnss_has_no_site(imported):
    case, attrs = imported("RDI_withBT.000")
    assert case.position is None and case.time_origin_utc is None
    assert attrs["/provenance"]["time_origin_utc_source"].startswith("none")
    value, why = case_declination(case)
    assert value is None and "/position" in why


@needs_reader
def test_heading_settings_recorded_and_written(imported, tmp_path):
    case, attrs = imported("RiverPro_test01.PD0")
    applied = attrs["/provenance"]["heading_settings_applied"]
    assert applied["heading_bias_EB_deg"] == 0.0 and applied["heading_alignment_EA_deg"] == 0.0
    assert applied["EB_in_case_heading"] is True and applied["EA_in_case_heading"] is False
    assert applied["magnetic_variation_in_file"] is False
    out = tmp_path / "rp.h5"
    write_imported(case, attrs, out, source=real("RiverPro_test01.PD0"))
    back = read_case(out)
    assert np.array_equal(back.position.latitude_deg, case.position.latitude_deg)
    assert back.time_origin_utc == case.time_origin_utc
    with h5py.File(out) as f:
        assert '"EB_in_case_heading": true' in f["provenance"].attrs["heading_settings_applied"]
        assert "GGA" in f["position"].attrs["source"]
