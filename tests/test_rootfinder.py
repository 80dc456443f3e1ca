"""The per-ping solves on arrays against independent references: scipy's root finder on the
measurement model ping by ping, Eq. 89 assembled in numpy from the attitude samples, a
mapped evaluation against a direct one."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import root

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators.correction.adc import _geometry, _ping_model
from adcpdyn.estimators.statistics.evaluation import true_attitude
from adcpdyn.models.doppler import ratio_from_radial, receive_time_paper, reported_range, slant_range
from adcpdyn.models.janus import beam_to_instrument
from adcpdyn.models.kinematics import centre_of_rotation_depth
from adcpdyn.models.measurement import bottom_track_function
from adcpdyn.models.motion import SampledAttitude, attitude_function, evaluate_attitude
from adcpdyn.models.rotations import euler_matrix
from adcpdyn.solvers import ping_map
from adcpdyn.solvers.ping_map import MapOptions
from adcpdyn.solvers.rootfinder import RootfinderOptions, error_direction, solve_bottom_track



@pytest.mark.parametrize("scenario, timing", [("pool_m1", "deep"),
                                             pytest.param("deep_ocean", "deep", marks=pytest.mark.slow),  # 7.6 s
                                             pytest.param("deep_ocean", "exact", marks=pytest.mark.slow)])  # 6.5 s
def test_exact_solve_equals_scipy_root_ping_by_ping(scenario, timing):
    """Noisy radials (a nonzero error velocity) and lever arms 2 cm off the truth: the vectorised
    solve against scipy's hybrid root finder (finite-difference Jacobian, from zero) on the
    measurement model evaluated ping by ping."""
    case = simulate(get_scenario(scenario), seed=3)
    att = true_attitude(case)  # the vessel's: lever arms and installation angles in the vessel frame
    r = case.truth.radius_vectors_m + 0.02
    ypr_st = case.truth.installation_ypr_rad
    out = solve_bottom_track(**_ping_model(case, att, r, ypr_st, slice(None)), timing=timing)
    assert out["unconverged_pings"] == 0 and np.max(out["residual"]) < 1e-9
    bt = bottom_track_function(attitude_function(att.layout), timing)
    B = case.instrument.beam_directions()
    n = error_direction(beam_to_instrument(B)[1])
    g_depth = centre_of_rotation_depth(case.environment.transducer_depth_m, r)
    depth = case.environment.depth_at_pings(case.pings.n)
    for k in np.linspace(0, case.pings.n - 1, 4).astype(int):
        def residual(x):
            radial, _ = bt(case.pings.time_s[k], depth[k], g_depth, case.instrument.sound_speed_m_s, x[:3], att.pack(),
                           r, ypr_st, B)
            return np.asarray(radial).ravel() + x[3] * n - case.pings.bt_radial_m_s[k]

        ref = root(residual, np.zeros(4), method="hybr", options={"xtol": 1e-13})
        assert np.max(np.abs(residual(ref.x))) < 1e-11  # converged to rounding (its own flag can say "no progress")
        assert np.max(np.abs(out["V"][k] - ref.x[:3])) < 1e-9
        assert abs(out["e"][k] - ref.x[3]) < 1e-9
        # the residual reported (the attitude expanded about the closed form's receive times) is the model's
        assert abs(np.max(np.abs(residual(np.r_[out["V"][k], out["e"][k]]))) - out["residual"][k]) < 1e-11
    assert np.max(np.abs(out["e"])) > 1e-3  # the noise: not the trivial root


@pytest.mark.parametrize("tangential, timing, sampled", [("consistent", "deep", False), ("paper_literal", "shallow", False),
                                                         ("consistent", "deep", True)])
def test_closed_form_equals_eq_89_assembled_in_numpy(tangential, timing, sampled):
    """A and b of Eq. 89 from the model's Function against the same equation assembled from
    numeric attitude (:func:`evaluate_attitude`) at Eq. 68's receive times."""
    case = simulate(get_scenario("pool_m1"), seed=2)
    att = SampledAttitude(case.attitude.time_s, case.attitude.ypr()) if sampled else true_attitude(case)
    r, ypr_st = case.truth.radius_vectors_m, case.truth.installation_ypr_rad
    rows = np.arange(0, case.pings.n, 37)
    geo = _geometry(case, att, r, ypr_st, tangential, timing, rows=rows)
    t, v, c = case.pings.time_s[rows], case.pings.bt_radial_m_s[rows], case.instrument.sound_speed_m_s
    Lst, B = np.asarray(euler_matrix(*ypr_st)), case.instrument.beam_directions()

    def state(times, anchor=None):
        a = evaluate_attitude(att, times.ravel(), None if anchor is None else np.repeat(anchor, 4))
        Lam = a["Lambda"].reshape(times.shape + (3, 3))
        rate = a["dLambda_dt" if tangential == "consistent" else "Omega"].reshape(times.shape + (3, 3))
        return Lam, np.einsum("...ij,jk,bk->...bi", Lam, Lst, B), np.einsum("...ij,bj->...bi", rate, r)

    Lam_T, d_T, w_T = state(t)
    z_T = centre_of_rotation_depth(case.environment.transducer_depth_m, r) + Lam_T[:, 2, :] @ r.T
    l = reported_range(slant_range(case.environment.depth_at_pings(case.pings.n)[rows, None], z_T, d_T[..., 2]), v, c)
    t_R = np.repeat(t[:, None], 4, axis=1) if timing == "shallow" else receive_time_paper(t[:, None], l, c)
    _, d_R, w_R = state(t_R, t if sampled else None)
    beam = np.arange(4)
    d_R, w_R = d_R[:, beam, beam], w_R[:, beam, beam]  # beam i at its own receive time
    rho = ratio_from_radial(v, c)
    A = d_R + rho[..., None] * d_T
    b = (rho - 1) * c - (np.sum(w_R * d_R, axis=-1) + rho * np.sum(w_T * d_T, axis=-1))
    assert np.max(np.abs(geo["A"] - A)) < 1e-12
    assert np.max(np.abs(geo["b"] - b)) < 1e-9  # (rho - 1) c: differences of ~1500 m/s terms
    V = np.linalg.lstsq(A[0], b[0], rcond=None)[0]
    assert np.max(np.abs(geo["V"][0] - V)) < 1e-12


