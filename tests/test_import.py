"""Import of real instrument files: conventions checked by independent routes, clear errors."""

from __future__ import annotations


import h5py
import numpy as np
import pytest
from conftest import REAL, dolfyn_dataset, real

from adcpdyn.cases.importers import ImportFailure, Window, detect_vendor, import_file, write_imported
from adcpdyn.cases.importers.rdi_frames import SWAP, beam_to_earth, rdi_matrix, to_beam
from adcpdyn.cases.io import read_case
from adcpdyn.estimators.asc import asc
from adcpdyn.models.rotations import euler_matrix

EARTH_BT_TOL = 1e-6  # m/s: ASC Earth-frame BT against the instrument's own
SPEED_RATIO_TOL = 0.05  # BT speed / GNSS speed within 5 %
FRAME_TOL = 1e-12

needs_reader = pytest.mark.skipif(not REAL.is_dir(), reason=f"real data folder {REAL} absent")


# ---------------------------------------------------------------- frames (no data needed)
def test_rdi_rotation_is_the_case_euler_matrix():
    rng = np.random.default_rng(1)
    for h, p, r in rng.uniform(-1.5, 1.5, (5, 3)):
        assert np.max(np.abs(SWAP @ rdi_matrix(h, p, r)[0] @ SWAP - np.asarray(euler_matrix(h, p, r)))) < FRAME_TOL


def test_beam_earth_round_trip():
    rng = np.random.default_rng(2)
    beams = rng.normal(size=(50, 4))
    rot = rdi_matrix(*rng.uniform(-1, 1, (3, 50)))
    earth = beam_to_earth(beams, np.deg2rad(20), rot)
    assert np.max(np.abs(to_beam(earth, "earth", np.deg2rad(20), True, rot) - beams)) < FRAME_TOL


# ---------------------------------------------------------------- real files
def _instrument_bt(name):
    return np.asarray(dolfyn_dataset(name)["vel_bt"].values, dtype=np.float64).T


@needs_reader
def test_earth_file_asc_matches_instrument_earth_bt(imported):
    case, attrs = imported("RDI_withBT.000")
    assert attrs["/provenance"]["coordinate_system_found"] == "earth"
    v = asc(case).vessel_velocity_m_s  # NED velocity of the transducer
    enu = _instrument_bt("RDI_withBT.000")[:, :3]  # bottom relative to the ADCP, E N U
    ok = np.all(np.isfinite(case.pings.bt_radial_m_s), axis=1) & np.all(np.abs(enu) < 30, axis=1)
    assert ok.sum() > 800
    mine = np.column_stack([-v[ok, 1], -v[ok, 0], v[ok, 2]])
    assert np.max(np.abs(mine - np.round(enu[ok] * 1000) / 1000)) < EARTH_BT_TOL


@needs_reader
def test_ship_file_asc_matches_instrument_ship_bt(imported):
    case, attrs = imported("winriver01.PD0")
    assert attrs["/provenance"]["coordinate_system_found"] == "ship"
    v = asc(case).vessel_velocity_m_s
    psi = case.attitude.heading_rad
    fwd = np.cos(psi) * v[:, 0] + np.sin(psi) * v[:, 1]
    stbd = -np.sin(psi) * v[:, 0] + np.cos(psi) * v[:, 1]
    ship = _instrument_bt("winriver01.PD0")[:, :3]  # X starboard, Y bow, Z up, bottom relative to the ADCP
    ok = np.all(np.isfinite(case.pings.bt_radial_m_s), axis=1)
    mine = np.column_stack([-stbd[ok], -fwd[ok], v[ok, 2]])
    assert np.max(np.abs(mine - np.round(ship[ok] * 1000) / 1000)) < EARTH_BT_TOL


