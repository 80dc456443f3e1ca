"""Sparse least-squares algebra of the diagnosis against dense closed forms, variance components
on a random walk with known levels, and the random-walk prior's rows in the measurement model."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import refit_without

from adcpdyn.estimators.statistics.normal_equations import (leave_out_predictions, log_det_normal, marginal_covariance,
                                                           quadratic_diagonal, factor, inverse_diagonal, redundancy)


def _problem(seed=0, n=400, p=12):
    rng = np.random.default_rng(seed)
    J = sp.random(n, p, density=0.3, random_state=seed, format="csr") + sp.eye(n, p, format="csr")
    return J.tocsr(), rng.normal(size=n)


def test_leverages_and_covariance_equal_the_dense_inverse():
    J, _ = _problem()
    Jd = J.toarray()
    A_inv = np.linalg.inv(Jd.T @ Jd)
    lu = factor((J.T @ J).tocsc(), 0.0)
    np.testing.assert_allclose(quadratic_diagonal(lu, J), np.einsum("ij,jk,ik->i", Jd, A_inv, Jd), rtol=1e-9)
    index = [3, 0, 7]
    np.testing.assert_allclose(marginal_covariance(J, index, 2.5), 2.5 * A_inv[np.ix_(index, index)], rtol=1e-6)


def test_the_inverse_diagonal_from_the_band_equals_the_dense_one():
    """diag(A^-1) of a banded SPD matrix (a velocity per ping's normal equations: blocks of runs, each
    banded) by Takahashi's recurrences equals the dense inverse's; a wide band takes the LU solves."""
    rng = np.random.default_rng(4)
    blocks = []
    for n in (40, 25):  # two runs: banded blocks, no coupling between them
        B = sp.random(n, n, density=1.0, random_state=rng).toarray()
        B = np.triu(np.tril(B, 3), -3)
        blocks.append(B @ B.T + n * np.eye(n))
    A = sp.block_diag(blocks, format="csc")
    dense = np.diag(np.linalg.inv(A.toarray()))
    np.testing.assert_allclose(inverse_diagonal(A), dense, rtol=1e-10)
    wide = sp.csc_matrix(A.toarray() + 0.01 * np.ones(A.shape))  # every unknown coupled: no band
    np.testing.assert_allclose(inverse_diagonal(wide), np.diag(np.linalg.inv(wide.toarray())), rtol=1e-9)


def test_log_det_of_the_normal_matrix_equals_the_dense_one():
    J, _ = _problem(seed=3)
    sign, dense = np.linalg.slogdet(J.toarray().T @ J.toarray())
    assert sign > 0
    assert log_det_normal(J) == pytest.approx(dense, rel=1e-9, abs=1e-6)


def test_random_walk_likelihood_is_marginal_over_the_velocities():
    """On a random-walk base the log-likelihood is the profiled one less 1/2 log det of the per-ping
    velocities' information at the profiled levels: that block of J^T J (dense here), rows reweighted
    from the fit's levels; halving every level adds n_V log 4."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.base import fit_base
    from adcpdyn.estimators.diagnosis.config import DiagnosisConfig
    from adcpdyn.estimators.measurement_model import VELOCITY_NAME

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=2)
    base, model, fit, sigma = fit_base([case], DiagnosisConfig(navigation="random_walk"))
    cols = np.flatnonzero(fit.free)
    latent = [c for c in cols if VELOCITY_NAME.fullmatch(model.names[c])]
    assert len(latent) == 3 * case.pings.n
    rss = fit.group_rss(model)
    levels = {k: np.sqrt(r / n) for k, (r, n) in rss.items() if n}
    ratio = np.array([fit.sigma[k] / levels[k] for k in model.sigma_keys])[model.row_sigma] * (model.mask > 0)
    Jv = ratio[:, None] * sp.csr_matrix(fit.jacobian).toarray()[:, latent]
    sign, dense = np.linalg.slogdet(Jv.T @ Jv)
    assert sign > 0
    assert fit.latent_log_det(model, levels) == pytest.approx(dense, rel=1e-7)
    profiled = sum(-0.5 * n * (np.log(2 * np.pi * r / n) + 1) for r, n in rss.values() if n)
    assert fit.log_likelihood(model) == pytest.approx(profiled - 0.5 * dense, rel=1e-9)
    halved = fit.latent_log_det(model, {k: 0.5 * v for k, v in levels.items()})
    assert halved - dense == pytest.approx(len(latent) * np.log(4.0), rel=1e-6)


