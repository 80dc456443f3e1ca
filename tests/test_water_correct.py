"""Water cells through every correction: referenced to the bottom track or to the GNSS, relative kept."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import noise_free

from adcpdyn.cases.case import Reference
from adcpdyn.cases.scenario import get_scenario
from adcpdyn.estimators.correction.adc import dynamic_correction
from adcpdyn.estimators.asc import asc
from adcpdyn.estimators.calibration.record import CalibrationRecord
from adcpdyn.estimators.correction.correct_case import correct_case, with_moving_bed
from adcpdyn.estimators.water import check_reference, reference_velocity_at
from adcpdyn.models.motion import AttitudeParams, evaluate_attitude
from adcpdyn.models.rotations import euler_matrix
from adcpdyn.cases.simulation import simulate


def truth_calibration(case) -> CalibrationRecord:
    t = case.truth
    head = t.radius_vectors_m @ np.asarray(euler_matrix(*t.installation_ypr_rad))
    return CalibrationRecord.from_dict({"radius_vectors_m": t.radius_vectors_m.tolist(), "radius_vectors_head_m": head.tolist(),
                                        "installation_ypr_rad": t.installation_ypr_rad.tolist()})


@pytest.fixture(scope="module")
def ocean():
    """deep_ocean (8-s roll, transducer metres from G, reference point 32 m from G), 60 s, noise-free."""
    sc = noise_free(get_scenario("deep_ocean"))
    return simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=60.0)), seed=5)


def with_exact_reference(case):
    """The reference point's true velocity sampled at the pings: V_G + dLambda/dt p (no interpolation error)."""
    att = AttitudeParams.from_dict(json.loads(case.truth.extra_attrs["attitude_model"]))
    dlam = evaluate_attitude(att, case.pings.time_s)["dLambda_dt"]
    p = case.reference.point_body_m
    v = case.truth.vessel_velocity_m_s + np.einsum("nij,j->ni", dlam, p)
    return case.replace(reference=Reference(time_s=case.pings.time_s.copy(), velocity_m_s=v, point_body_m=p))


def test_static_water_is_relative_plus_the_reference(ocean):
    bt = asc(ocean)
    gnss = asc(ocean, water_reference="gnss")
    rel = bt.water_relative_velocity_m_s
    np.testing.assert_array_equal(rel, gnss.water_relative_velocity_m_s)
    four = np.all(np.isfinite(ocean.pings.bt_radial_m_s), axis=1)
    assert four.mean() > 0.9  # linear transform: bt - w = (bt) + (-w) wherever all four beams hold
    assert np.nanmax(np.abs(bt.water_velocity_m_s[four] - (rel[four] + bt.vessel_velocity_m_s[four, None, :]))) < 1e-12
    v_ref = reference_velocity_at(ocean, ocean.pings.time_s)
    assert np.nanmax(np.abs(gnss.water_velocity_m_s - (rel + v_ref[:, None, :]))) < 1e-15
    assert bt.provenance.water_reference == "bt" and gnss.provenance.water_reference == "gnss"


@pytest.mark.parametrize("method", ["adc", "rootfinder", "oracle"])
def test_dynamic_water_from_the_gnss_matches_the_bottom_track(ocean, method):
    """With the reference point's exact velocity, the centre of rotation's velocity from it (v_ref - dLambda/dt p,
    the point 32 m from G: a 2 m/s tangential velocity) gives the same water as the bottom track's."""
    case = with_exact_reference(ocean)
    calib = None if method == "oracle" else truth_calibration(case)
    bt = dynamic_correction(case, method, calib)
    gnss = dynamic_correction(case, method, calib, water_reference="gnss")
    ok = np.isfinite(bt.water_velocity_m_s[..., 0]) & np.isfinite(gnss.water_velocity_m_s[..., 0])
    assert ok.mean() > 0.5
    assert np.max(np.abs(gnss.water_velocity_m_s[ok] - bt.water_velocity_m_s[ok])) < 1e-4  # 1.2e-5 measured
    np.testing.assert_array_equal(bt.water_relative_velocity_m_s, gnss.water_relative_velocity_m_s)
    # relative to G: the referenced water less the vessel velocity, to the model's V/c coupling
    shift = bt.water_velocity_m_s - bt.vessel_velocity_m_s[:, None, :] - bt.water_relative_velocity_m_s
    assert np.nanmax(np.abs(shift)) < 1e-3  # 2.4e-4 measured
    if method == "oracle":  # and the truth
        truth = case.truth.water_velocity_m_s[ok]
        assert np.max(np.abs(gnss.water_velocity_m_s[ok] - truth)) < 1e-3 < 0.1 < np.nanmax(np.abs(asc(case).water_velocity_m_s - case.truth.water_velocity_m_s))


def test_tangential_velocity_of_the_reference_point_matters(ocean):
    """Taking the antenna's velocity for G's (p ignored) would be 0.5 m/s or more off: the test above can fail."""
    case = with_exact_reference(ocean)
    moved = case.replace(reference=dataclasses.replace(case.reference, point_body_m=np.zeros(3)))
    bt = dynamic_correction(case, "oracle")
    wrong = dynamic_correction(moved, "oracle", water_reference="gnss")
    assert np.nanmax(np.abs(wrong.water_velocity_m_s - bt.water_velocity_m_s)) > 0.5


def test_moving_bed_is_added_to_bottom_track_water_only(ocean):
    bed = np.array([0.2, -0.1])
    for reference, added in (("bt", True), ("gnss", False)):
        r = asc(ocean, water_reference=reference)
        out = with_moving_bed(r, bed, "test")
        expected = r.water_velocity_m_s + (np.array([0.2, -0.1, 0.0]) if added else 0.0)
        np.testing.assert_array_equal(out.water_velocity_m_s, expected)
        np.testing.assert_array_equal(out.water_relative_velocity_m_s, r.water_relative_velocity_m_s)


def test_correct_case_records_what_it_applied(ocean):
    r = correct_case(ocean, "asc", None, reference="gnss")
    assert r.provenance.water_reference == "gnss" and "GNSS" in r.provenance.water_reference_note
    assert r.provenance.heading_misalignment_applied_rad is None and "headings as recorded" in r.provenance.heading_correction_note
    head = ocean.replace(attitude=dataclasses.replace(ocean.attitude, frame="transducer"))
    calib = CalibrationRecord.from_dict({"heading_misalignment_rad": 0.1, "magnetic_declination_rad": 0.3})
    r = correct_case(head, "asc", calib)
    assert r.provenance.heading_misalignment_applied_rad == 0.1 and r.provenance.magnetic_declination_rad == 0.3


def test_reference_errors_are_one_line(ocean):
    with pytest.raises(ValueError, match=r"--reference: expected one of \['bt', 'gnss'\], got 'gps'"):
        check_reference("gps")
    with pytest.raises(ValueError, match="--reference gnss needs the case's reference velocity"):
        asc(ocean.replace(reference=None), water_reference="gnss")


def test_cli_reference_gnss_without_reference_exits_2(tmp_path, capsys, ocean):
    from adcpdyn.cases.io import write_case
    from adcpdyn.cli import main

    path = tmp_path / "no_ref.h5"
    write_case(ocean.replace(reference=None, truth=None), path)
    assert main(["correct", str(path), "--reference", "gnss", "--out", str(tmp_path / "o.h5")]) == 2
    err = capsys.readouterr().err
    assert "/reference" in err and err.count("\n") == 1 and not (tmp_path / "o.h5").exists()