def test_mapped_evaluation_in_blocks_and_threads_equals_direct_calls(monkeypatch):
    monkeypatch.setattr(ping_map, "CHUNK", 7)
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 3)
    f = ca.Function("f", [x, p], [ca.vertcat(x[0] * p[0] + ca.sin(x[1]), p[1] * p[2]), ca.exp(x[0])])
    pf = ping_map.PingFunction(f)
    X = np.random.default_rng(1).normal(size=(30, 2))
    P = np.array([2.0, 3.0, 5.0])
    for threads in (1, 2, 3):
        a, b = pf(X, P, options=MapOptions(threads=threads, compile="never"))
        assert np.allclose(a, np.column_stack([2 * X[:, 0] + np.sin(X[:, 1]), np.full(30, 15.0)]), rtol=0, atol=1e-15)
        assert np.allclose(b[:, 0], np.exp(X[:, 0]), rtol=1e-15, atol=0)
    with pytest.raises(ValueError, match="column vectors"):
        ping_map.PingFunction(ca.Function("g", [p], [ca.horzcat(p, p)]))
    with pytest.raises(ValueError, match="threads"):
        MapOptions(threads=0)


def test_a_ping_without_a_root_is_nan_and_counted():
    """A ping whose bottom depth is unknown (NaN) goes through every Newton step and casadi.rootfinder
    and comes out NaN with its residual; the other pings are untouched."""
    case = simulate(get_scenario("pool_m1"), seed=1)
    args = _ping_model(case, true_attitude(case), case.truth.radius_vectors_m, case.truth.installation_ypr_rad,
                       np.arange(20))
    good = solve_bottom_track(**args)
    args["depth_m"] = args["depth_m"].copy()
    args["depth_m"][5] = np.nan
    out = solve_bottom_track(**args, options=RootfinderOptions(steps=2))
    assert out["newton_pings"] == out["fallback_pings"] == out["unconverged_pings"] == 1
    assert np.isnan(out["V"][5]).all() and np.isnan(out["e"][5]) and not out["residual"][5] <= 1e-9
    keep = np.arange(20) != 5
    assert np.array_equal(out["V"][keep], good["V"][keep])
    assert good["unconverged_pings"] == good["fallback_pings"] == 0 and np.max(good["residual"]) < 1e-9


@pytest.mark.slow  # 6.3 s
def test_pings_beyond_the_expansion_get_the_residual_evaluated_at_their_receive_times(monkeypatch):
    """With the expansion's reach set to zero every ping's residual is evaluated at the result's own
    receive times: the same residuals (to 1e-12 m/s in 300 m of water) and the same solution."""
    from adcpdyn.solvers import rootfinder

    case = simulate(get_scenario("deep_ocean"), seed=2)
    args = _ping_model(case, true_attitude(case), case.truth.radius_vectors_m + 0.01, case.truth.installation_ypr_rad,
                       np.arange(40))
    near = solve_bottom_track(**args)
    monkeypatch.setattr(rootfinder, "EXPANSION_MAX_STEP_S", 0.0)
    far = solve_bottom_track(**args)
    assert np.max(near["residual"]) > 1e-11  # deep water: the first Newton step leaves something to compare
    assert np.max(np.abs(far["residual"] - near["residual"])) < 1e-12
    assert np.array_equal(far["V"], near["V"])