def test_banded_selected_inversion_equals_the_dense_inverse():
    """Velocities per ping (each row on one or two neighbouring knots) plus global unknowns: the
    leverages by the band of B^-1 and a Schur complement equal diag(J A^-1 J^T) computed densely,
    and a wide band falls back to the solves."""
    from adcpdyn.estimators.statistics.normal_equations import (MAX_SYMBOLIC_BAND, arrow_leverages, band_of_inverse,
                                                                leverages, ridged)
    from scipy.linalg import cholesky_banded

    rng = np.random.default_rng(3)
    knots, g, m = 60, 7, 1500
    I, C = [], []
    for r in range(m):
        j = int(rng.integers(0, knots - 1))
        cols = list(range(3 * j, 3 * j + (6 if rng.random() < 0.5 else 3))) + list(3 * knots + rng.choice(g, 3, replace=False))
        I += [r] * len(cols)
        C += cols
    J = sp.csr_matrix((rng.normal(size=len(I)), (I, C)), shape=(m, 3 * knots + g))
    A = ridged((J.T @ J).tocsc())
    Jd, Ad = J.toarray(), A.toarray()
    dense = np.einsum("ij,jk,ik->i", Jd, np.linalg.inv(Ad), Jd)
    local = np.arange(J.shape[1]) < 3 * knots
    np.testing.assert_allclose(leverages(A, J, local), dense, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(leverages(A, J), dense, rtol=1e-8, atol=1e-12)
    B = Ad[:3 * knots, :3 * knots]
    Binv = np.linalg.inv(B)
    for p in (5, MAX_SYMBOLIC_BAND + 4):  # the recurrence as a CasADi mapaccum, and stepped in numpy past its band
        ab = np.array([np.concatenate([np.diag(B, -d), np.zeros(d)]) for d in range(p + 1)])  # B's band is 5 wide
        zb = band_of_inverse(cholesky_banded(ab, lower=True))
        for d in range(p + 1):
            np.testing.assert_allclose(zb[d, :3 * knots - d], np.diag(Binv, -d), rtol=1e-8, atol=1e-12)
    assert arrow_leverages(A, J, np.ones(J.shape[1], dtype=bool)) is None  # the globals make the band wide


def test_differenced_fixes_windows_keep_the_banded_inversion():
    """A reference velocity differenced from two fixes is the mean over its window: its row touches every
    ping inside (winriver01: a band of 27 in the velocities' block). The selected inversion takes that
    band, and its leverages still equal the dense diag(J A^-1 J^T)."""
    from adcpdyn.estimators.statistics.normal_equations import arrow_leverages, ridged

    rng = np.random.default_rng(8)
    knots, g = 120, 5
    rows = [list(range(3 * j, 3 * j + 6)) for j in range(knots - 1) for _ in range(4)]  # pings' beams: two knots
    rows += [list(range(3 * j, min(3 * j + 27, 3 * knots), 3)) for j in range(0, knots - 9, 3)]  # windows of 9 pings
    rows = [r + list(3 * knots + rng.choice(g, 2, replace=False)) for r in rows]
    I = np.concatenate([[i] * len(r) for i, r in enumerate(rows)])
    J = sp.csr_matrix((rng.normal(size=I.size), (I, np.concatenate(rows))), shape=(len(rows), 3 * knots + g))
    A = ridged((J.T @ J).tocsc())
    local = np.arange(J.shape[1]) < 3 * knots
    Jd = J.toarray()
    dense = np.einsum("ij,jk,ik->i", Jd, np.linalg.inv(A.toarray()), Jd)
    h = arrow_leverages(A, J, local)
    assert h is not None  # the band (24 here) is taken, not the solves
    np.testing.assert_allclose(h, dense, rtol=1e-8, atol=1e-12)


def test_redundancies_share_the_degrees_of_freedom():
    """sum_g r_g = n - p (the trace of I - H), each r_g = n_g - sum of its leverages."""
    J, _ = _problem(1)
    Jd = J.toarray()
    group = np.arange(J.shape[0]) % 3
    r = redundancy(J, group, np.ones(J.shape[0], dtype=bool), 3)
    h = np.einsum("ij,jk,ik->i", Jd, np.linalg.inv(Jd.T @ Jd), Jd)
    assert r.sum() == pytest.approx(J.shape[0] - J.shape[1], rel=1e-9)
    np.testing.assert_allclose(r, [np.sum(1 - h[group == g]) for g in range(3)], rtol=1e-9)


def test_leave_out_predictions_equal_refits_without_the_fold():
    J, y = _problem(2)
    Jd = J.toarray()
    x = np.linalg.lstsq(Jd, y, rcond=None)[0]
    e = Jd @ x - y
    fold = np.arange(J.shape[0]) // 50 % 4
    pred = leave_out_predictions(J, e, np.ones(J.shape[0], dtype=bool), fold, damping=0.0)
    for k in range(4):
        np.testing.assert_allclose(pred[fold == k], refit_without(Jd, y, fold != k), atol=1e-8)


@pytest.mark.slow  # 7 s: `make test-slow`, CI's second step
def test_variance_components_recover_a_random_walk_and_its_noise():
    """A velocity per ping, a random walk of intensity sqrt(q) = 0.05 m/s/sqrt(s), seen at every ping
    with noise 0.02 m/s (as the bottom track) and every fifth with 0.1 m/s (as the reference):
    iterated Helmert estimates (sigma_g^2 = RSS_g / r_g) find all three levels."""
    rng = np.random.default_rng(4)
    n, q_sqrt, s_bt, s_ref = 3000, 0.05, 0.02, 0.1
    t = np.cumsum(rng.uniform(0.3, 0.7, n))
    v = np.concatenate([[0.0], np.cumsum(q_sqrt * np.sqrt(np.diff(t)) * rng.normal(size=n - 1))])
    ref = np.arange(0, n, 5)
    D = sp.diags([-1.0, 1.0], [0, 1], shape=(n - 1, n)).tocsr()
    A = sp.vstack([sp.eye(n), sp.eye(n, format="csr")[ref], sp.diags(1 / np.sqrt(np.diff(t))) @ D]).tocsr()
    y = np.concatenate([v + s_bt * rng.normal(size=n), v[ref] + s_ref * rng.normal(size=ref.size), np.zeros(n - 1)])
    group = np.repeat([0, 1, 2], [n, ref.size, n - 1])
    sigma = np.array([0.1, 0.1, 0.1])
    for _ in range(12):  # within 2 % of the 30-iteration levels, well inside the 12 % asked
        w = 1.0 / sigma[group]
        J = sp.diags(w) @ A
        x = sp.linalg.spsolve((J.T @ J).tocsc(), J.T @ (w * y))
        res = A @ x - y
        r = redundancy(J, group, np.ones(group.size, dtype=bool), 3)
        sigma = np.sqrt([np.sum(res[group == g] ** 2) / r[g] for g in range(3)])
    np.testing.assert_allclose(sigma, [s_bt, s_ref, q_sqrt], rtol=0.12)


def test_random_walk_rows_are_velocity_increments_over_root_dt():
    """The base's motion rows are (V_j+1 - V_j) / sqrt(t_j+1 - t_j) of its per-ping horizontal
    velocities, its vertical rows the per-ping vertical velocity itself (a floating boat heaves about
    zero, it does not drift up or down), both levels estimated from the data beside the noise levels."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.base import fit_base
    from adcpdyn.estimators.diagnosis.config import DiagnosisConfig

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=1)
    base, model, fit, sigma = fit_base([case], DiagnosisConfig(navigation="random_walk"))
    knots = base.runs[0].knots
    np.testing.assert_array_equal(knots, case.pings.time_s)
    sl = model.channel_slices()
    for axis, channel in zip("xy", ("motion_north", "motion_east")):
        V = np.array([fit.x[model.names.index(f"V{j}_{axis}")] for j in range(knots.size)])
        np.testing.assert_allclose(fit.raw[sl[channel]], np.diff(V) / np.sqrt(np.diff(knots)), atol=1e-12)
    assert "motion_down" not in sl
    W = np.array([fit.x[model.names.index(f"V{j}_z")] for j in range(knots.size)])
    np.testing.assert_allclose(fit.raw[sl["vertical_down"]], W, atol=1e-12)
    for group in ("motion", "vertical"):
        assert 0 < sigma[(0, group)] < 1.0 and sigma[(0, group)] != base.sigma0[(0, group)]
    with pytest.raises(ValueError, match="navigation: expected one of"):
        DiagnosisConfig(navigation="spline")


def test_auto_navigation_walks_where_a_real_boat_is_under_way():
    """auto: a velocity per ping where the sensor's samples are in the beams (a real boat) and no
    reference holds the run still, with or without a moving reference, or where the motion model
    follows the attitude only beyond the sensors' noise (irregular); knots where a motion model
    follows the attitude or the reference stays put."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.run_setup import choose_navigation

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=2)
    assert case.reference is not None and not case.reference.stationary
    assert choose_navigation(case, "samples") == "random_walk"
    assert choose_navigation(case, "model") == "knots"
    assert choose_navigation(case, "model", irregular=True) == "random_walk"
    assert choose_navigation(case, "frozen", irregular=True) == "knots"  # the two-stage method's fixed attitude
    still = case.replace(reference=dataclasses.replace(case.reference, stationary=True))
    assert choose_navigation(still, "samples") == "knots"
    assert choose_navigation(still, "model", irregular=True) == "knots"
    assert choose_navigation(case.replace(reference=None), "samples") == "random_walk"  # the bottom track alone follows it
    assert choose_navigation(case.replace(reference=None), "model") == "knots"
    assert choose_navigation(case, "samples", "knots") == "knots"
    with pytest.raises(ValueError, match="navigation: expected one of"):
        choose_navigation(case, "samples", "spline")


