"""Command line end to end, and cases written by another producer."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from adcpdyn.cases.corrected import read_correction
from adcpdyn.cases.io import read_case
from adcpdyn.cli import main


def test_simulate_info_correct(tmp_path, capsys):
    case = tmp_path / "m1.h5"
    assert main(["simulate", "pool_m1", "--seed", "2", "--out", str(case)]) == 0
    assert main(["info", str(case)]) == 0
    text = capsys.readouterr().out
    for word in ("instrument", "pings", "attitude", "roll", "dominant period", "truth", "groups"):
        assert word in text
    out = tmp_path / "m1_asc.h5"
    assert main(["correct", str(case), "--method", "asc", "--out", str(out)]) == 0
    corr = read_correction(out)
    n = read_case(case).pings.n
    assert corr["method"] == "asc"
    assert corr["time_s"].shape == (n,)
    assert corr["vessel_velocity_m_s"].shape == (n, 3)


def test_correct_refuses_to_overwrite_its_input(tmp_path, capsys):
    case = tmp_path / "c.h5"
    main(["simulate", "pool_m0", "--out", str(case)])
    before = case.read_bytes()
    assert main(["correct", str(case), "--out", str(case)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--out" in err and "\n" not in err
    assert case.read_bytes() == before


def test_bad_file_gives_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.h5"
    with h5py.File(bad, "w") as f:
        f.attrs["format"] = "adcp-case"
        f.attrs["version"] = 1
    assert main(["info", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert "/instrument" in err and "\n" not in err


def test_unknown_method_is_a_clear_error(tmp_path, capsys):
    case = tmp_path / "c.h5"
    main(["simulate", "pool_m0", "--out", str(case)])
    assert main(["correct", str(case), "--method", "magic", "--out", str(tmp_path / "o.h5")]) == 2
    assert "--method" in capsys.readouterr().err


def _foreign_case(path, heading, velocity, beam_angle=np.deg2rad(20.0), n=40):
    """A rotation-free case written directly with h5py, as an independent simulator would."""
    s, c = np.sin(beam_angle), np.cos(beam_angle)
    beams_t = np.array([[-s, 0, c], [s, 0, c], [0, s, c], [0, -s, c]])
    ch, sh = np.cos(heading), np.sin(heading)
    R = np.array([[ch, -sh, 0], [sh, ch, 0], [0, 0, 1]])
    radial = np.tile(beams_t @ R.T @ velocity, (n, 1))
    t = 0.5 + np.arange(n) * 1.1
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": b"adcp-case", "version": np.int32(1), "name": "foreign"})
        g = f.create_group("instrument")
        g.attrs.update({"beam_angle_rad": beam_angle, "transducer_radius_m": 0.05, "frequency_hz": 1.2e6,
                        "sound_speed_m_s": 1500.0, "n_beams": 4, "layout": "janus4"})
        f.create_group("environment").attrs.update({"water_depth_m": 12.0, "transducer_depth_m": 0.5})
        p = f.create_group("pings")
        p["time_s"] = t
        p["bt_radial_m_s"] = radial.astype(np.float32).astype(float)
        a = f.create_group("attitude")
        a.attrs["frame"] = "vessel"
        a["time_s"] = t[::2] + 0.1
        a["heading_rad"] = np.full(t[::2].size, heading)
        a["pitch_rad"] = np.zeros(t[::2].size)
        a["roll_rad"] = np.zeros(t[::2].size)
        r = f.create_group("reference")
        r["time_s"] = t
        r["velocity_m_s"] = np.tile(velocity, (n, 1))
        r.attrs["point_body_m"] = np.zeros(3)
        f.create_group("unknown_extra").attrs["whatever"] = 1


def test_foreign_rotation_free_case_asc_recovers_reference(tmp_path, capsys):
    path = tmp_path / "foreign.h5"
    v = np.array([0.7, -0.4, 0.01])
    _foreign_case(path, heading=np.deg2rad(250.0), velocity=v)
    assert main(["info", str(path)]) == 0
    out = tmp_path / "foreign_asc.h5"
    assert main(["correct", str(path), "--out", str(out)]) == 0
    corr = read_correction(out)
    ref = read_case(path).reference.velocity_m_s
    assert np.max(np.abs(corr["vessel_velocity_m_s"] - ref)) < 1e-6  # float32 radials in the file


@pytest.mark.parametrize("scenario", ["pool_m0", "deep_ship",
                                      pytest.param("deep_ocean", marks=pytest.mark.slow)])  # 7.5 s
def test_every_builtin_scenario_simulates_reads_and_corrects(tmp_path, scenario):
    case = tmp_path / f"{scenario}.h5"
    assert main(["simulate", scenario, "--seed", "1", "--out", str(case)]) == 0
    assert main(["correct", str(case), "--out", str(tmp_path / "o.h5")]) == 0


@pytest.mark.slow  # 7 s: `make test-slow`, CI's second step
def test_correct_oracle_with_exact_timing_and_a_clear_error_for_the_closed_form(tmp_path, capsys):
    case = tmp_path / "d.h5"
    assert main(["simulate", "deep_ocean", "--seed", "1", "--out", str(case)]) == 0
    out = tmp_path / "d_oracle.h5"
    assert main(["correct", str(case), "--method", "oracle", "--timing", "exact", "--out", str(out)]) == 0
    corr = read_correction(out)
    assert np.all(np.isfinite(corr["vessel_velocity_m_s"][corr["beams_used"] == 4]))
    assert main(["correct", str(case), "--method", "asc", "--timing", "exact", "--out", str(tmp_path / "x.h5")]) == 0
    assert main(["correct", str(case), "--method", "adc", "--timing", "exact", "--out", str(tmp_path / "y.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "timing" in err and "exact" in err