@needs_reader
@pytest.mark.parametrize("name, offset_s, tol_s", [("RiverPro_test01.PD0", 2.0, 1.0),
                                                    ("winriver01.PD0", 4 * 3600 + 25.0, 3.0),
                                                    ("winriver02_transect.PD0", 8 * 3600 + 1.0, 2.0)])
def test_bt_speed_agrees_with_gnss(imported, name, offset_s, tol_s):
    case, attrs = imported(name)
    prov = attrs["/provenance"]
    assert case.attitude.frame == "transducer"
    assert abs(prov["clock_offset_s"] - offset_s) < tol_s
    assert abs(prov["bt_vs_gnss_speed_ratio_bt_over_gnss"] - 1.0) < SPEED_RATIO_TOL
    assert abs(prov["bt_vs_gnss_course_offset_gnss_minus_bt_deg"]) < 30.0  # a sign error would give ~180
    ref = case.reference
    assert np.all(np.diff(ref.time_s) > 0) and ref.time_s[0] > -10 and ref.time_s[-1] < case.pings.time_s[-1] + 10
    # VTG or differenced GGA: horizontal only; the vertical is not measured (NaN), never a made-up 0
    assert np.all(np.isnan(ref.velocity_m_s[:, 2])) and np.isfinite(ref.velocity_m_s[:, :2]).mean() > 0.9


@needs_reader
def test_beam_file_without_attitude_is_flagged(imported):
    case, attrs = imported("vmdas02_os.ENR")
    assert attrs["/attitude"]["attitude_recorded"] == 0 and "no attitude" in attrs["/attitude"]["attitude_warning"]
    assert case.reference is None
    bt = np.nanmedian(case.pings.bt_radial_m_s, axis=0)  # underway along x_t (RDI beam 3 = case beam 2)
    assert bt[1] > 2.0 and bt[0] < -2.0 and np.all(np.abs(bt[2:]) < 0.5)


@needs_reader
def test_bad_marker_and_slant_ranges(imported):
    case, _ = imported("RiverPro_test01.PD0")
    bt = case.pings.bt_radial_m_s
    assert np.all(np.isnan(bt) | (np.abs(bt) < 32.0))
    rng = case.pings.bt_range_m
    assert np.nanmin(rng) > 0 and np.nanmedian(rng) * np.cos(case.instrument.beam_angle_rad) < 10


@needs_reader
def test_written_case_validates_with_provenance(tmp_path, imported):
    case, attrs = imported("RiverPro_test01.PD0")
    out = tmp_path / "rp.h5"
    write_imported(case, attrs, out, source=real("RiverPro_test01.PD0"))
    back = read_case(out)
    assert back.pings.n == case.pings.n and back.attitude.frame == "transducer"
    with h5py.File(out) as f:
        assert "RDI beams 4,3,2,1" in f["/provenance"].attrs["beam_mapping"]
        assert f["/provenance"].attrs["clock_offset_s"] == attrs["/provenance"]["clock_offset_s"]


@needs_reader
def test_window_and_decimation():
    path = real("RiverPro_test01.PD0")
    case, attrs = import_file(path, Window(start_s=20.0, end_s=120.0, every=2))
    assert case.pings.time_s[0] == 0.0 and case.pings.time_s[-1] <= 100.0
    assert 60 < case.pings.n < 80 and "every 2" in attrs["/provenance"]["selection"]


@needs_reader
@pytest.mark.parametrize("name, words", [("adcp.adc", "could not read the file"),
                                         ("Sig1000_IMU.ad2cp", "bottom track: none"),
                                         ("clllm_20250530T065119_009_000000.ENS", "bottom track: none")])
def test_unsupported_files_fail_in_one_line(tmp_path, capsys, name, words):
    from adcpdyn.cli import main

    path = real(name)
    assert main(["import", str(path), "--out", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "x.h5").exists()


def test_bad_inputs(tmp_path):
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"hello")
    with pytest.raises(ImportFailure, match="file type: expected a TRDI PD0"):
        detect_vendor(junk)
    with pytest.raises(ImportFailure, match="no such file"):
        detect_vendor(tmp_path / "missing.PD0")
    with pytest.raises(ValueError, match="every: expected an integer >= 1"):
        Window(every=0)