def test_reference_latency_model_is_the_velocity_a_delay_earlier():
    """The hook's v(t - d0) - (d - d0) v'(t - d0), the slope from the knots, equals v(t - d) for a
    velocity linear in time whatever the expansion point, and to second order in d - d0 otherwise."""
    import casadi as ca

    from adcpdyn.estimators.knots import hat_basis_dm, navigation_slope
    from adcpdyn.models.effects import get_effect

    knots = np.arange(0.0, 60.0, 0.05)
    t_ref = np.linspace(10.0, 50.0, 41)
    effect = get_effect("reference_latency")
    linear = lambda t: np.column_stack([0.5 + 0.04 * t, -0.2 + 0.01 * t, 0.0 * t])
    curved = lambda t: np.column_stack([0.5 + 0.04 * t - 0.001 * t**2, -0.2 + 0.01 * t, 0.0 * t])
    for velocity, delay, shift, tol in ((linear, 1.5, 0.0, 1e-9), (linear, -0.7, 0.4, 1e-9), (curved, 1.1, 1.0, 2e-5)):
        V = ca.DM(velocity(knots))
        ctx = SimpleNamespace(reference_slope=navigation_slope(t_ref - shift, knots, V), reference_shift_s=shift)
        v = ca.mtimes(hat_basis_dm(t_ref - shift, knots), V)
        got = np.asarray(ca.evalf(effect.reference_velocity(v, ctx, ca.DM([delay]))))
        np.testing.assert_allclose(got, velocity(t_ref - delay), atol=tol)


