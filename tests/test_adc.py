"""Per-ping dynamic correction: limits, the oracle on noise-free data, rootfinder vs closed form."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import noise_free

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cli import main
from adcpdyn.estimators.correction.adc import dynamic_correction
from adcpdyn.estimators.asc import asc
from adcpdyn.estimators.calibration.record import CalibrationRecord
from adcpdyn.models.rotations import euler_matrix
from adcpdyn.cases.simulation import simulate


def truth_calibration(case) -> CalibrationRecord:
    """A calibration holding the simulator's true lever arms (what CALIB.json would hold)."""
    t = case.truth
    head = t.radius_vectors_m @ np.asarray(euler_matrix(*t.installation_ypr_rad))
    return CalibrationRecord.from_dict({"radius_vectors_m": t.radius_vectors_m.tolist(), "radius_vectors_head_m": head.tolist(),
                                        "installation_ypr_rad": t.installation_ypr_rad.tolist()})


def test_no_rotation_dynamic_equals_static_correction(pool_still):
    case = simulate(noise_free(pool_still), seed=2)
    static = asc(case).vessel_velocity_m_s
    for method in ("adc", "rootfinder"):
        dyn = dynamic_correction(case, method, truth_calibration(case)).vessel_velocity_m_s
        assert np.max(np.abs(dyn - static)) < 1e-9
        assert np.max(np.abs(dyn - case.truth.vessel_velocity_m_s)) < 1e-9


def test_oracle_removes_the_swaying_error_on_noise_free_data():
    case = simulate(noise_free(get_scenario("pool_m1")), seed=4)
    truth = case.truth.vessel_velocity_m_s
    oracle = dynamic_correction(case, "oracle").vessel_velocity_m_s
    static = asc(case).vessel_velocity_m_s
    rms = lambda v: np.sqrt(np.mean(np.sum((v - truth) ** 2, axis=1)))
    assert rms(oracle) < 1e-4 < 0.01 < rms(static)


def test_rootfinder_agrees_with_closed_form_in_shallow_water(pool_m0):
    case = simulate(noise_free(get_scenario("pool_m1")), seed=5)
    calib = truth_calibration(case)
    adc = dynamic_correction(case, "adc", calib)
    rf = dynamic_correction(case, "rootfinder", calib)
    assert np.max(np.abs(adc.vessel_velocity_m_s - rf.vessel_velocity_m_s)) < 1e-6
    assert np.nanmax(np.abs(rf.error_velocity_m_s)) < 1e-3


def test_lost_beam_falls_back_to_three_beams_and_says_so():
    case = simulate(noise_free(get_scenario("pool_m1")), seed=6)
    bt = case.pings.bt_radial_m_s.copy()
    bt[3, 1] = np.nan
    bt[5, :2] = np.nan
    case = case.replace(pings=dataclasses.replace(case.pings, bt_radial_m_s=bt))
    out = dynamic_correction(case, "rootfinder", truth_calibration(case))
    assert out.beams_used[3] == 3 and out.beams_used[5] == 2
    assert np.all(np.isfinite(out.vessel_velocity_m_s[3])) and np.all(np.isnan(out.vessel_velocity_m_s[5]))
    assert np.isnan(out.error_velocity_m_s[3])


def test_methods_need_a_calibration_and_a_known_name():
    case = simulate(get_scenario("pool_m1"), seed=1)
    with pytest.raises(ValueError, match="calibration"):
        dynamic_correction(case, "adc")
    with pytest.raises(ValueError, match="method"):
        dynamic_correction(case, "magic", truth_calibration(case))
    with pytest.raises(ValueError, match="null"):
        dynamic_correction(case, "adc", CalibrationRecord.from_dict({"radius_vectors_head_m": [[None] * 3] * 4}))


def test_compare_and_correct_from_the_command_line(tmp_path, capsys):
    m0, m1, calib = tmp_path / "m0.h5", tmp_path / "m1.h5", tmp_path / "calib.json"
    assert main(["simulate", "pool_m0", "--seed", "1", "--out", str(m0)]) == 0
    assert main(["simulate", "pool_m1", "--seed", "1", "--out", str(m1)]) == 0
    assert main(["calibrate", str(m0), "--starts", "2", "--out", str(calib)]) == 0
    assert main(["correct", str(m1), "--method", "adc", "--calibration", str(calib), "--out", str(tmp_path / "o.h5")]) == 0
    capsys.readouterr()
    assert main(["compare", str(m1), "--calibration", str(calib), "--out", str(tmp_path / "cmp")]) == 0
    table = capsys.readouterr().out
    for method in ("asc", "adc", "paper_literal", "rootfinder", "oracle", "truth"):
        assert method in table
    assert (tmp_path / "cmp" / "pool_m1_compare.png").exists()


