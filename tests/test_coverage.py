"""Spec-allowed NaN accepted and handled; time spans checked; the attitude never extrapolated."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest
from conftest import shortened

from adcpdyn.cases.coverage import MAX_DROPPED_FRACTION, reference_at, restrict_to_coverage
from adcpdyn.cases.corrected import read_correction
from adcpdyn.cases.io import read_case, write_case
from adcpdyn.cases.validation import case_warnings
from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cli import main
from adcpdyn.estimators.calibration.config import CalibrationConfig
from adcpdyn.estimators.calibration.problem import CalibrationProblem
from adcpdyn.cases.simulation import simulate

SANE_M_S = 20.0  # no boat in these cases moves faster


@pytest.fixture(scope="module")
def m1():
    return simulate(get_scenario("pool_m1"), seed=1)


@pytest.fixture(scope="module")
def calib(tmp_path_factory):
    path = tmp_path_factory.mktemp("calib") / "calib.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        CalibrationProblem(simulate(get_scenario("pool_m0"), seed=1), CalibrationConfig(n_starts=1)).solve().to_json(path)
    return path


def _with_reference(case, fn):
    return case.replace(reference=dataclasses.replace(case.reference, **fn(case.reference)))


def _nan_vertical(case):
    v = case.reference.velocity_m_s.copy()
    v[:, 2] = np.nan
    return _with_reference(case, lambda r: {"velocity_m_s": v})


def _sane(path):
    corr = read_correction(path)
    v, used = corr["vessel_velocity_m_s"], corr["beams_used"]
    assert np.all(np.isfinite(v[used >= 3])) and np.all(np.abs(v[used >= 3]) < SANE_M_S) and (used >= 3).any()
    return corr


def test_missing_attitude_samples_are_accepted_and_left_out(m1, tmp_path, calib, capsys):
    a = m1.attitude
    pitch, heading = a.pitch_rad.copy(), a.heading_rad.copy()
    pitch[[3, 10]] = np.nan
    heading[20] = np.nan
    case = m1.replace(attitude=dataclasses.replace(a, pitch_rad=pitch, heading_rad=heading))
    path = tmp_path / "nan_attitude.h5"
    write_case(case, path)
    back = read_case(path)
    assert np.isnan(back.attitude.ypr()[20, 0]) and np.isfinite(back.attitude.ypr()[21, 0])  # unwrap skips the gap
    assert any("3 of" in w and "NaN angle" in w for w in case_warnings(back))
    kept, note = restrict_to_coverage(back)
    assert kept.attitude.time_s.size == a.time_s.size - 3 and "3 of" in note
    assert main(["info", str(path)]) == 0
    assert "with a NaN angle" in " ".join(capsys.readouterr().out.split())  # words, whatever the wrapping
    for method in ("asc", "adc", "rootfinder"):
        out = tmp_path / f"{method}.h5"
        assert main(["correct", str(path), "--method", method, "--calibration", str(calib), "--out", str(out)]) == 0
        corr = _sane(out)
        assert any("attitude samples with a NaN angle left out" in w for w in corr["provenance"].warnings)


def test_missing_per_ping_bed_depths_fall_back_on_the_attribute(m1):
    depth = np.full(m1.pings.n, 6.0)
    depth[[0, 5]] = np.nan
    env = dataclasses.replace(m1.environment, water_depth_per_ping_m=depth)
    got = env.depth_at_pings(m1.pings.n)
    assert got[0] == m1.environment.water_depth_m and got[1] == 6.0
    assert any("2 of" in w for w in case_warnings(m1.replace(environment=env)))


@pytest.mark.slow  # 5.9 s
def test_reference_without_vertical_is_valid_for_info_correct_compare_and_diagnose(m1, tmp_path, calib, capsys):
    case = _nan_vertical(shortened(m1, 20.0))
    path = tmp_path / "no_vertical.h5"
    write_case(case, path)
    assert main(["info", str(path)]) == 0
    assert "down component is NaN throughout" in capsys.readouterr().err
    assert main(["correct", str(path), "--method", "adc", "--calibration", str(calib), "--out", str(tmp_path / "c.h5")]) == 0
    _sane(tmp_path / "c.h5")
    # against the reference (no truth): horizontal metrics and a horizontal vector error, not NaN
    no_truth = tmp_path / "no_truth.h5"
    write_case(case.replace(truth=None), no_truth)
    assert main(["compare", str(no_truth), "--calibration", str(calib), "--out", str(tmp_path / "cmp")]) == 0
    table = json.loads((tmp_path / "cmp" / f"{case.name}_compare.json").read_text())
    assert table["reference"]["n_pings"] == case.pings.n and np.isfinite(table["asc"]["vector_error_rms_m_s"])
    assert main(["diagnose", str(path), "--effects", "heave", "--out", str(tmp_path / "d.json")]) == 0
    diag = json.loads((tmp_path / "d.json").read_text())
    assert np.isfinite(diag["gap_before"])


def test_calibrate_with_a_reference_without_vertical(m1, tmp_path):
    path = tmp_path / "no_vertical.h5"
    write_case(_nan_vertical(shortened(m1, 20.0)), path)
    assert main(["calibrate", str(path), "--starts", "1", "--out", str(tmp_path / "c.json")]) == 0


@pytest.mark.parametrize("verb", ["calibrate", "correct", "diagnose"])
@pytest.mark.parametrize("offset_s", [1e3, 1e4])
def test_reference_far_from_the_pings_is_a_one_line_error_before_any_work(m1, tmp_path, capsys, verb, offset_s):
    path = tmp_path / "far.h5"
    case = shortened(m1, 20.0)
    far = case.replace(reference=dataclasses.replace(case.reference, time_s=case.reference.time_s + offset_s))
    with pytest.raises(ValueError, match="/reference/time_s: expected a record overlapping the pings"):
        write_case(far, path)  # not even written
    with_h5 = tmp_path / "ok.h5"
    write_case(case, with_h5)
    import h5py

    with h5py.File(with_h5, "r+") as f:
        f["reference/time_s"][...] = f["reference/time_s"][()] + offset_s
    out = tmp_path / ("out.h5" if verb == "correct" else "out.json")  # the extension each verb writes
    assert main([verb, str(with_h5), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/reference/time_s" in err
    assert not out.exists()


def test_pings_outside_the_attitude_record_are_left_out_with_a_count(m1, tmp_path, calib, capsys):
    a = m1.attitude
    cut = a.time_s <= a.time_s[0] + 30.0
    case = m1.replace(attitude=dataclasses.replace(a, time_s=a.time_s[cut], heading_rad=a.heading_rad[cut],
                                                   pitch_rad=a.pitch_rad[cut], roll_rad=a.roll_rad[cut]))
    kept, note = restrict_to_coverage(case)
    tol = float(np.median(np.diff(a.time_s[cut])))
    inside = m1.pings.time_s <= a.time_s[cut][-1] + tol
    assert kept.pings.n == inside.sum() < m1.pings.n
    assert kept.truth.vessel_velocity_m_s.shape == (kept.pings.n, 3)
    assert f"{m1.pings.n - inside.sum()} of {m1.pings.n} pings outside the attitude record" in note
    assert kept.reference.time_s[-1] <= kept.pings.time_s[-1] + 1.0  # reference trimmed to what is covered
    path = tmp_path / "short_attitude.h5"
    write_case(case, path)
    out = tmp_path / "c.h5"
    assert main(["correct", str(path), "--method", "adc", "--calibration", str(calib), "--out", str(out)]) == 0
    assert "pings outside the attitude record" in capsys.readouterr().err
    assert _sane(out)["time_s"].size == inside.sum()


def test_most_pings_outside_the_attitude_record_is_refused(m1):
    a = m1.attitude
    cut = a.time_s <= a.time_s[0] + 0.4 * (a.time_s[-1] - a.time_s[0])
    case = m1.replace(attitude=dataclasses.replace(a, time_s=a.time_s[cut], heading_rad=a.heading_rad[cut],
                                                   pitch_rad=a.pitch_rad[cut], roll_rad=a.roll_rad[cut]))
    assert (m1.pings.time_s > a.time_s[cut][-1]).mean() > MAX_DROPPED_FRACTION
    with pytest.raises(ValueError, match=r"^src: /pings/time_s: expected at most 50% of the pings outside"):
        restrict_to_coverage(case, "src")
    one = m1.replace(attitude=dataclasses.replace(a, time_s=a.time_s[:1], heading_rad=a.heading_rad[:1],
                                                  pitch_rad=a.pitch_rad[:1], roll_rad=a.roll_rad[:1]))
    with pytest.raises(ValueError, match="/attitude: expected at least 2 samples"):
        restrict_to_coverage(one)


def test_nothing_changes_when_everything_is_covered(m1):
    kept, note = restrict_to_coverage(m1)
    assert kept is m1 and note is None


def test_reference_is_interpolated_over_its_finite_samples_and_never_extrapolated(m1):
    r = m1.reference
    v = r.velocity_m_s.copy()
    v[5, 0] = np.nan
    v[:, 2] = np.nan
    case = m1.replace(reference=dataclasses.replace(r, velocity_m_s=v))
    dt = float(np.median(np.diff(r.time_s)))
    t = np.array([r.time_s[5], r.time_s[-1] + 0.5 * dt, r.time_s[-1] + 3 * dt])
    got = reference_at(case, t)
    assert got[0, 0] == pytest.approx(0.5 * (v[4, 0] + v[6, 0])) and np.isfinite(got[1, :2]).all()
    assert np.isnan(got[2]).all() and np.isnan(got[:, 2]).all()


def test_unusual_values_are_warnings_in_the_output(m1, tmp_path, capsys):
    ins = dataclasses.replace(m1.instrument, sound_speed_m_s=1350.0)
    path = tmp_path / "cold.h5"
    write_case(m1.replace(instrument=ins), path)
    assert main(["info", str(path)]) == 0
    captured = capsys.readouterr()
    assert 'warning: /instrument.attrs["sound_speed_m_s"]: 1350 m/s is outside the usual' in captured.err
    assert "warning:" not in captured.out  # stdout keeps the results a script reads
    assert main(["correct", str(path), "--out", str(tmp_path / "c.h5")]) == 0
    assert any("sound_speed_m_s" in w for w in read_correction(tmp_path / "c.h5")["provenance"].warnings)


def test_reference_record_far_longer_than_the_pings_is_trimmed_before_calibrating(m1, tmp_path):
    """GNSS logged for hours around a short ADCP run: the calibration sees only the samples over
    the pings (its velocity knots span the pings, not 1e4 s), and CALIB.json says how many were left out."""
    case = shortened(m1, 20.0)
    r = case.reference
    dt = float(np.median(np.diff(r.time_s)))
    extra = r.time_s[-1] + dt * (1 + np.arange(int(1e4 / dt)))
    longer = dataclasses.replace(r, time_s=np.r_[r.time_s, extra],
                                 velocity_m_s=np.r_[r.velocity_m_s, np.tile(r.velocity_m_s[-1], (extra.size, 1))])
    path = tmp_path / "long_gnss.h5"
    write_case(case.replace(reference=longer), path)
    kept, note = restrict_to_coverage(read_case(path))
    assert kept.reference.time_s[-1] <= kept.pings.time_s[-1] + 2 * dt and f"of {longer.time_s.size} reference" in note
    out = tmp_path / "calib.json"
    assert main(["calibrate", str(path), "--starts", "1", "--out", str(out)]) in (0, 1)
    assert any("reference samples outside the pings' span" in w for w in json.loads(out.read_text())["warnings"])