def test_reference_latency_is_recorded_as_late_time_stamps():
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.selftest import with_effect

    sc = get_scenario("diag_boat")
    sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0))
    clean, late = simulate(sc, seed=5), simulate(with_effect(sc, "reference_latency", {"delay_s": 1.25}), seed=5)
    np.testing.assert_allclose(late.reference.time_s, clean.reference.time_s + 1.25)
    np.testing.assert_array_equal(late.reference.velocity_m_s, clean.reference.velocity_m_s)
    np.testing.assert_array_equal(late.pings.bt_radial_m_s, clean.pings.bt_radial_m_s)


def test_field_errors_are_written_on_the_recorded_channels():
    """Each injected field error changes only its channel, by the stated amount; bad names and an
    error needing a reference on a run without one are refused in one line."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.field_errors import FIELD_ERRORS, inject

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=2)
    turned = inject(case, "compass_offset_deg", 3.0)
    np.testing.assert_allclose(turned.attitude.heading_rad - case.attitude.heading_rad, np.radians(3.0))
    np.testing.assert_array_equal(turned.pings.bt_radial_m_s, case.pings.bt_radial_m_s)
    late = inject(case, "attitude_latency_s", 0.4)
    np.testing.assert_allclose(late.attitude.time_s - case.attitude.time_s, 0.4)
    ref_late = inject(case, "reference_latency_s", 1.5)
    np.testing.assert_allclose(ref_late.reference.time_s - case.reference.time_s, 1.5)
    bed = inject(case, "moving_bed_m_s", 0.2)
    u = bed.reference.velocity_m_s - case.reference.velocity_m_s
    v = np.nanmean(case.reference.velocity_m_s, axis=0)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 0.2)
    assert abs(u[0] @ v) < 1e-9 and v[0] * u[0, 1] - v[1] * u[0, 0] < 0  # across the course, to port (course - 90 deg)
    fast = inject(case, "sound_speed_relative", 0.03)
    np.testing.assert_allclose(fast.pings.bt_radial_m_s, 1.03 * case.pings.bt_radial_m_s)
    slow = inject(case, "tilt_lowpass_s", 1.0)
    np.testing.assert_array_equal(slow.attitude.heading_rad, case.attitude.heading_rad)
    assert np.std(slow.attitude.roll_rad) < np.std(case.attitude.roll_rad)
    heave = inject(case, "heave_m_s", 0.1)
    c = np.cos(case.instrument.beam_angle_rad)
    dr = heave.pings.bt_radial_m_s - case.pings.bt_radial_m_s
    np.testing.assert_allclose(dr, dr[:, :1] * np.ones((1, 4)))  # the same vertical velocity on every beam
    assert np.max(np.abs(dr)) == pytest.approx(0.1 * c, rel=0.01)
    assert set(FIELD_ERRORS) == {"compass_offset_deg", "attitude_latency_s", "reference_latency_s", "moving_bed_m_s",
                                 "sound_speed_relative", "tilt_lowpass_s", "heave_m_s"}
    with pytest.raises(ValueError, match="error: expected one of"):
        inject(case, "compass", 1.0)
    with pytest.raises(ValueError, match="needs a moving reference"):
        inject(case.replace(reference=None), "moving_bed_m_s", 0.1)


def test_colour_factor_is_one_for_white_gains_and_large_for_a_slow_wander():
    """The long-run over white variance of the per-bin likelihood gains: about 1 for white gains,
    near (1 + rho) / (1 - rho) = 9 for AR(1) gains with rho = 0.8 (Bartlett-shrunk below it)."""
    from adcpdyn.estimators.diagnosis.heldout import colour_factor

    rng = np.random.default_rng(7)
    n = 4000
    t = np.arange(n) * 0.5
    case = SimpleNamespace(pings=SimpleNamespace(time_s=t))
    model = SimpleNamespace(sigma_keys=[(0, "bt")], row_sigma=np.zeros(n, dtype=int), mask=np.ones(n), row_run=np.zeros(n, dtype=int),
                            times=t, base=SimpleNamespace(runs=[SimpleNamespace(case=case)]))
    fit = SimpleNamespace(raw=np.zeros(n))
    white = rng.normal(size=n)
    ar = np.zeros(n)
    for i in range(1, n):
        ar[i] = 0.8 * ar[i - 1] + rng.normal()
    factors = []
    for d in (white, ar):
        ref = SimpleNamespace(raw=np.sqrt(d - d.min() + 1.0))  # (ref/s)^2 - 0 = d + const: the constant is centred out
        factors.append(colour_factor(model, fit, model, ref, {(0, "bt"): 1.0}))
    assert 1.0 <= factors[0] < 1.3
    assert 4.0 < factors[1] < 10.0


def test_lowpass_of_samples_matches_the_closed_form_step_and_ramp_responses():
    """The injected tilt low-pass against closed forms: a ramp x = t gives y = t - tau (1 - exp(-t/tau)),
    on irregular sample times; a constant passes unchanged."""
    from adcpdyn.estimators.diagnosis.field_errors import lowpass

    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.2, 0.9, 200))
    t -= t[0]
    tau = 0.8
    np.testing.assert_allclose(lowpass(t, t, tau), t - tau * (1 - np.exp(-t / tau)), atol=1e-12)
    np.testing.assert_allclose(lowpass(t, np.full(t.size, 0.3), tau), 0.3)


def test_field_selftest_injects_only_the_errors_its_candidates_can_name():
    """By default every field error at its typical sizes; with the candidates restricted (--effects),
    only the errors one of them can name: an error no candidate could name is not counted a miss."""
    from adcpdyn.estimators.diagnosis.diagnose import DiagnosisConfig
    from adcpdyn.estimators.diagnosis.field_errors import FIELD_ERRORS
    from adcpdyn.estimators.diagnosis.field_selftest import default_sizes

    assert default_sizes(DiagnosisConfig()) == {e: spec[2] for e, spec in FIELD_ERRORS.items()}
    assert default_sizes(DiagnosisConfig(effects=("moving_bed", "heave", "surge"))) == {
        "moving_bed_m_s": FIELD_ERRORS["moving_bed_m_s"][2], "heave_m_s": FIELD_ERRORS["heave_m_s"][2]}


@pytest.mark.slow  # 13 s: `make test-slow`, CI's second step
def test_field_selftest_reports_what_a_file_can_detect(tmp_path):
    """A clean run and an injected bed across the course on the file's own motion, diagnosed blind:
    the bed is named first, the table and the files say so; the CLI refuses a call without --out."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.cli import main
    from adcpdyn.estimators.diagnosis.diagnose import DiagnosisConfig
    from adcpdyn.estimators.diagnosis.field_selftest import field_selftest, format_field_selftest, write_field_selftest

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=40.0)), seed=3)
    res = field_selftest(case, None, DiagnosisConfig(effects=("moving_bed", "attitude_latency")),
                         sizes={"moving_bed_m_s": [0.3]})
    assert [r["error"] for r in res["rows"]] == ["clean", "moving_bed_m_s"]
    clean, bed = res["rows"]
    assert clean["verdict"] == "none" and bed["hit"] and bed["verdict"].startswith("moving_bed")
    assert (clean["outcome"], bed["outcome"]) == ("clean", "named")
    assert res["summary"]["per_error"]["moving_bed_m_s"]["smallest_detected"] == 0.3
    assert "| moving_bed_m_s | 0.3 m/s | moving_bed" in format_field_selftest(res)
    written = write_field_selftest(res, tmp_path / "self.json")
    assert all(p.exists() for p in written)
    # the base that follows the boat (a velocity per ping, coloured-residual BIC) names it too, and not the clean run
    walk = field_selftest(case, None, DiagnosisConfig(effects=("moving_bed", "attitude_latency"), navigation="random_walk"),
                          sizes={"moving_bed_m_s": [0.3]})
    assert [r["verdict"] for r in walk["rows"]] == ["none", "moving_bed"]
    assert "random-walk prior" in walk["rows"][1]["statement"] and "random-walk" not in res["rows"][1]["statement"]
    assert main(["diagnose", str(tmp_path / "x.h5"), "--field-selftest"]) == 2  # one line: expects --out