def test_deep_ocean_timing_matters_and_rootfinder_reaches_the_oracle():
    sc = get_scenario("deep_ocean")
    sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=200.0, water=None))
    case = simulate(sc, seed=3)
    calib, truth = truth_calibration(case), case.truth.vessel_velocity_m_s
    rms = lambda c: np.sqrt(np.nanmean(np.sum((c.vessel_velocity_m_s - truth) ** 2, axis=1)))
    shallow = rms(dynamic_correction(case, "adc", calib, timing="shallow"))
    rootfinder = rms(dynamic_correction(case, "rootfinder", calib))
    oracle = rms(dynamic_correction(case, "oracle"))
    assert rootfinder <= 0.5 * shallow
    assert rootfinder <= 1.1 * oracle


def test_water_profile_no_rotation_limit():
    from adcpdyn.models.motion import AttitudeParams

    sc = noise_free(get_scenario("deep_ocean"))
    still = AttitudeParams.from_axis_modes([], 0.0, [], 0.0, [0.3])
    sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, motion=still, duration_s=20.0))
    case = simulate(sc, seed=1)
    out = dynamic_correction(case, "rootfinder", truth_calibration(case))
    ok = np.isfinite(out.water_velocity_m_s[..., 0])
    assert ok.mean() > 0.5
    assert np.max(np.abs(out.water_velocity_m_s[ok] - case.truth.water_velocity_m_s[ok])) < 1e-6


@pytest.mark.slow  # 10 s: `make test-slow`, CI's second step
def test_pings_the_newton_steps_leave_unconverged_go_to_casadi_rootfinder():
    """With no Newton step the closed form's pings stay ~1e-5 m/s off and casadi.rootfinder
    must finish them: same answer as the default iteration."""
    from adcpdyn.solvers.rootfinder import RootfinderOptions

    case = simulate(noise_free(get_scenario("deep_ocean")), seed=2)
    calib = truth_calibration(case)
    default = dynamic_correction(case, "rootfinder", calib)
    bare = dynamic_correction(case, "rootfinder", calib, rootfinder_options=RootfinderOptions(steps=0))
    assert default.provenance.rootfinder_fallback_pings == 0
    assert bare.provenance.rootfinder_fallback_pings > 0
    assert bare.provenance.rootfinder_unconverged_pings == default.provenance.rootfinder_unconverged_pings == 0
    assert np.nanmax(np.abs(bare.vessel_velocity_m_s - default.vessel_velocity_m_s)) < 1e-9


@pytest.mark.skipif(__import__("shutil").which("gcc") is None, reason="no C compiler")
def test_compiled_rootfinder_equals_interpreted(tmp_path, monkeypatch):
    from adcpdyn.solvers.rootfinder import RootfinderOptions

    monkeypatch.chdir(tmp_path)
    case = simulate(get_scenario("pool_m1"), seed=3)
    calib = truth_calibration(case)
    vm = dynamic_correction(case, "rootfinder", calib, rootfinder_options=RootfinderOptions(compile="never"))
    cc = dynamic_correction(case, "rootfinder", calib, rootfinder_options=RootfinderOptions(compile="always"))
    assert np.nanmax(np.abs(vm.vessel_velocity_m_s - cc.vessel_velocity_m_s)) < 1e-12
    assert list(tmp_path.iterdir()) == []  # the compiler's files stay out of the working folder


@pytest.mark.slow  # 7 s: `make test-slow`, CI's second step
def test_exact_travel_time_reproduces_the_simulator_in_deep_water():
    """The oracle with the travel time solved for the moving transducer against the simulator's
    own fixed-point echoes (noise-free deep_ocean): the first-order model leaves ~1e-5 m/s."""
    case = simulate(noise_free(get_scenario("deep_ocean")), seed=1)
    truth = case.truth.vessel_velocity_m_s
    err = {t: np.nanmax(np.abs(dynamic_correction(case, "oracle", timing=t).vessel_velocity_m_s - truth))
           for t in ("deep", "exact")}
    assert err["exact"] < 1e-9 < 1e-6 < err["deep"]
    with pytest.raises(ValueError, match="exact"):
        dynamic_correction(case, "adc", truth_calibration(case), timing="exact")


