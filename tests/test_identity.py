"""Whose calibration it is: instrument identity in cases and CALIB.json, refused for another
instrument through every verb, warned for another site or season."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import calibrated_pool_m0

from adcpdyn.cases.identity import (InstrumentIdentity, Site, days_apart, distance_km, identity_of,
                                    instrument_difference, site_differences)
from adcpdyn.cases.io import read_case, write_case
from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators.calibration.identity import check_calibration_identity
from adcpdyn.estimators.calibration.record import CalibrationRecord, as_record


def _ident(**changes):
    base = InstrumentIdentity("TRDI", "RiverPro", "1234", 1.2e6, 20.0, 4, "transducer")
    return dataclasses.replace(base, **changes)


def test_instrument_difference_names_what_differs_and_tolerates_what_is_not_known():
    assert instrument_difference(_ident(), _ident()) is None
    assert instrument_difference(_ident(), _ident(serial_number="99")) == "serial number 1234 vs 99"
    assert instrument_difference(_ident(), _ident(make="Nortek")) == "make TRDI vs Nortek"
    # unknown make/serial on one side: the acoustic figures decide (1228.8 kHz is a 1200 kHz head's carrier)
    unknown = _ident(make="", model="", serial_number="")
    assert instrument_difference(_ident(), dataclasses.replace(unknown, frequency_hz=1.2288e6)) is None
    assert instrument_difference(_ident(), dataclasses.replace(unknown, frequency_hz=6e5)) == "frequency 1200 vs 600 kHz"
    assert instrument_difference(_ident(), dataclasses.replace(unknown, beam_angle_deg=30.0)) == "beam angle 20.0 vs 30.0 deg"
    assert InstrumentIdentity.from_dict(_ident().to_dict()) == _ident()


def test_site_distance_and_dates_against_closed_forms():
    a = Site(0.0, 0.0, "2024-05-01T10:00:00Z", "2024-05-01T11:00:00Z")
    b = Site(0.0, 1.0, "2025-06-01T10:00:00Z", "2025-06-01T11:00:00Z")
    assert distance_km(a, b) == pytest.approx(6371.0 * np.radians(1.0), rel=1e-9)  # one degree of the equator
    assert days_apart(a, b) == pytest.approx(396.0 - 1.0 / 24, abs=1e-9)
    assert days_apart(a, a) == 0.0 and distance_km(a, Site(None, None, None, None)) is None
    assert site_differences(a, b) == ["111 km apart (beyond a survey's 50 km)", "396 days apart"]
    assert site_differences(a, Site(0.0, 0.1, None, None)) == []


def test_simulated_and_written_cases_carry_their_instrument(tmp_path):
    case = simulate(get_scenario("pool_m1"), seed=1)
    assert identity_of(case).label() == "adcpdyn simulator pool_boat ADCP SN pool_boat (600 kHz, 30.0 deg, 4 beams)"
    write_case(case, tmp_path / "m1.h5")
    assert identity_of(read_case(tmp_path / "m1.h5")) == identity_of(case)


@pytest.fixture(scope="module")
def pool_calibration(tmp_path_factory):
    return calibrated_pool_m0(tmp_path_factory.mktemp("ident"), n_starts=1)


def test_calibration_records_whose_it_is_and_refuses_another_instrument(pool_calibration, tmp_path):
    result, path, m0 = pool_calibration
    record = CalibrationRecord.from_json(path)
    assert record.instrument == identity_of(m0) and record.schema_version == 3
    assert record.site == Site(None, None, None, None)  # a pool: no GNSS, no UTC; said as null
    cal = as_record(path)
    m1 = simulate(get_scenario("pool_m1"), seed=1)
    assert check_calibration_identity(cal, m1) == []  # the same boat, the same pool, the same day
    launch = simulate(dataclasses.replace(get_scenario("diag_boat"), run=dataclasses.replace(
        get_scenario("diag_boat").run, duration_s=20.0)), seed=1)
    with pytest.raises(ValueError, match=r"^calibration: .*pool_boat .*600 kHz.* but diag_boat was measured with "
                                         r".*survey_launch.*1200 kHz.*--accept-other-instrument"):
        check_calibration_identity(cal, launch)
    assert "applied anyway" in check_calibration_identity(cal, launch, accept_other_instrument=True)[0]
    old = {k: v for k, v in json.loads(path.read_text()).items() if k not in ("instrument", "site")}
    old["schema_version"] = 2
    assert "does not say which instrument" in check_calibration_identity(as_record(old), launch)[0]


def test_every_verb_refuses_another_instruments_calibration_and_writes_nothing(pool_calibration, tmp_path):
    from adcpdyn.cli import main

    _, path, _ = pool_calibration
    sc = get_scenario("diag_boat")
    launch = tmp_path / "launch.h5"
    write_case(simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=1), launch)
    out = tmp_path / "out"
    calls = {"correct": ["correct", str(launch), "--method", "adc", "--calibration", str(path), "--out", f"{out}.h5"],
             "compare": ["compare", str(launch), "--calibration", str(path), "--out", str(out)],
             "diagnose": ["diagnose", str(launch), "--calibration", str(path), "--out", f"{out}.json"]}
    for verb, argv in calls.items():
        assert main(argv) == 2, verb
        assert not list(tmp_path.glob("out*")), verb
    assert main(calls["compare"] + ["--accept-other-instrument"]) == 0  # what it cannot drive is reported, not fatal
    assert (tmp_path / "out").is_dir()


def test_joint_calibration_refuses_two_instruments_and_warns_on_two_sites():
    from adcpdyn.estimators.calibration.config import CalibrationConfig
    from adcpdyn.estimators.calibration.problem import CalibrationProblem

    m0 = simulate(get_scenario("pool_m0"), seed=1)
    sc = get_scenario("diag_boat")
    launch = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=1)
    with pytest.raises(ValueError, match=r"^cases: pool_m0 \(.*\) and diag_boat \(.*\) are two instruments \(serial number"):
        CalibrationProblem([m0, launch], CalibrationConfig(n_starts=1))
    river = get_scenario("river_survey")
    here = simulate(dataclasses.replace(river, run=dataclasses.replace(river.run, duration_s=20.0)), seed=1)
    assert here.position is not None and here.time_origin_utc is not None
    far = here.replace(name="elsewhere", position=dataclasses.replace(
        here.position, latitude_deg=here.position.latitude_deg + 1.0))
    problem = CalibrationProblem([here, far], CalibrationConfig(n_starts=1))
    assert any("111 km apart" in w for w in problem.identity_warnings)
    assert CalibrationProblem([here, here.replace(name="again")], CalibrationConfig(n_starts=1)).identity_warnings == []


def test_netcdf_records_the_calibrated_transducer_depth_and_the_entered_one(pool_calibration, tmp_path):
    import xarray as xr

    from adcpdyn import api

    _, path, _ = pool_calibration
    d = json.loads(path.read_text())
    d["runs"][0].update(case="pool_m1", transducer_depth_offset_m=0.05)
    m1 = simulate(get_scenario("pool_m1"), seed=1)
    api.correct(m1, "adc", d, out=tmp_path / "m1.nc")
    with xr.open_dataset(tmp_path / "m1.nc") as ds:
        entered, adcp = m1.environment.transducer_depth_m, ds["adcp"].attrs  # the instrument's container variable
        assert adcp["transducer_depth_m"] == pytest.approx(entered + 0.05, abs=1e-12)
        assert adcp["transducer_depth_entered_m"] == pytest.approx(entered, abs=1e-12)
        assert "calibrated" in adcp["transducer_depth_comment"]


def test_correct_applies_the_site_bed_where_a_runs_own_is_half_determined(pool_calibration):
    """One bed lookup for every reader: a run whose east bed component is not determined (null)
    gets the site's bed, never a NaN that would blank its east velocities."""
    from adcpdyn.estimators.correction.correct_case import correct_case

    _, path, _ = pool_calibration
    d = json.loads(path.read_text())
    d["moving_bed_velocity_m_s"], d["moving_bed_velocity_se_m_s"] = [0.05, -0.15], [0.01, 0.01]
    d["runs"][0].update(case="pool_m1", moving_bed_velocity_m_s=[0.04, None])
    m1 = simulate(get_scenario("pool_m1"), seed=1)
    plain = correct_case(m1, "adc", as_record({k: v for k, v in d.items() if k != "moving_bed_velocity_m_s"} | {"runs": [
        {**d["runs"][0], "moving_bed_velocity_m_s": None}]}))
    result = correct_case(m1, "adc", as_record(d))
    assert result.provenance.moving_bed_velocity_m_s == (0.05, -0.15)
    assert "site bed" in result.provenance.moving_bed_note
    np.testing.assert_allclose(result.vessel_velocity_m_s[:, :2] - plain.vessel_velocity_m_s[:, :2],
                               np.tile([0.05, -0.15], (m1.pings.n, 1)), atol=1e-12)
    assert CalibrationRecord.from_dict(d).moving_bed_for("pool_m1")[0].tolist() == [0.05, -0.15]