@pytest.mark.slow  # a survey's field self-test: `make test-slow`, CI's second step
def test_field_selftest_of_a_survey_writes_one_error_into_every_run():
    """Two transects of a river survey (there and back), calibrated jointly: each field error is
    written into both runs as one boat on one river meets it (the bed one velocity across the
    survey's mean course, the compass offset the same turn of every heading) and the survey is
    diagnosed jointly: the compass offset and the bed, which one course confounds, are each named."""
    from adcpdyn import api
    from adcpdyn.cases.survey import simulate_survey
    from adcpdyn.estimators.diagnosis.field_errors import inject_survey, survey_course

    cases = simulate_survey("river_survey", 2, 5, compass_rad=(0.0, 0.0, 0.0), bed_speed_m_s=0.0)
    bed = inject_survey(cases, "moving_bed_m_s", 0.2)
    added = [b.reference.velocity_m_s - c.reference.velocity_m_s for b, c in zip(bed, cases)]
    course = survey_course(cases)
    np.testing.assert_allclose(added[0], added[1])
    np.testing.assert_allclose(added[0][0], 0.2 * np.array([np.cos(course - np.pi / 2), np.sin(course - np.pi / 2), 0.0]))
    res = api.field_selftest(cases, None, effects=["compass_offset", "moving_bed"],
                             sizes={"compass_offset_deg": [3.0], "moving_bed_m_s": [0.2]})
    assert res["case"] == "+".join(c.name for c in cases) and "jointly" in res["notes"][-1]
    assert [(r["error"], r["verdict"]) for r in res["rows"]] == [
        ("clean", "none"), ("compass_offset_deg", "compass_offset"), ("moving_bed_m_s", "moving_bed")]