def test_a_calibration_on_the_samples_corrects_with_the_samples():
    """On noise-free 0.2-s attitude the dynamic correction with the samples' interpolation comes
    within the interpolation error of the truth (the motion model: exact), and the exact per-ping
    solve on the same samples agrees with the closed form on them."""
    import json

    from adcpdyn.models.motion import AttitudeParams, SampledAttitude, evaluate_attitude

    sc = get_scenario("deep_ship")
    case = simulate(noise_free(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=60.0))), seed=3)
    t = case.truth
    calib = {"radius_vectors_m": t.radius_vectors_m.tolist(), "installation_ypr_rad": t.installation_ypr_rad.tolist()}
    model = dynamic_correction(case, "adc", CalibrationRecord.from_dict(calib))
    sampled = dynamic_correction(case, "adc", CalibrationRecord.from_dict({**calib, "attitude_source": "samples"}))
    rms = lambda v: float(np.sqrt(np.nanmean(np.sum((v - t.vessel_velocity_m_s) ** 2, axis=1))))
    static = asc(case, t.installation_ypr_rad).vessel_velocity_m_s
    # the samples' segment-average rates leave a few mm/s where the motion curves (the first
    # pings' free decay); the static correction is off by the whole tangential velocity
    assert rms(model.vessel_velocity_m_s) < 1e-4 and rms(sampled.vessel_velocity_m_s) < 0.2 * rms(static)
    a = case.attitude
    mid = 0.5 * (a.time_s[1:] + a.time_s[:-1])
    linear = evaluate_attitude(SampledAttitude(a.time_s, a.ypr(), "linear"), mid)["ypr"]
    assert np.allclose(linear[:, 1], np.interp(mid, a.time_s, a.pitch_rad), atol=1e-12)
    # the default smoothing spline lies nearer the true attitude between the samples than the segments do
    true = evaluate_attitude(AttitudeParams.from_dict(json.loads(t.extra_attrs["attitude_model"])), mid)["ypr"]
    spline = evaluate_attitude(SampledAttitude(a.time_s, a.ypr()), mid)["ypr"]
    for j in (1, 2):
        assert np.sqrt(np.mean((spline[:, j] - true[:, j]) ** 2)) < 0.5 * np.sqrt(np.mean((linear[:, j] - true[:, j]) ** 2))
    exact = dynamic_correction(case, "rootfinder", CalibrationRecord.from_dict({**calib, "attitude_source": "samples"}))
    assert exact.provenance.rootfinder_unconverged_pings == 0
    assert np.nanmax(np.abs(exact.vessel_velocity_m_s - sampled.vessel_velocity_m_s)) < 1e-4


def test_samples_too_sparse_for_the_motion_are_joined_linearly_not_smoothed_away():
    """One recipe for the beams' attitude from samples: a smoothing spline within the motion band
    where the samples resolve the motion; where most of an axis' variance lies above half their
    Nyquist frequency (deep_ship's modes of 1.05-2.0 rad/s sampled every 1.6 s) the spline's penalty
    cuts into the motion and departs from the noise-free samples where the beams ping, so the samples
    are joined linearly and the reason is said. The share
    itself: a sine above half the Nyquist frequency is all above it, one below none of it."""
    from adcpdyn.estimators.attitude_fit import sampled_attitude
    from adcpdyn.models.motion import share_above_half_nyquist
    from adcpdyn.models.motion import SampledAttitude, evaluate_attitude

    t = np.arange(0.0, 300.0, 1.0)  # Nyquist pi rad/s
    sines = np.column_stack([0.1 * np.sin(0.8 * np.pi * t), 0.1 * np.sin(0.3 * np.pi * t), 0.1 * np.sin(0.6 * np.pi * t)])
    share = share_above_half_nyquist(t, sines)
    assert share[0] > 0.95 and share[1] < 0.05 and share[2] > 0.95

    sc = get_scenario("deep_ship")
    case = simulate(noise_free(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=120.0))), seed=3)
    dense = sampled_attitude(case)
    assert dense.interpolation == "spline"
    a = case.attitude
    sparse = dataclasses.replace(a, **{f: getattr(a, f)[::8] for f in ("time_s", "heading_rad", "pitch_rad", "roll_rad")})
    chosen = sampled_attitude(dataclasses.replace(case, attitude=sparse))
    assert chosen.interpolation == "linear" and "roll" in chosen.reason and "Nyquist" in chosen.reason
    at = lambda s: evaluate_attitude(s, sparse.time_s[2:-2])["ypr"]
    truth = sparse.ypr()[2:-2]
    spline = SampledAttitude(sparse.time_s, sparse.ypr(), band_rad_s=chosen.band_rad_s)
    assert np.allclose(at(chosen), truth, atol=1e-12)  # the samples, where the beams ping
    from adcpdyn.cases.summary import summarise  # `adcpdyn info` says which, before any calibration

    from adcpdyn.models.motion import fast_axes

    told = ", ".join(f"{n} {100 * v:.0f} %" for n, v in fast_axes(sparse.time_s, sparse.ypr()).items())
    said = lambda c: " ".join(summarise(c).split())  # its lines wrapped at 100 characters, joined back
    assert "roll" in told and f"joined linearly where the beams take the samples: {told}" in \
        said(dataclasses.replace(case, attitude=sparse))
    assert "joined by a smoothing spline within the motion band" in said(case)
    assert np.sqrt(np.mean((at(spline)[:, 2] - truth[:, 2]) ** 2)) > 0.02 * np.std(truth[:, 2])  # cut into the motion


