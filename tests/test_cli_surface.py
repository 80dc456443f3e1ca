"""The command line's surface: --version, --help (every command, defaults, choices, exit statuses),
exit statuses, progress on stderr, provenance of what the commands write, the in-process batch of one
or two cases, and --format."""

from __future__ import annotations

import json
import os
from importlib.metadata import version

import h5py
import numpy as np
import pytest

import adcpdyn
from adcpdyn.cases.hashing import sha256_of
from conftest import assert_provenance
from adcpdyn.cli import main
from adcpdyn.cli.parser import build_parser


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """pool_m0 and pool_m1 case files and a CALIB.json of pool_m0 (2 starts)."""
    folder = tmp_path_factory.mktemp("cli")
    m0, m1, calib = folder / "m0.h5", folder / "m1.h5", folder / "CALIB.json"
    assert main(["simulate", "pool_m0", "--seed", "1", "--out", str(m0)]) == 0
    assert main(["simulate", "pool_m1", "--seed", "1", "--out", str(m1)]) == 0
    assert main(["calibrate", str(m0), "--starts", "2", "--out", str(calib)]) == 0
    return None, calib, m0, m1


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"adcpdyn {version('adcpdyn')}" == f"adcpdyn {adcpdyn.__version__}"


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return parser, action


def test_help_lists_every_command_with_defaults_choices_and_exit_statuses(capsys):
    parser, action = _subcommands()
    assert main(["--help"]) == 0
    top = capsys.readouterr().out
    helps = {c.dest: c.help for c in action._choices_actions}
    assert set(helps) == set(action.choices) and len(helps) >= 12
    for name, text in helps.items():
        assert text and f"{name}" in top and text.split()[0] in top, name
    for status in ("0 ", "1 ", "2 ", "130", "141", "143"):
        assert f"  {status}" in top
    for name, sub in action.choices.items():
        assert main([name, "--help"]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert "exit status:" in text, name
        for a in sub._actions:
            if not a.option_strings or a.help == "==SUPPRESS==" or a.dest == "help":
                continue
            if a.default not in (None, False):
                assert f"(default: {a.default})" in text, (name, a.dest)
            if a.choices:
                assert "{" + ",".join(map(str, a.choices)) + "}" in text, (name, a.dest)
    choices = {a.dest: a.choices for a in action.choices["correct"]._actions}
    assert choices["method"] == adcpdyn.CORRECTION_METHODS and choices["reference"] == ("bt", "gnss")
    assert tuple(choices["timing"]) == ("deep", "shallow", "exact")
    for verb in ("compare", "demo", "diagnose"):
        assert {a.dest: a.choices for a in action.choices[verb]._actions}["format"] == ("png", "pdf", "svg")


def test_exit_statuses(calibrated, tmp_path, capsys, monkeypatch):
    _, _, m0, _ = calibrated
    assert main(["scenarios"]) == 0
    assert main(["info", str(tmp_path / "missing.h5")]) == 2
    assert main(["correct", str(m0), "--method", "magic", "--out", str(tmp_path / "o.h5")]) == 2
    assert main(["compare", str(m0), "--format", "gif"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 3 and "--method" in err and "--format" in err
    from adcpdyn.estimators.calibration.result import CalibrationResult

    monkeypatch.setattr(CalibrationResult, "success", property(lambda self: False))  # a solve that did not converge
    out = tmp_path / "c.json"
    assert main(["calibrate", str(m0), "--starts", "1", "--out", str(out)]) == 1
    assert out.exists()  # written, and it says so
    assert json.loads(out.read_text())["solver"]["success"] in (True, False)


def test_progress_lines_on_stderr_only_when_asked_or_on_a_terminal(calibrated, tmp_path, capfd, monkeypatch):
    _, _, m0, _ = calibrated
    monkeypatch.setenv("ADCPDYN_PROGRESS", "1")
    assert main(["calibrate", str(m0), "--starts", "1", "--out", str(tmp_path / "a.json")]) == 0
    out, err = capfd.readouterr()
    lines = [ln for ln in err.splitlines() if ln.startswith("adcpdyn calibrate: [")]
    assert len(lines) == 2 and "attitude pre-fit" in lines[0] and "solving: 1 start" in lines[1]
    assert "adcpdyn calibrate: [" not in out  # stdout stays clean for parsing
    monkeypatch.setenv("ADCPDYN_PROGRESS", "0")
    assert main(["calibrate", str(m0), "--starts", "1", "--out", str(tmp_path / "b.json")]) == 0
    assert "adcpdyn calibrate: [" not in capfd.readouterr().err


@pytest.mark.slow  # 6.8 s on 2026-12-02's host: `make test-slow`, CI's second step
def test_diagnose_progress_names_round_effect_and_time(tmp_path, capfd, monkeypatch):
    import dataclasses

    from adcpdyn.cases.scenario import get_scenario

    sc = get_scenario("diag_boat")  # as tests/test_diagnosis.py, shortened
    sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=30.0))
    path = tmp_path / "d.h5"
    adcpdyn.simulate(sc, seed=3, out=path)
    monkeypatch.setenv("ADCPDYN_PROGRESS", "1")
    code = main(["diagnose", str(path), "--effects", "attitude_latency", "--out", str(tmp_path / "diag.json"),
                 "--format", "svg"])
    out, err = capfd.readouterr()
    assert code in (0, 1)
    lines = [ln for ln in err.splitlines() if ln.startswith("adcpdyn diagnose: [")]
    assert "fitting the base model (1 run)" in lines[0]
    assert any("round 1: fitted attitude_latency" in ln for ln in lines), lines
    assert lines[-1].split("] ")[1].startswith("done: verdict")
    assert all(ln[len("adcpdyn diagnose: ["):].split(" s]")[0].strip().replace(".", "").isdigit() for ln in lines)
    figure = tmp_path / "diag_residuals.svg"  # named after DIAG.json, not the run: two diagnoses in one folder keep theirs
    assert figure.exists() and b"<svg" in figure.read_bytes()[:2000]


# ----------------------------------------------------------------------------------------------- batch
def test_a_batch_of_one_or_two_cases_runs_in_this_process(calibrated, tmp_path, capsys, monkeypatch):
    import distributed

    from adcpdyn.batch import resolve_scheduler

    assert [resolve_scheduler("auto", n) for n in (1, 2, 3)] == ["none", "none", "local"]
    assert resolve_scheduler("local", 1) == "local" and resolve_scheduler("tcp://h:1", 1) == "tcp://h:1"
    with pytest.raises(ValueError, match="--scheduler"):
        resolve_scheduler("nowhere", 1)

    def no_cluster(*a, **k):
        raise AssertionError("a LocalCluster was started for two cases")

    monkeypatch.setattr(distributed, "LocalCluster", no_cluster)
    _, calib, m0, m1 = calibrated
    out = tmp_path / "corr"
    assert main(["correct", str(m0), str(m1), "--method", "adc", "--calibration", str(calib), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "2 cases on scheduler 'none' (auto: in this process for 1-2 cases)" in text
    assert sorted(p.name for p in out.glob("*.h5")) == ["m0_adc.h5", "m1_adc.h5"]
    with h5py.File(out / "m1_adc.h5", "r") as f:  # batch outputs carry the same provenance
        assert json.loads(f["corrected"].attrs["settings"])["calibration_sha256"] == sha256_of(calib)


def test_provenance_of_what_the_commands_write_and_the_umask(calibrated, tmp_path):
    _, _, m0, m1 = calibrated
    calib = tmp_path / "CALIB.json"
    old = os.umask(0o027)
    try:
        assert main(["calibrate", str(m0), "--starts", "1", "--out", str(calib)]) == 0
        h5, nc = tmp_path / "m1.h5", tmp_path / "m1.nc"
        assert main(["correct", str(m1), "--method", "adc", "--calibration", str(calib), "--out", str(h5)]) == 0
        assert main(["correct", str(m1), "--method", "asc", "--calibration", str(calib), "--out", str(nc)]) == 0
    finally:
        os.umask(old)
    assert_provenance(calib, h5, nc, m0, m1)


@pytest.mark.parametrize("fmt, magic", [("pdf", b"%PDF")])
def test_compare_format_option(calibrated, tmp_path, fmt, magic, capsys):
    _, calib, _, m1 = calibrated
    assert main(["compare", str(m1), "--calibration", str(calib), "--out", str(tmp_path), "--format", fmt]) == 0
    figure = tmp_path / f"pool_m1_compare.{fmt}"
    assert magic in figure.read_bytes()[:400]
    assert "against simulated truth" in capsys.readouterr().out


def test_demo_writes_its_figures_in_the_format_asked(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--starts", "1", "--scenario", "pool_m1", "--format", "svg", "--out", str(out)]) == 0
    for name in ("attitude_fit", "radius_vectors", "pool_m1_velocity"):
        assert b"<svg" in (out / f"{name}.svg").read_bytes()[:2000], name
    assert not list(out.glob("*.png"))
    assert "radius_vectors.svg" in capsys.readouterr().out


def test_contradicting_options_and_wrong_files_are_refused_in_one_line_naming_them(tmp_path, capsys):
    """Options that contradict or would be ignored, output names that do not match what is written,
    and files of another kind (a CALIB.json, a PD0, a netCDF export given as a case) are refused in
    one line in the user's own flag names and units, exit 2, nothing written."""
    case, nc, calib = tmp_path / "m1.h5", tmp_path / "m1.nc", tmp_path / "c.json"
    assert main(["simulate", "pool_m1", "--seed", "1", "--out", str(case)]) == 0
    assert main(["export", str(case), "--out", str(nc)]) == 0
    calib.write_text('{"radius_vectors_m": null}')
    out = tmp_path / "out"
    cases = {
        ("calibrate", str(case), "--out", f"{out}.h5"): "--out: expected a CALIB.json file name ending in .json",
        ("calibrate", str(case), "--declination-deg", "400", "--out", f"{out}.json"): "--declination-deg: expected an angle in degrees within +-180",
        ("calibrate", str(case), "--moving-bed", "off", "--bed-knots", "5", "--out", f"{out}.json"): "--bed-knots 5: sets the values of --moving-bed section",
        ("calibrate", str(case), "--compass-deviation", "off", "--compass-deviation-prior-deg", "2", "--out", f"{out}.json"):
            "--compass-deviation-prior-deg 2: the prior of --compass-deviation auto",
        ("calibrate", str(case), "--compass-deviation-prior-deg", "0", "--out", f"{out}.json"):
            "--compass-deviation-prior-deg: expected a standard deviation in degrees within (0, 28.6]",
        ("calibrate", "--joint", str(case), str(case), "--method", "two-stage", "--out", f"{out}.json"): "--method two-stage: the paper's two-stage baseline",
        ("correct", str(case), "--out", f"{out}.csv"): "--out: expected OUT.h5",
        ("diagnose", "--selftest", "3", str(case)): "--selftest 3 simulates its own cases",
        ("diagnose", str(case), "--out", f"{out}.h5"): "--out: expected a file name ending in .json",
        ("diagnose", str(case), "--ignore-own-effects", "--out", f"{out}.json"):
            "--ignore-own-effects: drops what a calibration's own runs showed when calibrated; with no --calibration",
        ("diagnose", str(case), "--given", "heave", "--ignore-own-effects", "--out", f"{out}.json"):
            "with --given (given effects are fitted, nothing is held)",
        ("info", str(calib)): "got a JSON file (a CALIB.json",
        ("info", str(nc)): "got a netCDF file (an export",
    }
    for argv, words in cases.items():
        capsys.readouterr()
        assert main(list(argv)) == 2, argv
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, (argv, err)
        assert not list(tmp_path.glob("out*")), argv


def test_noise_levels_are_printed_with_their_units():
    import numpy as np

    from adcpdyn.text import noise_levels_line

    line = noise_levels_line({"heading": float(np.radians(0.5)), "bt": 0.0637, "range": 0.396, "reference": None,
                              "motion": 0.19})
    assert line == "noise levels (one standard deviation): heading 0.5 deg, bt 0.0637 m/s, range 0.396 m, motion 0.19 m/s/sqrt(s)"


def test_a_reader_that_stops_reading_ends_the_command_quietly():
    """``adcpdyn scenarios | head -1``: the pipe closed before the output is written ends the
    command with 128 + SIGPIPE and nothing on stderr (no 'Broken pipe' error, no traceback)."""
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "adcpdyn.cli", "scenarios"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 128 + signal.SIGPIPE and err == ""


def test_compass_deviation_prior_flag_sets_the_calibrations_prior():
    """`--compass-deviation-prior-deg` is the prior's SD of B and C in degrees; without it the
    calibration's default (1 deg)."""
    from adcpdyn.cli.parser import build_parser
    from adcpdyn.cli.verbs.calibration import calibration_config as _calibration_config
    from adcpdyn.estimators.calibration.config import CalibrationConfig

    parse = lambda *more: build_parser().parse_args(["calibrate", "m.h5", "--out", "c.json", *more])
    assert _calibration_config(parse("--compass-deviation-prior-deg", "0.5")).compass_deviation_prior_rad == \
        pytest.approx(np.deg2rad(0.5))
    assert _calibration_config(parse()).compass_deviation_prior_rad == CalibrationConfig().compass_deviation_prior_rad