@pytest.mark.slow  # 30 s: `make test-slow`, CI's second step
def test_field_selftest_holds_the_files_own_effects():
    """A file that carries an effect of its own (here attitude samples stamped 0.5 s late) has it found
    on top of its calibration and held at its value in every run's diagnosis: the clean run names nothing
    new, an injected bed is named, and a further 0.5 s of the same latency is named as that effect moved
    from its value (it read 0.5 s, the run now holds 1.0)."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.diagnose import DiagnosisConfig
    from adcpdyn.estimators.diagnosis.field_errors import inject
    from adcpdyn.estimators.diagnosis.field_selftest import field_selftest

    sc = get_scenario("diag_boat")
    case = inject(simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=40.0)), seed=3),
                  "attitude_latency_s", 0.5)
    res = field_selftest(case, None, DiagnosisConfig(effects=("moving_bed", "attitude_latency")),
                         sizes={"moving_bed_m_s": [0.3], "attitude_latency_s": [0.5]})
    clean, bed, late = res["rows"]
    assert res["own_effects"] == ["attitude_latency"] and res["own_effects_from"] == "found here"
    assert clean["verdict"] == "none" and clean["own_effects"] == ["attitude_latency"]
    assert bed["hit"] and bed["verdict"] == "moving_bed"
    assert bed["statement"].startswith("on top of the run's own attitude_latency.delay_s = 0.5")
    assert late["hit"] and late["verdict"] == "attitude_latency"
    assert late["estimate"]["attitude_latency.delay_s"] == pytest.approx(1.0, abs=0.1)
    with pytest.raises(ValueError, match="unknown effect|expected one of"):
        DiagnosisConfig(given=("no_such_effect",))
    with pytest.raises(ValueError, match=r"given_values: expected the unknowns of every given effect \['heave'\]"):
        DiagnosisConfig(given=("heave",), given_values=(("moving_bed.velocity_north_m_s", 0.0, 0.01),))


def test_field_selftest_says_why_an_error_was_not_named():
    """Not named because the file cannot show it (its effect alone not significant), because it was
    not tried (and why), or because another effect was preferred: three different statements."""
    from types import SimpleNamespace

    from adcpdyn.estimators.diagnosis.field_selftest import outcome

    result = SimpleNamespace(base={"navigation": "random_walk", "skipped_effects": {"reference_latency": "no reference"}},
                             gap_before=0.4)
    row = {"expected": "moving_bed", "verdict": "compass_offset", "hit": False}
    mine = {"delta_bic_hac": -27.4, "delta_bic": -40.0, "shrink_fraction": 0.33, "significant": True}
    assert outcome(row, mine, result) == "outscored by compass_offset (BIC change -27, shrink 33 %)"
    assert outcome({**row, "verdict": "none"}, {**mine, "significant": False}, result).startswith("below detection (BIC")
    assert outcome({**row, "expected": "reference_latency"}, None, result) == "not tried: no reference"
    flat = SimpleNamespace(base=result.base, gap_before=-0.2)  # nothing to explain: not the effect's detection limit
    assert outcome({**row, "verdict": "none"}, {**mine, "significant": False}, flat).startswith("no gap to explain (held-out")
    assert outcome({**row, "hit": True, "verdict": "moving_bed"}, mine, result) == "named"
    assert outcome({"expected": "none", "verdict": "heave", "hit": False}, None, result) == "names heave"
    own_peak = {**row, "verdict": "none", "expected": "attitude_latency", "size": 1.0, "unit": "s", "detection_limit": 2.0,
                "detection_limit_beyond": True, "detection_limit_reason": "its own delay peak"}
    assert outcome(own_peak, {**mine, "significant": False}, result).startswith(
        "under the file's detection limit (1 s: its own delay peak; BIC")


@pytest.mark.slow  # 11 s: `make test-slow`, CI's second step
def test_detection_limit_is_the_size_the_selection_takes():
    """The clean run's detection limit (HAC standard error times sqrt(k log n + margin)) splits the
    sizes the diagnosis names from those it cannot: three times it is named, a third of it is not."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.diagnose import DiagnosisConfig, diagnose
    from adcpdyn.estimators.diagnosis.field_errors import detection_limit, inject

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=40.0)), seed=5)
    config = DiagnosisConfig(effects=("sound_speed_error", "moving_bed"), navigation="random_walk")
    clean = diagnose(case, config)
    score = next(s for s in clean.ranking if s["effect"] == "sound_speed_error")
    limit = detection_limit("sound_speed_relative", score["detection_limit"])
    se = score["params_se"]["sound_speed_error.relative_error"]
    assert clean.verdict == "none" and limit == pytest.approx(se * np.sqrt(np.log(clean.base["n_observations"]) + 10.0))
    assert diagnose(inject(case, "sound_speed_relative", 3 * limit), config).verdict == "sound_speed_error"
    assert diagnose(inject(case, "sound_speed_relative", limit / 3), config).verdict == "none"
    assert detection_limit("compass_offset_deg", {"compass_offset.A_rad": 0.01}) == pytest.approx(np.degrees(0.01))
    assert detection_limit("moving_bed_m_s", {"moving_bed.velocity_north_m_s": 0.02, "moving_bed.velocity_east_m_s": 0.05}) == 0.05
    assert detection_limit("heave_m_s", {"heave.cos_m": 0.01}) is None  # frequency-dependent: not claimed
    assert detection_limit("tilt_lowpass_s", {"tilt_lowpass.tau_s": 0.1}) is None  # its linearisation is optimistic


