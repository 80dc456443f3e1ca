"""Survey calibration: several runs of one boat in one NLP, the moving bed and the compass error
as parameters, honest uncertainty (HAC sandwich) and the bed added back by the corrections."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.estimators.calibration.config import CalibrationConfig
from adcpdyn.estimators.calibration.problem import CalibrationProblem, calibrate, calibrate_runs
from adcpdyn.cases.simulation import simulate

Z_MAX = 3.5
MISALIGNMENT_RAD = 0.25  # true heading = sensor heading + 0.25 rad: the compass reads psi - 0.25
BED = {"velocity_north_m_s": 0.12, "velocity_east_m_s": -0.08}


def survey_run(course_rad: float, seed: int, duration_s: float = 80.0, bed=BED, noise=None):
    """One transect of a launch whose compass sits in the head (installation not zero): compass
    error, moving bed, a speed-up mid-run; ``course_rad`` sets the heading."""
    sc = get_scenario("diag_boat")
    mounting = dataclasses.replace(sc.platform.mounting, attitude_frame="transducer", installation_ypr_rad=(0.12, 0.01, -0.02))
    motion = dataclasses.replace(sc.run.motion, yaw_trend=np.array([course_rad, 0.0]))
    effects = ({"name": "compass_deviation", "params": {"A_rad": -MISALIGNMENT_RAD, "B_rad": 0.0, "C_rad": 0.0}},)
    if bed is not None:
        effects += ({"name": "moving_bed", "params": bed},)
    bump = 0.3 * np.array([np.cos(course_rad), np.sin(course_rad), 0.0])
    nav = dataclasses.replace(sc.run.navigation, knot_times_s=(0.0, duration_s / 2, duration_s),
                              knot_velocities_m_s=((0.0, 0.0, 0.0), tuple(bump), (0.0, 0.0, 0.0)))
    run = dataclasses.replace(sc.run, motion=motion, effects=effects, duration_s=duration_s, navigation=nav,
                              noise=noise or sc.run.noise)
    sc = dataclasses.replace(sc, platform=dataclasses.replace(sc.platform, mounting=mounting), run=run)
    return simulate(sc, seed=seed).replace(name=f"transect{seed}")


def _quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


@pytest.fixture(scope="module")
def survey():
    return [survey_run(0.4, 1), survey_run(0.4 + np.pi, 2)]


@pytest.fixture(scope="module")
def joint(survey):
    return _quiet(calibrate_runs, survey, CalibrationConfig(n_starts=3, formulation="minimal"))


def test_joint_calibration_separates_compass_error_and_moving_bed(survey, joint):
    r = joint
    assert r.success and len(r.runs) == 2 and r.moving_bed == "constant"
    err = r.heading_misalignment_rad - MISALIGNMENT_RAD
    assert abs(err) < Z_MAX * r.heading_misalignment_se_rad and abs(err) < np.deg2rad(0.5)
    bed = np.array([BED["velocity_north_m_s"], BED["velocity_east_m_s"]])
    assert np.all(np.abs(r.moving_bed_velocity_m_s - bed) < Z_MAX * r.moving_bed_velocity_se_m_s)
    assert np.all(np.abs(r.moving_bed_velocity_m_s - bed) < 0.02)
    for run in r.runs:  # a constant bed applies to every run
        assert np.allclose(run.moving_bed_velocity_m_s, r.moving_bed_velocity_m_s)
    assert r.confounded == []  # opposite courses separate the two


def test_single_run_names_the_confounding_and_covers_the_truth(survey):
    """One course: the misalignment and the bed share most of their variance; the report names the
    pair and the SE carries it, so the truth stays within it (no 0.2-degree SE on a 10-degree error)."""
    for case in survey:
        r = _quiet(calibrate, case, CalibrationConfig(n_starts=2, formulation="minimal"))
        assert [c["pair"] for c in r.confounded] == [["heading_misalignment", "moving_bed_velocity"]]
        assert abs(r.heading_misalignment_rad - MISALIGNMENT_RAD) < Z_MAX * r.heading_misalignment_se_rad
        assert r.heading_misalignment_se_rad > np.deg2rad(0.5)


def test_calibration_file_keeps_the_survey(joint, tmp_path):
    path = tmp_path / "calib.json"
    joint.to_json(path)
    out = json.loads(path.read_text())
    assert out["schema_version"] == 3
    assert [r["case"] for r in out["runs"]] == ["transect1", "transect2"]
    assert len(out["moving_bed_velocity_m_s"]) == 2 and len(out["moving_bed_velocity_se_m_s"]) == 2
    assert all(len(r["moving_bed_velocity_m_s"]) == 2 for r in out["runs"])
    assert out["standard_errors"]["method"] == "hac"
    assert out["installation_ypr_rad"][0] == pytest.approx(out["heading_misalignment_rad"])
    for run in out["runs"]:
        assert {"noise_sigma", "chi2_per_channel", "residual_lag1", "attitude_model"} <= set(run)


def test_correct_adds_the_run_bed_back_and_says_so(survey, joint, tmp_path):
    """Bottom track measures the vessel over the bed: with the calibration's bed added back, the
    static correction's velocity matches the true velocity over ground; without, it is off by the bed."""
    from adcpdyn.estimators.calibration.record import as_record
    from adcpdyn.estimators.correction.correct_case import correct_case

    path = tmp_path / "calib.json"
    joint.to_json(path)
    calib = json.loads(path.read_text())
    case = survey[0]
    out = correct_case(case, "asc", as_record(calib))
    assert out.provenance.moving_bed_note and list(out.provenance.moving_bed_velocity_m_s) == pytest.approx(
        joint.moving_bed_velocity_m_s.tolist())
    truth = case.truth.vessel_velocity_m_s
    with_bed = np.nanmean(out.vessel_velocity_m_s[:, :2] - truth[:, :2], axis=0)
    without = np.nanmean(correct_case(case, "asc", as_record({**calib, "runs": [], "moving_bed_velocity_m_s": None}))
                         .vessel_velocity_m_s[:, :2] - truth[:, :2], axis=0)
    bed = np.array([BED["velocity_north_m_s"], BED["velocity_east_m_s"]])
    assert np.allclose(without, -bed, atol=0.03)
    assert np.all(np.abs(with_bed) < 0.03)