@needs_reader
def test_a_window_where_the_bottom_track_is_lost_fails_in_one_line_naming_the_output(tmp_path, capsys):
    """winriver02's last 90 s have no bottom track: the GNSS comparison skips it (it crashed in
    np.interp) and the error names the output and the instrument file, not the temporary file."""
    from adcpdyn.cli import main

    out = tmp_path / "end.h5"
    assert main(["import", str(real("winriver02_transect.PD0")), "--start", "375", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{out} (from winriver02_transect.PD0): /pings/bt_radial_m_s" in err and "adcpdyn-tmp" not in err
    assert not out.exists()


def test_window_velocity_of_too_few_pings_is_nan():
    from adcpdyn.cases.importers.gnss import _window_velocity

    windows = np.array([[0.0, 1.0], [2.0, 2.0]])
    assert np.isnan(_window_velocity(np.array([0.5]), np.array([[1.0, 0.0]]), windows)).all()
    windows = np.array([[0.0, 1.0], [2.0, 2.0], [1.0, 3.0]])
    w = _window_velocity(np.array([0.0, 2.0]), np.array([[1.0, 0.0], [3.0, 0.0]]), windows)
    # positions trapezoidal at the pings, linear between them: [0, 1] averages the segment (2); the last leaves the span
    np.testing.assert_allclose(w, [[2.0, 0.0], [3.0, 0.0], [np.nan, np.nan]])


@needs_reader
def test_import_refuses_to_overwrite_input(tmp_path, capsys):
    from adcpdyn.cli import main

    src = tmp_path / "copy.PD0"
    src.write_bytes(real("RiverPro_test01.PD0").read_bytes())
    assert main(["import", str(src), "--out", str(src)]) == 2
    assert "inputs are never overwritten" in capsys.readouterr().err
    assert src.read_bytes() == real("RiverPro_test01.PD0").read_bytes()


def _calibrated_misalignment(case, moving_bed="auto") -> tuple[float, float]:
    import warnings

    from adcpdyn.estimators.calibration.config import CalibrationConfig
    from adcpdyn.estimators.calibration.problem import calibrate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = calibrate(case, CalibrationConfig(n_starts=2, timing="shallow", moving_bed=moving_bed))
    assert r.success
    return r.heading_misalignment_rad, r.heading_misalignment_se_rad


@pytest.mark.slow  # 8 s: `make test-slow`, CI's second step
def test_real_heading_misalignment_follows_a_turned_reference(imported):
    """On a real moving-boat file, turning the GNSS velocities by 40 degrees turns the calibrated
    heading misalignment by 40 degrees (within 3 SE; the bed, a true-Earth velocity, turns with
    them), and with the bed taken as fixed the misalignment agrees with the importer's BT-vs-GNSS
    course offset (an independent, model-free route that assumes a fixed bed) within 3 degrees."""
    import dataclasses

    case, attrs = imported("RiverPro_test01.PD0")
    fixed, _ = _calibrated_misalignment(case, moving_bed="off")
    assert abs(np.rad2deg(fixed) - attrs["/provenance"]["bt_vs_gnss_course_offset_gnss_minus_bt_deg"]) < 3.0
    d0, se0 = _calibrated_misalignment(case)
    turn = np.deg2rad(40.0)
    R = np.asarray(euler_matrix(turn, 0.0, 0.0))
    v = case.reference.velocity_m_s.copy()
    v[:, :2] = v[:, :2] @ R[:2, :2].T  # the horizontal turned; the vertical (not measured, NaN) stays
    ref = dataclasses.replace(case.reference, velocity_m_s=v)
    d1, se1 = _calibrated_misalignment(case.replace(reference=ref))
    assert abs((d1 - d0) - turn) < 3 * np.hypot(se0, se1)


def test_real_file_runs_through_diagnose(imported, tmp_path):
    from adcpdyn.estimators.diagnosis import DiagnosisConfig, diagnose

    case, _ = imported("RiverPro_test01.PD0")
    result = diagnose(case, DiagnosisConfig(effects=("surge", "installation_misalignment")))
    assert result.verdict in ("surge", "installation_misalignment", "none")
    assert result.where and np.isfinite(result.gap_before)


def _chatty_import(ok: bool):
    """A stand-in TRDI reader that logs as dolfyn does, warns, and hands LAPACK a NaN."""
    def fake(path, window):
        import logging
        import warnings

        for pos in (0, 512, 1024):
            logging.warning(f"Ensemble starting at startpos {pos} has a checksum error")
        warnings.warn("a reader's warning")
        with pytest.raises(np.linalg.LinAlgError):
            a = np.ones((5, 2))
            a[0, 0] = np.nan
            np.linalg.lstsq(a, np.ones(5), rcond=None)  # LAPACK prints DLASCL lines on fd 1
        if not ok:
            raise ImportFailure(f"{path}: could not read the file (KeyError: 377)")
        from adcpdyn.cases.scenario import get_scenario
        from adcpdyn.cases.simulation import simulate

        return simulate(get_scenario("pool_m0"), seed=1), {"/provenance": {"gnss": "none", "coordinate_system_found": "beam"}}
    return fake


@pytest.mark.parametrize("ok", [True, False])
def test_reader_chatter_is_kept_out_of_the_terminal(tmp_path, capfd, monkeypatch, ok):
    import logging

    from adcpdyn.cases.importers import trdi
    from adcpdyn.cli import main

    monkeypatch.setattr(trdi, "import_trdi", _chatty_import(ok))
    src = tmp_path / "damaged.PD0"
    src.write_bytes(b"\x7f\x7f")
    handlers = logging.getLogger().handlers[:]
    code = main(["import", str(src), "--out", str(tmp_path / "x.h5")])
    out, err = capfd.readouterr()
    assert logging.getLogger().handlers == handlers  # the logging set-up is given back
    assert "DLASCL" not in out + err and "startpos 512" not in out + err and "a reader's warning" not in out + err
    if ok:  # the reader's summary is one warning (checksum errors...) on stderr, wrapped at 100 characters
        assert code == 0 and "note:" not in out and "warning:" not in out
        assert err.count("warning: ") == 1 and err.startswith("warning: ")
        assert all(ln.startswith("    ") for ln in err.splitlines()[1:]) and max(map(len, err.splitlines())) <= 100
        assert "kept out of the terminal" in err and "startpos 0" in err
    else:
        assert code == 2 and err.count("\n") == 1
        assert "KeyError: 377" in err and "the reader reported: Ensemble starting at startpos 0" in err
        assert not (tmp_path / "x.h5").exists()


@needs_reader
def test_real_samples_too_sparse_for_the_roll_are_joined_linearly(imported):
    """winriver01's 1.31-s attitude samples hold most of their roll variance above half their Nyquist
    frequency (the roll aliased: 94 %), so its beams take straight segments; RiverPro (0.67 s) and
    winriver02 (0.52 s) resolve their motion and keep the smoothing spline."""
    from adcpdyn.estimators.attitude_fit import sampled_attitude, undersampled_axes

    chosen = {name: sampled_attitude(imported(name)[0]) for name in
              ("winriver01.PD0", "RiverPro_test01.PD0", "winriver02_transect.PD0")}
    assert {n: s.interpolation for n, s in chosen.items()} == {
        "winriver01.PD0": "linear", "RiverPro_test01.PD0": "spline", "winriver02_transect.PD0": "spline"}
    assert list(undersampled_axes(imported("winriver01.PD0")[0])) == ["roll"]
