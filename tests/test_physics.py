"""Physics against identities, closed forms and limits (not against our own numbers)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from conftest import noise_free, with_doppler

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.estimators.asc import asc
from adcpdyn.models import doppler, janus
from adcpdyn.models.empirical import motion_guess
from adcpdyn.models.kinematics import radius_vectors
from adcpdyn.models.motion import AttitudeParams, attitude_function, damped_mode, evaluate_attitude
from adcpdyn.models.rotations import euler_matrices, euler_matrix, matrix_euler
from adcpdyn.cases.simulation import simulate
from adcpdyn.models.simulator import echo_geometry, Kinematics

FD_TOL = 1e-6  # finite differences against algorithmic differentiation
EXACT_TOL = 1e-9  # identities that hold to rounding

RNG = np.random.default_rng(12)
TWO_AXES = AttitudeParams.from_axis_modes(
    roll_modes=[[0.25, -0.05, 6.11, 0.112], [0.03, 0.0, 2.0, 0.0]],
    roll_bias=0.01,
    pitch_modes=[[0.1, 0.3, 4.6, 0.2]],
    pitch_bias=-0.02,
    yaw_trend=[0.7, 0.01, -1e-4],
    yaw_coupling=[-0.3, 0.05, 0.1],
)
STILL = AttitudeParams.from_axis_modes([], 0.0, [], 0.0, [0.3])
TIMES = np.linspace(0.0, 20.0, 41)


def test_rotation_is_orthonormal_and_inverts():
    ypr = np.column_stack([RNG.uniform(-3, 3, 50), RNG.uniform(-1.4, 1.4, 50), RNG.uniform(-3, 3, 50)])
    R = euler_matrices(ypr)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=EXACT_TOL)
    assert np.allclose(np.linalg.det(R), 1.0, atol=EXACT_TOL)
    back = np.array([np.asarray(matrix_euler(ca.DM(r))).ravel() for r in R])
    assert np.allclose(back, ypr, atol=EXACT_TOL)


def test_euler_matrix_closed_form_eq7():
    psi, theta, phi = 0.3, -0.2, 0.5
    c, s = np.cos, np.sin
    eq7 = np.array([
        [c(psi) * c(theta), c(psi) * s(theta) * s(phi) - s(psi) * c(phi), c(psi) * s(theta) * c(phi) + s(psi) * s(phi)],
        [s(psi) * c(theta), s(psi) * s(theta) * s(phi) + c(psi) * c(phi), s(psi) * s(theta) * c(phi) - c(psi) * s(phi)],
        [-s(theta), c(theta) * s(phi), c(theta) * c(phi)],
    ])
    assert np.allclose(np.asarray(euler_matrix(psi, theta, phi)), eq7, atol=EXACT_TOL)


def test_damped_mode_solves_the_roll_equation():
    """Eq. 34 solves phi'' + 2 v phi' + n^2 phi = 0 with n^2 = n1^2 + v^2 (Eq. 35), phi(t0)=A, phi'(t0)=0."""
    t = ca.SX.sym("t")
    A, t0, n1, v = 0.25, 0.4, 6.11, 0.15
    phi = damped_mode(t, A, t0, n1, v)
    d1 = ca.jacobian(phi, t)
    d2 = ca.jacobian(d1, t)
    f = ca.Function("f", [t], [phi, d1, d2 + 2 * v * d1 + (n1**2 + v**2) * phi])
    for tk in np.linspace(0, 10, 23):
        assert abs(float(f(tk)[2])) < 1e-9
    assert float(f(t0)[0]) == pytest.approx(A, abs=EXACT_TOL)
    assert float(f(t0)[1]) == pytest.approx(0.0, abs=EXACT_TOL)


def test_omega_is_skew_and_matches_finite_differences():
    out = evaluate_attitude(TWO_AXES, TIMES)
    Om = out["Omega"]
    assert np.max(np.abs(Om + Om.transpose(0, 2, 1))) < 1e-12
    h = 1e-5
    Lp = evaluate_attitude(TWO_AXES, TIMES + h)["Lambda"]
    Lm = evaluate_attitude(TWO_AXES, TIMES - h)["Lambda"]
    fd = (Lp - Lm) / (2 * h)
    assert np.max(np.abs(fd - out["dLambda_dt"])) < FD_TOL
    assert np.max(np.abs(fd @ out["Lambda"].transpose(0, 2, 1) - Om)) < FD_TOL


def test_omega_axial_vector_matches_euler_rate_kinematics():
    """Independent route: body rates from Euler rates (ZYX), rotated to the Earth frame."""
    out = evaluate_attitude(TWO_AXES, TIMES)
    h = 1e-5
    rates = (evaluate_attitude(TWO_AXES, TIMES + h)["ypr"] - evaluate_attitude(TWO_AXES, TIMES - h)["ypr"]) / (2 * h)
    psi_d, th_d, ph_d = rates.T
    _, th, ph = out["ypr"].T
    w_body = np.column_stack([
        ph_d - psi_d * np.sin(th),
        th_d * np.cos(ph) + psi_d * np.cos(th) * np.sin(ph),
        -th_d * np.sin(ph) + psi_d * np.cos(th) * np.cos(ph),
    ])
    w_earth = np.einsum("nij,nj->ni", out["Lambda"], w_body)
    assert np.max(np.abs(w_earth - out["omega"])) < FD_TOL


def test_rate_identities_match_differentiating_lambda_to_rounding():
    """dLambda/dt = Lambda skew(w_b) and dLambda/dt r = omega x Lambda r (the forms the models
    evaluate) against CasADi's derivative of Lambda's nine entries, at large angles and rates."""
    from adcpdyn.models.kinematics import tangential_velocity_earth
    from adcpdyn.models.rotations import euler_matrix_and_rate

    t = ca.SX.sym("t")
    a, b, r = ca.SX.sym("a", 3), ca.SX.sym("b", 3), ca.SX.sym("r", 4, 3)
    ypr = a + b * t + 0.3 * ca.sin(2 * t) * b  # angles with rates and curvature
    Lam = euler_matrix(ypr[0], ypr[1], ypr[2])
    dLam = ca.reshape(ca.jacobian(ca.vec(Lam), t), 3, 3)
    Lam2, dLam2, w_b = euler_matrix_and_rate(ypr, ca.jacobian(ypr, t))
    omega = ca.mtimes(Lam2, w_b)
    f = ca.Function("f", [t, a, b, r], [Lam - Lam2, dLam - dLam2, ca.mtimes(r, dLam.T) - tangential_velocity_earth(Lam2, omega, r)])
    for _ in range(20):
        args = RNG.uniform(-3, 3), RNG.uniform(-np.pi, np.pi, 3), RNG.uniform(-2, 2, 3), RNG.uniform(-5, 5, (4, 3))
        for diff in f(*args):
            assert float(ca.norm_inf(diff)) < 1e-13


def test_attitude_rates_by_the_turned_mode_pair_equal_differentiating_the_angles():
    """attitude_ypr_and_rate's rates (each mode's basis pair turned) against CasADi's derivative of
    the angles, with a yaw trend of order 2 and three modes."""
    from adcpdyn.models.motion import AttitudeLayout, attitude_ypr_and_rate

    layout = AttitudeLayout(n_modes=3, yaw_trend_order=2, t_ref_s=5.0)
    t, p = ca.SX.sym("t"), ca.SX.sym("p", layout.size)
    ypr, rate = attitude_ypr_and_rate(t, p, layout)
    f = ca.Function("f", [t, p], [ca.jacobian(ypr, t) - rate])
    for _ in range(10):
        params = RNG.uniform(-1, 1, layout.size)
        params[layout.slices()["modes"]] = np.ravel([[RNG.uniform(0.3, 3), RNG.uniform(0, 0.3)] for _ in range(3)])
        assert float(ca.norm_inf(f(RNG.uniform(-5, 15), params))) < 1e-13


def test_attitude_expansion_converges_at_its_order_and_is_exact_at_its_centre():
    """attitude_expansion of order 2 against the attitude Function itself at t0 + h: every output
    (angles, Lambda, its rate, Omega, omega) equal at h = 0, the error shrinking as h^3 (a tenth
    of h: a thousandth of the error) down to 2e-4 s, for three modes with a yaw trend."""
    from adcpdyn.models.motion import AttitudeLayout, attitude_expansion

    layout = AttitudeLayout(n_modes=3, yaw_trend_order=2, t_ref_s=5.0)
    fun = attitude_function(layout)
    t0, h, p = ca.SX.sym("t0"), ca.SX.sym("h"), ca.SX.sym("p", layout.size)
    about = attitude_expansion(fun, t0, p, order=2)
    err = ca.Function("err", [t0, h, p], [ca.vertcat(*[ca.vec(a - b) for a, b in zip(about(t0 + h), fun(t0 + h, p))])])
    for _ in range(5):
        params = RNG.uniform(-0.5, 0.5, layout.size)
        params[layout.slices()["modes"]] = np.ravel([[RNG.uniform(0.3, 1.5), RNG.uniform(0, 0.3)] for _ in range(3)])
        t = RNG.uniform(0, 10)
        e = [float(ca.norm_inf(err(t, step, params))) for step in (0.0, 1e-1, 1e-2, 2e-4)]
        assert e[0] < 1e-15
        assert 300 < e[1] / e[2] < 3000  # third order
        assert e[3] < 2 * e[2] * (2e-4 / 1e-2) ** 3 + 1e-15


def test_janus_least_squares_is_eq5_and_error_velocity_vanishes_for_rigid_motion():
    a = np.deg2rad(30.0)
    B = np.asarray(janus.janus_beam_directions(a))
    M, e = janus.beam_to_instrument(B)
    assert np.allclose(M, np.asarray(janus.beam_to_instrument_janus(a)), atol=EXACT_TOL)
    v = RNG.normal(size=(20, 3))
    radial = v @ B.T
    assert np.allclose(radial @ M.T, v, atol=EXACT_TOL)
    assert np.max(np.abs(radial @ e)) < EXACT_TOL
    # RDI's error velocity for the Janus layout
    r = RNG.normal(size=4)
    assert r @ e == pytest.approx((r[0] + r[1] - r[2] - r[3]) / (2 * np.sqrt(2) * np.sin(a)), abs=EXACT_TOL)


def test_three_beam_solution_recovers_rigid_velocity():
    B = np.asarray(janus.janus_beam_directions(np.deg2rad(20.0)))
    v = RNG.normal(size=(8, 3))
    radial = v @ B.T
    radial[np.arange(8), np.arange(8) % 4] = np.nan
    radial[7, :2] = np.nan  # three beams lost: no solution
    est, n_good = janus.three_beam_solution(B, radial)
    assert np.allclose(est[:7], v[:7], atol=EXACT_TOL)
    assert n_good.tolist() == [3] * 7 + [1]
    assert np.all(np.isnan(est[7]))


def test_radius_vectors_satisfy_janus_conditions():
    tr = 0.0147
    r = np.asarray(radius_vectors(np.deg2rad([45.0, 2.0, -3.0]), np.array([0.01, -0.02, 0.14]),
                                  janus.janus_transducer_positions(tr)))
    assert np.allclose((r[0] + r[1]) / 2, (r[2] + r[3]) / 2, atol=EXACT_TOL)  # midpoints coincide
    assert abs((r[1] - r[0]) @ (r[2] - r[3])) < EXACT_TOL  # diagonals perpendicular
    assert np.linalg.norm(r[1] - r[0]) == pytest.approx(2 * tr, abs=EXACT_TOL)
    assert np.linalg.norm(r[2] - r[3]) == pytest.approx(2 * tr, abs=EXACT_TOL)


def test_doppler_conversion_round_trips():
    c = 1482.0
    v = np.linspace(-9.5, 9.5, 101)
    assert np.allclose(doppler.radial_from_ratio(doppler.ratio_from_radial(v, c), c), v, atol=1e-12)
    # still transducer geometry: equal velocities at transmit and receive give back u exactly
    u = RNG.uniform(-3, 3, 50)
    assert np.allclose(doppler.radial_from_ratio(doppler.bottom_echo_ratio(u, u, c), c), u, atol=1e-12)
    # water echo with a still transducer: radial = -w (water receding is negative)
    w = RNG.uniform(-2, 2, 50)
    ratio = doppler.water_echo_ratio(0 * w, 0 * w, w, w, c)
    assert np.allclose(doppler.radial_from_ratio(ratio, c), -w, atol=1e-12)


def test_no_rotation_radials_are_v_dot_d_and_asc_recovers_velocity(pool_still):
    case = simulate(noise_free(pool_still), seed=4)
    kin = Kinematics(noise_free(pool_still))
    tx = kin.at(case.pings.time_s)
    expected = np.sum(tx["velocity"] * tx["d"], axis=-1)  # V_T . d
    assert np.max(np.abs(case.pings.bt_radial_m_s - expected)) < EXACT_TOL
    assert np.max(np.abs(tx["velocity"] - tx["vessel_velocity"][:, None, :])) < EXACT_TOL
    result = asc(case)  # sensor in the head: no installation angles needed
    assert np.max(np.abs(result.vessel_velocity_m_s - case.truth.vessel_velocity_m_s)) < EXACT_TOL


def test_vessel_frame_sensor_needs_installation_angles():
    sc = noise_free(get_scenario("deep_ship"))
    sc = __import__("dataclasses").replace(sc, run=__import__("dataclasses").replace(
        sc.run, motion=AttitudeParams.from_axis_modes([], 0.0, [], 0.0, [1.0]),
        duration_s=30.0))
    case = simulate(sc, seed=2)
    good = asc(case, case.truth.installation_ypr_rad)
    assert np.max(np.abs(good.vessel_velocity_m_s - case.truth.vessel_velocity_m_s)) < EXACT_TOL
    bad = asc(case)  # 7.4 degrees of installation yaw ignored
    assert np.max(np.abs(bad.vessel_velocity_m_s - case.truth.vessel_velocity_m_s)) > 0.1


def _two_way_vs_instantaneous(scenario):
    sc = noise_free(scenario)
    two_way = simulate(sc, seed=5).pings.bt_radial_m_s
    inst = simulate(with_doppler(sc, timing="instantaneous"), seed=5).pings.bt_radial_m_s
    kin = Kinematics(sc)
    t_T = simulate(sc, seed=5).pings.time_s
    u_tx, u_rx, _, _, t_R, _ = echo_geometry(kin, sc, t_T, kin.at(t_T), np.full((t_T.size, 1), sc.run.water_depth_m),
                                     sc.platform.instrument.sound_speed_m_s)
    return two_way, inst, u_tx, u_rx


def test_shallow_water_two_way_agrees_with_instantaneous_within_txrx_difference(pool_m0):
    two_way, inst, u_tx, u_rx = _two_way_vs_instantaneous(pool_m0)
    # to first order the two-way radial is the mean of the transmit and receive projections
    assert np.max(np.abs(two_way - (u_tx + u_rx) / 2)) < 1e-5
    assert np.max(np.abs(two_way - inst)) <= np.max(np.abs(u_rx - u_tx)) / 2 + 1e-5
    assert np.max(np.abs(two_way - inst)) < 2e-3  # 5 m: a few-ms round trip


@pytest.mark.slow  # 11 s: `make test-slow`, CI's second step
def test_deep_water_two_way_differs_from_instantaneous():
    two_way, inst, u_tx, u_rx = _two_way_vs_instantaneous(get_scenario("deep_ocean"))
    assert np.sqrt(np.mean((two_way - inst) ** 2)) > 0.02  # 300 m: the beams turn during the flight
    assert np.max(np.abs(two_way - (u_tx + u_rx) / 2)) < 1e-3


def test_exact_travel_time_closes_the_geometry():
    sc = noise_free(get_scenario("deep_ocean"))
    kin = Kinematics(sc)
    t_T = np.linspace(0, 100, 30)
    tx = kin.at(t_T)
    c = sc.platform.instrument.sound_speed_m_s
    H = np.full((30, 1), sc.run.water_depth_m)
    _, _, e_tx, _, t_R, l = echo_geometry(kin, sc, t_T, tx, H, c)
    spot = tx["position"] + l[..., None] * e_tx
    rx = kin.at(t_R)
    pos_R = rx["position"][np.arange(30)[:, None], np.arange(4)[None, :], np.arange(4)[None, :]]
    back = np.linalg.norm(spot - pos_R, axis=-1)
    assert np.max(np.abs(c * (t_R - t_T[:, None]) - l - back)) < 1e-6
    assert np.allclose(spot[..., 2], sc.run.water_depth_m, atol=1e-9)


def test_reference_velocity_is_lever_arm_consistent():
    sc = noise_free(get_scenario("deep_ship"))
    case = simulate(sc, seed=1)
    kin = Kinematics(sc)
    t = case.reference.time_s[:20]
    p = case.reference.point_body_m
    h = 1e-4
    pos = lambda tt: kin.track.position(tt) + np.einsum("nij,j->ni", kin.at(tt)["Lambda"], p)
    fd = (pos(t + h) - pos(t - h)) / (2 * h)
    assert np.max(np.abs(fd - case.reference.velocity_m_s[:20])) < 1e-5


def test_head_sensor_reads_lambda_times_lambda_tb(pool_m0):
    sc = noise_free(pool_m0)
    case = simulate(sc, seed=3)
    out = evaluate_attitude(sc.run.motion, case.attitude.time_s)
    R = out["Lambda"] @ euler_matrices(np.asarray(sc.platform.mounting.installation_ypr_rad)[None, :])[0]
    sensed = euler_matrices(case.attitude.ypr())
    assert np.max(np.abs(sensed - R)) < EXACT_TOL


def test_simulation_is_reproducible(pool_m0):
    a, b, c = simulate(pool_m0, 7), simulate(pool_m0, 7), simulate(pool_m0, 8)
    assert np.array_equal(a.pings.bt_radial_m_s, b.pings.bt_radial_m_s)
    assert not np.array_equal(a.pings.bt_radial_m_s[:5], c.pings.bt_radial_m_s[:5])


def test_empirical_guess_near_paper_initial_guess():
    g = motion_guess(0.96, 0.2, 0.18, 18.0, 0.094, 0.018)
    assert g.roll_damped_rad_s == pytest.approx(6.3192, rel=0.05)  # Table 1 initial guess
    assert g.roll_damped_rad_s < g.roll_natural_rad_s
    with pytest.raises(ValueError, match="beam_m"):
        motion_guess(0.96, None, 0.18, 18.0)


def test_no_rotation_asc_recovers_water_profile():
    """Still ship, steady current: bt - water radial is the Earth radial water velocity (Eq. 4)."""
    import dataclasses

    sc = noise_free(get_scenario("deep_ocean"))
    sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, motion=STILL, duration_s=20.0))
    case = simulate(sc, seed=1)
    result = asc(case, case.truth.installation_ypr_rad)
    measured = np.isfinite(result.water_velocity_m_s[..., 0])
    assert measured.mean() > 0.5
    err = result.water_velocity_m_s[measured] - case.truth.water_velocity_m_s[measured]
    assert np.max(np.abs(err)) < 1e-5  # second order in speed / c only


@pytest.mark.parametrize("amplitude,t0,omega,decay", [(0.25, -0.05, 6.11, 0.112), (-0.2, 1.14, 6.19, 0.6), (0.03, 3.0, 1.05, 0.0)])
def test_cs_form_is_the_papers_eq34_and_converts_back(amplitude, t0, omega, decay):
    from adcpdyn.models.motion import cs_to_paper, mode_cs, paper_to_cs

    t_ref = 0.7
    c, s = paper_to_cs(amplitude, t0, omega, decay, t_ref)
    t = np.linspace(-1, 20, 57)
    paper = np.asarray(ca.Function("f", [], [damped_mode(ca.DM(t), amplitude, t0, omega, decay)])()["o0"]).ravel()
    ours = np.asarray(ca.Function("g", [], [mode_cs(ca.DM(t), c, s, omega, decay, t_ref)])()["o0"]).ravel()
    assert np.allclose(paper, ours, atol=1e-12)
    a2, t02 = cs_to_paper(c, s, omega, decay, t_ref)
    again = np.asarray(ca.Function("h", [], [damped_mode(ca.DM(t), a2, t02, omega, decay)])()["o0"]).ravel()
    assert np.allclose(again, paper, atol=1e-12)
    assert abs(t02 - t_ref) <= np.pi / omega + 1e-12


def test_chunked_attitude_evaluation_matches_single_calls():
    from adcpdyn.models.motion import EVAL_CHUNK

    t = np.linspace(0, 50, 2 * EVAL_CHUNK + 17)
    many = evaluate_attitude(TWO_AXES, t)
    pick = [0, EVAL_CHUNK - 1, EVAL_CHUNK, 2 * EVAL_CHUNK + 16]
    few = evaluate_attitude(TWO_AXES, t[pick])
    for key in ("ypr", "Lambda", "dLambda_dt"):
        assert np.array_equal(many[key][pick], few[key])


def test_local_attitude_is_the_samples_linear_interpolation():
    """The sampled-attitude model against np.interp of the samples (heading across north
    unwrapped), and its dLambda/dt against a central difference of Lambda inside a segment."""
    from adcpdyn.models.motion import local_attitude_function, local_attitude_params

    rng = np.random.default_rng(3)
    time_s = np.cumsum(rng.uniform(0.4, 0.8, 40))
    ypr = np.column_stack([np.mod(6.1 + 0.02 * time_s, 2 * np.pi), 0.05 * np.sin(time_s), 0.1 * np.cos(1.3 * time_s)])
    times = np.linspace(time_s[1], time_s[-2], 57)
    P = local_attitude_params(time_s, ypr, times)
    f = local_attitude_function()
    unwrapped = np.unwrap(ypr[:, 0])
    for k, t in enumerate(times):
        out = f(t, P[:, k])
        expected = [np.interp(t, time_s, unwrapped), np.interp(t, time_s, ypr[:, 1]), np.interp(t, time_s, ypr[:, 2])]
        assert np.allclose(np.asarray(out[0]).ravel(), expected, atol=1e-12)
        assert np.allclose(np.asarray(out[1]), np.asarray(euler_matrix(*expected)), atol=1e-12)
        j = np.searchsorted(time_s, t, side="right") - 1
        h = 1e-3 * min(t - time_s[j], time_s[j + 1] - t, 1.0)
        if h > 1e-9:
            fd = (np.asarray(f(t + h, P[:, k])[1]) - np.asarray(f(t - h, P[:, k])[1])) / (2 * h)
            assert np.allclose(np.asarray(out[2]), fd, atol=1e-7)


def test_heading_correction_is_a_yaw_offset_and_turns_the_rotation():
    """A constant misalignment d is the model with its yaw shifted by d (Eq. 7: Rz(psi + d) =
    Rz(d) Rz(psi)): Lambda and dLambda/dt equal to round-off. With a deviation B, C the Earth
    angular velocity is the sensor's turned by Rz(delta), its length unchanged, and delta is
    compass_correction at the sensor heading."""
    from adcpdyn.models.motion import heading_corrected_function, local_attitude_function
    from adcpdyn.models.sensors import compass_correction

    f = local_attitude_function()
    g = heading_corrected_function(f, mean_sin=0.3, mean_cos=-0.2)
    p = np.array([0.0, 1.0, 0.1, 0.2, 0.3, 0.01, 0.02, 1.0])  # ..., the slow heading (p[7])
    shifted = p.copy()
    shifted[1] += 0.2
    out, ref = g(0.5, np.r_[p, 0.2, 0.0, 0.0]), f(0.5, shifted)
    for k in (1, 2):
        assert np.max(np.abs(np.asarray(out[k] - ref[k]))) < 1e-14
    h = np.array([0.2, 0.03, -0.02])
    out, sensor = g(0.5, np.r_[p, h]), f(0.5, p)
    psi = float(sensor[0][0])
    delta = compass_correction(psi, *h, 0.3, -0.2)
    assert float(out[0][0]) == pytest.approx(psi + delta, abs=1e-14)
    assert delta == pytest.approx(0.2 + 0.03 * (np.sin(psi) - 0.3) - 0.02 * (np.cos(psi) + 0.2), abs=1e-15)
    w, w_s = np.asarray(out[4]).ravel(), np.asarray(sensor[4]).ravel()
    Rz = np.array([[np.cos(delta), -np.sin(delta), 0], [np.sin(delta), np.cos(delta), 0], [0, 0, 1]])
    assert np.allclose(w, Rz @ w_s, atol=1e-14)


def test_sampled_tilt_lead_inverts_a_first_order_lowpass_in_closed_form():
    """params_at(t, tau): pitch and roll x = y + tau y', rates x' = y' + tau y'' (y = A sin wt),
    heading untouched; the linear interpolation adds tau times the segment slope."""
    from adcpdyn.models.motion import SampledAttitude

    w, A, tau = 1.3, 0.05, 0.3
    t = np.arange(0.0, 60.0, 0.05)
    ypr = np.column_stack([0.2 * np.ones_like(t), A * np.sin(w * t), -A * np.sin(w * t)])
    s = SampledAttitude(t, ypr, band_rad_s=2 * w)
    tq = np.linspace(20.0, 40.0, 57)
    p0, p = s.params_at(tq), s.params_at(tq, tilt_lead_s=tau)
    x = A * (np.sin(w * tq) + tau * w * np.cos(w * tq))
    xdot = A * (w * np.cos(w * tq) - tau * w**2 * np.sin(w * tq))
    np.testing.assert_allclose(p[2], x, atol=1e-3 * A)  # the smoothing keeps 99.9 % at w
    np.testing.assert_allclose(p[3], -x, atol=1e-3 * A)  # the smoothing keeps 99.9 % at w
    np.testing.assert_allclose(p[5], xdot, atol=3e-3 * A * w)
    np.testing.assert_allclose(p[[0, 1, 4]], p0[[0, 1, 4]])
    lin = SampledAttitude(t, ypr, "linear")
    q0, q = lin.params_at(tq), lin.params_at(tq, tilt_lead_s=tau)
    np.testing.assert_allclose(q[2:4], q0[2:4] + tau * q0[5:7])