@pytest.mark.slow  # 5.0 s
def test_joint_problem_is_block_sparse_and_its_assembled_jacobian_is_casadis(survey):
    """Two runs: each run's rows touch only its own attitude and knots; the assembled Jacobian equals
    casadi.jacobian of the whole expanded problem (beams' attitude from the samples, bed, misalignment)."""
    problems = {j: CalibrationProblem(survey, CalibrationConfig(n_starts=2, seed=1, jacobian=j, attitude=a, workers=1))
                for j, a in (("assembled", "samples"), ("symbolic", "samples"))}
    p = problems["symbolic"]
    z = p.start_points(2, 1)[1]
    w = problems["assembled"].parameters()  # the weights; the symbolic problem's p holds its recorded numbers too
    assembled = problems["assembled"].jacobian_fun(z, w)
    symbolic = np.asarray(p.jacobian_fun(z, p.parameters()))
    assert np.max(np.abs(assembled.toarray() - symbolic)) < 1e-9 * np.max(np.abs(symbolic))
    gram = symbolic.T @ symbolic
    assert np.max(np.abs(problems["assembled"].jacobian_fun.gram(z, w) - gram)) < 1e-9 * np.max(np.abs(gram))
    JM = problems["assembled"].jacobian_fun.at(z, w) @ np.eye(symbolic.shape[1])  # J column by column, never formed
    assert np.max(np.abs(JM - symbolic)) < 1e-9 * np.max(np.abs(symbolic))
    u = p.model.unknowns
    rows = p.model.row_run
    for k, other in ((0, 1), (1, 0)):
        cols = u.index(f"velocity{other}")
        assert np.all(symbolic[np.ix_(rows == k, cols)] == 0)


def test_newey_west_recovers_the_long_run_variance_of_an_ar1_mean():
    """Closed form: the mean of T AR(1) values (rho, unit innovations) has variance
    sigma^2 / (1 - rho)^2 / T for large T; the white formula gives (1 / (1 - rho^2)) / T."""
    from adcpdyn.estimators.statistics.hac import sandwich

    rng = np.random.default_rng(5)
    T, rho = 20000, 0.8
    e = np.empty(T)
    e[0] = rng.normal() / np.sqrt(1 - rho**2)
    for t in range(1, T):
        e[t] = rho * e[t - 1] + rng.normal()
    J = np.ones((T, 1))  # y = mu + e: J of the residuals w.r.t. mu, P = (J^T J)^-1 = 1 / T
    sw = sandwich(J, e - e.mean(), np.full((1, 1), 1.0 / T), np.zeros(T, dtype=int), np.arange(T, dtype=float), {0: 1.0})
    theory = 1.0 / (1 - rho) ** 2 / T
    white = 1.0 / (1 - rho**2) / T
    assert sw.cov[0, 0] == pytest.approx(theory, rel=0.2)
    assert sw.cov[0, 0] > 4 * white
    assert 0.7 < sw.rho[0] < 0.9


def test_hat_basis_is_np_interp_of_the_unit_vectors_and_two_knots_per_row():
    """The navigation's interpolation weights, built sparse, equal np.interp of each knot's unit
    vector (held beyond the ends, one knot alone on a knot), in every form the models take."""
    import casadi as ca

    from adcpdyn.estimators.knots import hat_basis, hat_basis_dm, hat_basis_sparse

    knots = np.linspace(3.0, 50.0, 9)
    t = np.concatenate([np.linspace(-2.0, 60.0, 311), knots, np.random.default_rng(1).uniform(0.0, 55.0, 200)])
    expected = np.column_stack([np.interp(t, knots, np.eye(knots.size)[:, k]) for k in range(knots.size)])
    np.testing.assert_array_equal(hat_basis(t, knots), expected)
    H = hat_basis_sparse(t, knots)
    assert H.nnz == np.count_nonzero(expected) and np.all(np.diff(H.indptr) <= 2)
    D = hat_basis_dm(t, knots)
    assert D.nnz() == H.nnz
    np.testing.assert_array_equal(np.array(ca.densify(D)), expected)