def test_eliminating_local_unknowns_gives_the_dense_uncertainty():
    """uncertainty_eliminating (the velocities per ping eliminated by a Schur complement) equals the
    dense uncertainty: every SE, the covariance columns of the kept unknowns, and which derived
    quantities an undetermined direction leaves undetermined (a constraint on the kept ones, and a
    kept unknown no row touches)."""
    from adcpdyn.estimators.statistics.uncertainty import uncertainty, uncertainty_eliminating

    rng = np.random.default_rng(3)
    n_v, n_s = 30, 4  # a walk of 30 velocities (banded rows) and 4 shared unknowns, the last one in no row
    rows = []
    for j in range(n_v):  # a measurement of each velocity with the shared unknowns, and the walk's increments
        r = np.zeros(n_v + n_s)
        r[j], r[n_v:n_v + 3] = 1.0, rng.normal(size=3)
        rows.append(r)
        if j:
            d = np.zeros(n_v + n_s)
            d[j], d[j - 1] = 2.0, -2.0
            rows.append(d)
    J = np.array(rows)
    A = np.zeros((1, n_v + n_s))
    A[0, n_v], A[0, n_v + 1] = 1.0, -1.0  # the first two shared unknowns tied together
    names = [f"V{j}_x" for j in range(n_v)] + ["a", "b", "c", "d"]
    scale = np.ones(n_v + n_s)
    local = np.arange(n_v + n_s) < n_v
    dense = uncertainty(J, A, names, scale)
    elim = uncertainty_eliminating(sp.csr_matrix(J), A, names, scale, local)
    finite = np.isfinite(dense.se_z)
    assert np.array_equal(finite, np.isfinite(elim.se_z)) and not finite[-1]
    np.testing.assert_allclose(elim.se_z[finite], dense.se_z[finite], rtol=1e-8)
    kept = np.arange(n_v, n_v + 3)
    np.testing.assert_allclose(elim.cov_columns(kept), dense.cov_z[:, kept], rtol=1e-7, atol=1e-12)
    derived = np.eye(n_v + n_s)[[n_v, n_v + 2, n_v + 3]]  # a, c, d: d is not determined
    assert list(elim.determined_mask(derived)) == list(dense.determined_mask(derived)) == [True, True, False]
    with pytest.raises(ValueError, match="only the unknowns kept"):
        elim.cov_columns([0])
    # the velocities marked as the boat's own (a mask over all unknowns) follow the elimination
    on_boat = uncertainty_eliminating(sp.csr_matrix(J), A, names, scale, local, {"navigation": local})
    said = [w for w in on_boat.warnings if "not determined" in w]  # weak ones differ: the velocities' are gone
    assert len(said) == 1 and said[0].startswith("1 direction(s)") and said[0].endswith(": d alone")
    with pytest.raises(ValueError, match="navigation"):
        uncertainty(J, A, names, scale, {"navigation": local[:-1]})


