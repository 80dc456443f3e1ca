"""CALIB.json as a typed record (CalibrationResult.from_json), the one conversion of every form a
calibration is handed over in (as_record), what its readers use, and CALIB.json's provenance."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.estimators.calibration.record import CalibrationRecord, as_record
from adcpdyn.estimators.calibration.result import CalibrationResult
from adcpdyn.estimators.correction.correct_case import correct_case
from adcpdyn.cases.simulation import simulate
from conftest import calibrated_pool_m0


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """pool_m0 calibrated (2 starts), its CALIB.json, and pool_m1 to correct."""
    result, path, _ = calibrated_pool_m0(tmp_path_factory.mktemp("record"), n_starts=2)
    return result, path, simulate(get_scenario("pool_m1"), seed=1)


def test_every_form_of_a_calibration_is_read_into_one_record_with_the_same_numbers(calibrated):
    """The result, its dict, its file (path or text) and its record: one record, the same corrections."""
    result, path, m1 = calibrated
    forms = {"result": result, "dict": result.to_dict(), "path": path, "str": str(path),
             "record": CalibrationResult.from_json(path), "parsed file": json.loads(path.read_text())}
    for method in ("asc", "adc"):
        out = {k: correct_case(m1, method, as_record(c)).vessel_velocity_m_s for k, c in forms.items()}
        assert np.isfinite(out["path"]).all()
        for k, v in out.items():
            np.testing.assert_array_equal(v, out["path"], err_msg=f"{method} with the {k}")
    with pytest.raises(ValueError, match=r"^calibration: expected a CALIB.json path, a dict, a CalibrationResult"):
        as_record(3.0)
    with pytest.raises(ValueError, match=r"^calibration .*nope.json: cannot read the file"):
        as_record(path.parent / "nope.json")
    assert as_record(None) is None
    record = as_record(path)
    assert as_record(record) is record and record.source == str(path)


def test_from_json_round_trip(calibrated):
    result, path, _ = calibrated
    rec = CalibrationResult.from_json(path)
    assert isinstance(rec, CalibrationRecord) and rec.source == str(path)
    assert rec.schema_version == 3 and rec.attitude_frame == result.attitude_frame == "transducer"
    determined = np.isfinite(result.lever_arms_sensor_se_m)
    assert determined.any()
    np.testing.assert_array_equal(rec.lever_arms_m[determined], result.lever_arms_sensor_m[determined])
    assert np.all(np.isnan(rec.lever_arms_m[~determined]))
    np.testing.assert_array_equal(rec.lever_arms_se_m, result.lever_arms_sensor_se_m)
    assert rec.attitude_model.to_dict() == json.loads(json.dumps(result.attitude.to_dict()))
    assert rec.attitude_source == result.attitude_source and rec.success == result.success
    assert rec.noise_sigma == json.loads(json.dumps(result.noise_sigma))
    assert [r.case for r in rec.runs] == [r.case for r in result.runs] == ["pool_m0"]
    assert rec.runs[0].attitude_model is not None
    assert rec.runs[0].navigation == result.runs[0].navigation == "knots"  # the base it was fitted on, per run
    assert rec.heading_misalignment_rad is None  # a run at rest: no course to turn onto
    assert rec.data["schema_version"] == 3 and as_record(rec) is rec


def test_calibration_json_records_its_provenance(calibrated):
    result, path, _ = calibrated
    from adcpdyn.cases.hashing import adcpdyn_version

    prov = json.loads(path.read_text())["provenance"]
    assert prov["adcpdyn_version"] == adcpdyn_version() and prov["written_utc"].endswith("Z")
    assert prov["cases"] == [{"name": "pool_m0"}]  # in memory: no file to hash
    result.provenance = {"cases": [{"name": "pool_m0", "path": "m0.h5", "sha256": "ab" * 32}]}
    try:
        assert result.to_dict()["provenance"]["cases"][0]["sha256"] == "ab" * 32
    finally:
        result.provenance = {}


def test_record_types_a_survey_calibration():
    """Head sensor, misalignment, compass deviation, per-run beds, nulls: typed as the estimators read them."""
    d = {"schema_version": 2, "attitude_frame": "transducer", "radius_vectors_m": [[0.1, 0.0, 0.5]] * 4,
         "radius_vectors_head_m": [[0.2, None, 0.4]] * 4, "installation_ypr_rad": [0.2, None, None],
         "heading_misalignment_rad": 0.2, "heading_misalignment_se_rad": 0.01, "magnetic_declination_rad": 0.27,
         "compass_error_rad": -0.07, "compass_deviation_rad": {"sin": 0.004, "cos": -0.002, "mean_sin": 0.68,
                                                                 "mean_cos": -0.16},
         "compass_deviation_se_rad": {"sin": 0.01, "cos": 0.0},
         "moving_bed": {"model": "constant"}, "moving_bed_velocity_m_s": [0.05, -0.15],
         "runs": [{"case": "run01", "moving_bed_velocity_m_s": [0.04, None], "transducer_depth_offset_m": 0.02},
                  {"case": "run02", "moving_bed_velocity_m_s": [0.06, -0.14]}]}
    rec = CalibrationRecord.from_dict(d)
    assert rec.lever_arms_m[0, 0] == 0.2 and np.isnan(rec.lever_arms_m[0, 1])
    assert rec.radius_vectors_m[0].tolist() == [0.1, 0.0, 0.5]
    assert rec.heading_misalignment_rad == 0.2 and rec.magnetic_declination_rad == 0.27
    assert rec.compass_deviation_rad == (0.004, -0.002) and rec.compass_deviation_centre == (0.68, -0.16)
    assert rec.compass_deviation_se_rad == (0.01, 0.0)
    assert rec.moving_bed == "constant" and rec.provenance == {}
    assert rec.moving_bed_for("run02")[0].tolist() == [0.06, -0.14]
    assert rec.moving_bed_for("run01")[0].tolist() == [0.05, -0.15]  # its own is not determined: the site's
    assert rec.run_for("run01").transducer_depth_offset_m == 0.02 and rec.run_for("nope") is None
    with pytest.raises(ValueError, match=r"^calibration: runs\[1\].moving_bed_velocity_m_s\[0\]: expected"):
        CalibrationRecord.from_dict({**d, "runs": [{"case": "x", "moving_bed_velocity_m_s": [0.0, 0.0]},
                                                   {"case": "y", "moving_bed_velocity_m_s": [9.0, 0.0]}]})


def test_a_run_written_again_under_another_name_is_the_calibrations_run():
    """A transect copied under another name (a field error injected by another tool) is still the
    calibration's run when its pings lie within the calibration's UTC span: its run record and its
    bed are found for it (the diagnosis had tested it for the bed its calibration had already fixed);
    a run outside that span, or without UTC times, is not, and a survey's runs are matched by name only."""
    from types import SimpleNamespace

    d = {"schema_version": 2, "attitude_frame": "transducer", "installation_ypr_rad": [0.0, None, None],
         "moving_bed": {"model": "constant"}, "moving_bed_velocity_m_s": [0.05, -0.15],
         "site": {"latitude_deg": 64.56, "longitude_deg": -149.07, "start_utc": "2022-08-19T20:13:00.000000Z",
                  "end_utc": "2022-08-19T20:17:30.000000Z"},
         "runs": [{"case": "transect", "transducer_depth_offset_m": 0.02, "navigation": "knots"}]}
    rec = CalibrationRecord.from_dict(d)

    def case(name, start_s, end_s, origin="2022-08-19T20:13:00Z"):
        return SimpleNamespace(name=name, time_origin_utc=origin, position=None,
                               pings=SimpleNamespace(n=3, time_s=np.linspace(start_s, end_s, 3)))

    copy = case("transect_compass_2deg", 0.0, 270.0)
    assert rec.holds(copy) and rec.run_of(copy).transducer_depth_offset_m == 0.02 and rec.run_of(copy).navigation == "knots"
    assert rec.moving_bed_for(copy)[1] == "the calibration's site bed (this run's own is not determined)"
    assert rec.applied_to(copy, "transducer", dynamic=False).transducer_depth_offset_m == 0.02  # what `correct` applies
    later = case("next_transect", 300.0, 600.0)
    assert not rec.holds(later) and rec.run_of(later) is None
    assert rec.run_of(case("transect", 300.0, 600.0)).case == "transect"  # its name is enough
    assert not rec.holds(case("copy", 0.0, 270.0, origin=None))
    survey = CalibrationRecord.from_dict({**d, "runs": d["runs"] + [{"case": "other"}]})
    assert survey.holds(copy) and survey.run_of(copy) is None  # within the span, but which of its runs is unknown