def test_runs_corrected_or_diagnosed_with_a_calibration_join_the_samples_as_its_runs_did():
    """How the samples are joined is the sensor's sampling against the boat's motion: a calibration
    records it per run (CALIB.json runs[i].attitude_interpolation) and the runs corrected or
    diagnosed with it take it, whatever their own samples would choose (an injected tilt low-pass
    takes the fast content out and would turn winriver01's straight segments back into a spline);
    runs that disagree, or a file without it, leave the choice to the data."""
    from adcpdyn.estimators.diagnosis.base import base_from
    from adcpdyn.estimators.diagnosis.config import DiagnosisConfig

    sc = get_scenario("deep_ship")
    case = simulate(noise_free(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=60.0))), seed=3)
    t = case.truth
    calib = {"radius_vectors_m": t.radius_vectors_m.tolist(), "installation_ypr_rad": t.installation_ypr_rad.tolist(),
             "attitude_source": "samples"}
    run = lambda name, how: {"case": name, "attitude_source": "samples", "attitude_interpolation": how}
    linear = CalibrationRecord.from_dict({**calib, "runs": [run(case.name, "linear")]})
    mixed = CalibrationRecord.from_dict({**calib, "runs": [run(case.name, "linear"), run("other", "spline")]})
    assert linear.sample_interpolation() == "linear" and mixed.sample_interpolation() is None
    assert CalibrationRecord.from_dict(calib).sample_interpolation() is None
    assert linear.applied_to(case, case.attitude.frame, dynamic=True).attitude_interpolation == "linear"
    config = DiagnosisConfig(attitude="samples")
    held = base_from([case], config, linear).runs[0].samples
    assert held.interpolation == "linear" and held.reason == "joined linearly, as the calibration's runs"
    assert base_from([case], config, mixed).runs[0].samples.interpolation == "spline"  # these samples resolve the motion
    segments = dynamic_correction(case, "adc", linear)
    spline = dynamic_correction(case, "adc", CalibrationRecord.from_dict({**calib, "runs": [run(case.name, "spline")]}))
    assert not np.allclose(segments.vessel_velocity_m_s, spline.vessel_velocity_m_s, atol=1e-6, equal_nan=True)


def test_an_attitude_latency_on_samples_too_sparse_for_the_motion_says_it_is_told_only_modulo_a_sample():
    """A delay of the attitude samples is told only up to whole sample intervals where most of an
    axis' variance lies above half their Nyquist frequency (winriver01's injected 0.3 and 1.0 s read
    1.3 s off): the diagnosis says so beside a named attitude_latency, with the interval; not on
    samples that resolve the motion, and not beside other effects."""
    from types import SimpleNamespace

    from adcpdyn.estimators.diagnosis.statement import reading_of

    sc = get_scenario("deep_ship")
    case = simulate(noise_free(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=120.0))), seed=3)
    a = case.attitude
    sparse = dataclasses.replace(case, attitude=dataclasses.replace(
        a, **{f: getattr(a, f)[::8] for f in ("time_s", "heading_rad", "pitch_rad", "roll_rad")}))
    latency = SimpleNamespace(effect="attitude_latency", params={}, params_se={})
    said = reading_of(latency, [sparse])["aliased"]
    assert said["sample_interval_s"] == pytest.approx(np.median(np.diff(a.time_s[::8])), rel=1e-9)
    assert "roll" in said["axes"] and f"{said['sample_interval_s']:.2f} s" in said["text"]
    assert reading_of(latency, [case]) == {}
    assert reading_of(SimpleNamespace(effect="heave", params={}, params_se={}), [sparse]) == {}