def test_errors_that_need_a_reference_are_those_written_into_it_or_seen_only_against_it():
    # the bed and the reference delay are written into the reference velocity; a constant compass offset
    # turns every velocity alike; the others act on the beams, their attitude or their ranges
    from adcpdyn.estimators.diagnosis.field_errors import FIELD_ERRORS, needs_reference

    assert {e for e in FIELD_ERRORS if needs_reference(e)} == {"compass_offset_deg", "reference_latency_s", "moving_bed_m_s"}


@pytest.mark.slow  # a field self-test: `make test-slow`, CI's second step
def test_field_selftest_without_a_reference_does_not_try_a_compass_offset():
    """Without a moving reference a constant compass offset turns every velocity alike: nothing tells it,
    so the self-test lists it as not tried (with the bed and the reference latency) and reports no
    detection limit for it, where a linearised signal limit would have given one."""
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.diagnosis.diagnose import DiagnosisConfig
    from adcpdyn.estimators.diagnosis.field_selftest import field_selftest, format_field_selftest

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=40.0)), seed=3)
    case = case.replace(reference=None)
    res = field_selftest(case, None, DiagnosisConfig(effects=("heave", "compass_offset")),
                         sizes={"compass_offset_deg": [4.0], "heave_m_s": [0.15], "moving_bed_m_s": [0.3]})
    assert [r["error"] for r in res["rows"]] == ["clean", "heave_m_s"]
    assert res["skipped"] == ["compass_offset_deg", "moving_bed_m_s"]
    assert "compass_offset_deg" not in res["rows"][0]["signal_limits"]
    assert "- compass_offset_deg: not tried (needs a moving reference velocity)" in format_field_selftest(res)
