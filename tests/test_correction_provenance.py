"""What a correction applied, typed (CorrectionProvenance): written to the corrected file and read
back, read from files written before it was typed, and the calibrated and entered transducer
depth it carries into the netCDF; the one bed lookup on half-determined beds."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest
from conftest import calibrated_pool_m0

from adcpdyn import api
from adcpdyn.cases.corrected import CorrectionProvenance, read_correction, write_correction
from adcpdyn.cases.io import write_case
from adcpdyn.cases.netcdf import correction_from_file, export_file
from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators.calibration.record import CalibrationRecord, as_record
from adcpdyn.estimators.correction.correct_case import correct_case

xr = pytest.importorskip("xarray")

OFFSET_M = 0.05  # a transducer depth offset the slant ranges found, as a calibration records it per run
BED_M_S = [0.05, -0.15]


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """pool_m0 calibrated (one start); its CALIB.json with pool_m1 as a run of it (a depth offset, a
    site bed), and pool_m1 written as a case file."""
    folder = tmp_path_factory.mktemp("provenance")
    _, path, _ = calibrated_pool_m0(folder, n_starts=1)
    d = json.loads(path.read_text())
    d["runs"][0].update(case="pool_m1", transducer_depth_offset_m=OFFSET_M)
    d["moving_bed_velocity_m_s"], d["moving_bed_velocity_se_m_s"] = BED_M_S, [0.01, 0.01]
    calib = folder / "CALIB_m1.json"
    calib.write_text(json.dumps(d))
    m1 = simulate(get_scenario("pool_m1"), seed=1)
    case_path = folder / "m1.h5"
    write_case(m1, case_path)
    return d, calib, m1, case_path


def test_the_provenance_is_written_and_read_back_typed(setting, tmp_path):
    _, calib, m1, case_path = setting
    result = api.correct(case_path, "adc", calib)
    p = result.provenance
    entered = m1.environment.transducer_depth_m
    assert p.transducer_depth_entered_m == entered
    assert p.transducer_depth_calibrated_m == pytest.approx(entered + OFFSET_M, abs=1e-12)
    assert p.moving_bed_velocity_m_s == tuple(BED_M_S) and "site bed" in p.moving_bed_note
    assert p.calibration_file == str(calib) and len(p.calibration_sha256) == 64 and p.timing == "deep"
    assert np.asarray(p.lever_arms_sensor_m).shape == (4, 3) and p.source_case_name == "pool_m1"
    write_correction(result, tmp_path / "c.h5", source_case=str(case_path))
    back = read_correction(tmp_path / "c.h5")["provenance"]
    assert back == p  # every field, typed
    with h5py.File(tmp_path / "c.h5", "r") as f:  # the on-disk settings: one key per field
        settings = json.loads(f["corrected"].attrs["settings"])
    assert set(settings) == {f.name for f in dataclasses.fields(CorrectionProvenance)}
    with pytest.raises(TypeError):
        p.replace(no_such_field=1)


def test_netcdf_carries_the_calibrated_and_the_entered_transducer_depth_from_a_corrected_file(setting, tmp_path):
    """Through the corrected HDF5 and `export`: the depth the velocities were computed with, and the
    one entered, named; without an offset only the entered depth."""
    d, calib, m1, case_path = setting
    entered = m1.environment.transducer_depth_m
    api.correct(case_path, "adc", calib, out=tmp_path / "c.h5")
    export_file(tmp_path / "c.h5", tmp_path / "c.nc")
    with xr.open_dataset(tmp_path / "c.nc", engine="h5netcdf") as ds:
        adcp = ds["adcp"].attrs  # the instrument's container variable
        assert adcp["transducer_depth_m"] == pytest.approx(entered + OFFSET_M, abs=1e-12)
        assert "calibrated" in adcp["transducer_depth_comment"]
        assert adcp["transducer_depth_entered_m"] == entered
    plain = dict(d, runs=[{**d["runs"][0], "transducer_depth_offset_m": None}])
    result = api.correct(case_path, "adc", plain)
    assert result.provenance.transducer_depth_calibrated_m is None
    with api.to_xarray(case_path, result) as ds:
        adcp = ds["adcp"].attrs
        assert adcp["transducer_depth_m"] == entered and "transducer_depth_entered_m" not in adcp
        assert "calibrated" not in adcp["transducer_depth_comment"]


def test_a_corrected_file_written_before_the_provenance_was_typed_still_reads(setting, tmp_path):
    """The settings JSON as earlier versions wrote it: only the keys that applied, the compass
    deviation as the calibration's object (null: not determined), no entered depth, a key of its own."""
    _, calib, m1, case_path = setting
    path = tmp_path / "old.h5"
    write_correction(api.correct(case_path, "asc"), path, source_case=str(case_path))
    old = {"installation_ypr_rad": [0.0, 0.0, 0.0], "heading_misalignment_applied_rad": 0.1,
           "compass_deviation_applied_rad": {"sin": 0.01, "cos": None, "mean_sin": 0.2, "mean_cos": 0.3},
           "magnetic_declination_rad": None, "compass_error_rad": None, "heading_correction_note": "true heading = ...",
           "transducer_depth_note": "offset", "transducer_depth_calibrated_m": 0.75,
           "moving_bed_velocity_m_s": [0.05, -0.15], "moving_bed_note": "site bed", "warnings": ["a note"],
           "calibration_file": str(calib), "calibration_sha256": "ab" * 32, "calibration_provenance": {"cases": []},
           "source_case_name": "pool_m1", "source_case_file": str(case_path), "source_case_sha256": None,
           "a_key_of_that_version": {"x": 1}}
    with h5py.File(path, "r+") as f:
        f["corrected"].attrs["settings"] = json.dumps(old)
    corr, source = correction_from_file(path)
    p = corr.provenance
    assert source == str(case_path) and p.heading_misalignment_applied_rad == 0.1
    assert p.compass_deviation_applied_rad == (0.01, 0.0, 0.2, 0.3)  # null: not applied
    assert p.moving_bed_velocity_m_s == (0.05, -0.15) and p.warnings == ("a note",)
    assert p.transducer_depth_entered_m is None and p.water_reference is None and p.timing is None
    export_file(path, tmp_path / "old.nc")
    with xr.open_dataset(tmp_path / "old.nc", engine="h5netcdf") as ds:
        assert ds["adcp"].attrs["transducer_depth_m"] == 0.75
        assert ds["adcp"].attrs["transducer_depth_entered_m"] == m1.environment.transducer_depth_m  # the case's
        assert ds.attrs["heading_misalignment_deg"] == pytest.approx(np.rad2deg(0.1))
        assert ds.attrs["moving_bed_velocity_north_east_m_s"] == "[0.05, -0.15]"
        assert ds.attrs["calibration_sha256"] == "ab" * 32 and ds.attrs["magnetic_declination_deg"] == "not determined"


@pytest.mark.parametrize("own, site, expected", [
    ([0.04, None], BED_M_S, (BED_M_S, "site bed")),  # the run's own is half-determined: the site's
    ([0.04, None], [None, -0.15], (None, "")),  # both half-determined: none, never NaN
    ([0.04, 0.02], [None, -0.15], ([0.04, 0.02], "run 'pool_m1'")),  # the run's own, whatever the site's
    (None, [0.05, None], (None, "")),  # no bed of its own, the site's half-determined
])
def test_the_one_bed_lookup_on_half_determined_beds(setting, own, site, expected):
    d, _, m1, _ = setting
    d = dict(d, moving_bed_velocity_m_s=site, moving_bed_velocity_se_m_s=None,
             runs=[{**d["runs"][0], "moving_bed_velocity_m_s": own, "transducer_depth_offset_m": None}])
    record = CalibrationRecord.from_dict(d)
    bed, source = record.moving_bed_for("pool_m1")
    want, words = expected
    assert (bed is None and want is None) or bed.tolist() == want
    assert words in source
    none = as_record(dict(d, moving_bed_velocity_m_s=None, runs=[{**d["runs"][0], "moving_bed_velocity_m_s": None}]))
    plain = correct_case(m1, "asc", none).vessel_velocity_m_s
    v = correct_case(m1, "asc", record).vessel_velocity_m_s
    assert np.array_equal(np.isfinite(v), np.isfinite(plain))  # a bed never blanks a velocity
    added = np.zeros(2) if want is None else np.array(want)
    np.testing.assert_allclose(v[:, :2] - plain[:, :2], np.tile(added, (m1.pings.n, 1)), atol=1e-12)
