"""Every input gets a right answer or a one-line error (issue 17).

Malformed variants of a simulated case, of calibration files and of a real PD0
(``fuzzlib``) go through every verb that reads them, in this process: each run must end
with exit status 0 and finite, sane velocities on a valid input, or exit status 2 and
one line on stderr naming the field or option; never a traceback, never a temporary
file left behind. ``python tests/fuzzlib.py FOLDER`` prints the whole table.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import fuzzlib
from fuzzlib import Variant, calibration_variants, case_variants, judge, pd0_variants, run, run_plan

REAL_PD0 = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "RiverPro_test01.PD0"


@pytest.fixture(scope="module")
def fuzz(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz")
    return folder, fuzzlib.base_files(folder / "base")


def _report(problems, counts):
    table = "\n".join(f"{verb:<20} {what:<8} {n}" for (verb, what), n in sorted(counts.items()))
    return f"{len(problems)} problem(s):\n" + "\n".join(problems) + "\n" + table


def _ran(counts, verb, what):
    return counts.get((verb, what), 0)


@pytest.mark.slow  # 54 s: `make test-slow`, CI's second step
def test_malformed_case_files_through_every_verb(fuzz):
    folder, base = fuzz
    items = [(v, "case") for v in case_variants(base["pool"], folder / "cases")]
    items += [(v, "water") for v in case_variants(base["ocean"], folder / "water", water=True)]
    problems, counts = run_plan(items, base, folder)  # the NaN reference vertical included
    assert not problems, _report(problems, counts)
    # the generator really produced both kinds: refused files and valid foreign ones
    assert _ran(counts, "info", "exit 2") > 150 and _ran(counts, "correct adc", "exit 0") >= 10
    assert _ran(counts, "calibrate", "exit 0") >= 10 and _ran(counts, "compare", "exit 0") >= 10


@pytest.mark.slow  # 6.7 s on 2026-12-02's host: `make test-slow`, CI's second step
def test_malformed_calibration_files_through_every_reader(fuzz):
    folder, base = fuzz
    items = [(v, "calib_pool") for v in calibration_variants(base["calib_pool"], folder / "calibs")]
    items += [(v, "calib_ship") for v in calibration_variants(base["calib_ship"], folder / "calibs")]
    problems, counts = run_plan(items, base, folder)
    assert not problems, _report(problems, counts)
    assert _ran(counts, "correct adc", "exit 2") > 40 and _ran(counts, "correct rootfinder", "exit 0") >= 4


@pytest.mark.slow  # 5.5 s
@pytest.mark.skipif(not REAL_PD0.exists(), reason=f"real data file {REAL_PD0} absent")
def test_damaged_instrument_files_are_read_or_refused_in_one_line(fuzz, capfd):
    folder, base = fuzz
    items = [(v, "pd0") for v in pd0_variants(REAL_PD0, folder / "pd0")]
    problems, counts = run_plan(items, base, folder)
    out, err = capfd.readouterr()  # what escaped to the file descriptors (dolfyn's log, LAPACK)
    assert not problems, _report(problems, counts)
    assert _ran(counts, "import", "exit 0") >= 2 and _ran(counts, "import", "exit 2") >= 4
    assert "checksum" not in out + err and "DLASCL" not in out + err


@pytest.mark.parametrize("argv, words", [
    (["calibrate", "{case}", "--starts", "0", "--out", "{out}/c.json"], "--starts"),
    (["calibrate", "{case}", "--starts", "many", "--out", "{out}/c.json"], "--starts"),
    (["calibrate", "{case}", "--formulation", "best", "--out", "{out}/c.json"], "formulation"),
    (["simulate", "pool_m0", "--seed", "-1", "--out", "{out}/s.h5"], "--seed"),
    (["correct", "{case}", "--timing", "later", "--out", "{out}/o.h5"], "--timing"),
    (["correct", "{case}", "--method", "magic", "--out", "{out}/o.h5"], "--method"),
    (["correct", "{case}", "--out", "{out}/missing/o.h5"], "--out"),
    (["correct", "{case}", "--out", "{case}"], "--out"),
    (["correct", "{case}", "--out", "{out}"], "--out"),
    (["import", "{case}", "--start", "nan", "--out", "{out}/i.h5"], "--start"),
    (["diagnose", "{case}"], "--out"),
    (["diagnose", "--selftest", "0"], "--selftest"),
    (["diagnose", "{case}", "{case}", "--field-selftest", "--out", "{out}/s.json"], "--joint"),
    (["info"], "case"),
    (["frobnicate"], "command"),
])
def test_bad_options_are_one_line_errors(fuzz, tmp_path, argv, words):
    _, base = fuzz
    outcome = run([a.format(case=base["pool"], out=tmp_path) for a in argv])
    assert outcome.traceback is None and outcome.code == 2
    assert outcome.err.count("\n") == 1 and words in outcome.err and "usage:" not in outcome.err
    assert [p for p in tmp_path.rglob("*") if p.is_file()] == []


def test_many_cases_with_malformed_ones(fuzz, tmp_path):
    """A folder mixing valid and malformed cases: each bad one is one error row, the others are written."""
    folder, base = fuzz
    cases = tmp_path / "cases"
    cases.mkdir()
    picks = [v for v in case_variants(base["pool"], folder / "batch_src")
             if v.path.is_file() and v.name.split(": ", 1)[1] in ("/pings/bt_radial_m_s one Inf", "truncated HDF5",
                                                                   "reference without vertical", "missing attitude samples",
                                                                   '/instrument.attrs["sound_speed_m_s"] NaN')]
    assert len(picks) == 5
    for v in picks:
        (cases / v.path.name).write_bytes(v.path.read_bytes())
    out = tmp_path / "corrected"
    o = run(["correct", str(cases), "--method", "adc", "--calibration", str(base["calib_pool"]), "--scheduler", "none",
             "--out", str(out)])
    assert o.traceback is None and o.code == 2 and o.err == ""
    rows = json.loads((out / "summary.json").read_text())
    bad = {Path(r["case"]).name for r in rows if r["error"]}
    assert bad == {v.path.name for v in picks if v.expect == "error"}
    assert all("\n" not in r["error"] for r in rows if r["error"])
    assert sorted(p.name for p in out.glob("*.h5")) == sorted(f"{v.path.stem}_adc.h5" for v in picks if v.expect == "ok")
    assert not list(tmp_path.rglob(f"*{fuzzlib.TMP_TAG}*"))


def test_the_judge_catches_what_it_is_for(tmp_path):
    """The harness itself: a traceback, a two-line error, an error not naming the field, a valid
    input refused and garbage velocities are all reported."""
    import h5py
    import numpy as np

    v_err = Variant("x", tmp_path / "x.h5", "error", ("/pings/time_s",))
    v_ok = Variant("y", tmp_path / "y.h5", "ok")
    assert "traceback" in judge(v_err, "info", fuzzlib.Outcome(None, "", "", "Traceback\nKeyError: 3"), [], tmp_path)
    assert "2 lines" in judge(v_err, "info", fuzzlib.Outcome(2, "", "a\nb\n"), [], tmp_path)
    assert "does not name" in judge(v_err, "info", fuzzlib.Outcome(2, "", "bad input\n"), [], tmp_path)
    assert judge(v_err, "info", fuzzlib.Outcome(2, "", "f: /pings/time_s: expected ...\n"), [], tmp_path) is None
    assert "valid input refused" in judge(v_ok, "info", fuzzlib.Outcome(2, "", "f: x\n"), [], tmp_path)
    out = tmp_path / "o.h5"
    with h5py.File(out, "w") as f:
        f["corrected/vessel_velocity_m_s"] = np.array([[1e3, 0.0, 0.0]])
        f["corrected/beams_used"] = np.array([4])
    assert "absurd" in judge(v_ok, "correct", fuzzlib.Outcome(0, "", ""), [out], tmp_path)
    (tmp_path / f".o.h5{fuzzlib.TMP_TAG}h-1-abcdefgh.tmp").write_text("")
    assert "temporary" in judge(v_ok, "correct", fuzzlib.Outcome(0, "", ""), [], tmp_path)


@pytest.mark.slow
def test_valid_variants_through_diagnose(fuzz):
    """The slow verb on every case variant the format allows (a few seconds each)."""
    folder, base = fuzz
    problems, out = [], folder / "out_diagnose"  # its own: the other verbs' outputs share "out"
    out.mkdir(exist_ok=True)
    for v in case_variants(base["pool"], folder / "cases_slow"):
        if v.expect == "error":
            continue
        d = out / "d.json"
        o = run(["diagnose", str(v.path), "--effects", "heave", "--out", str(d)])
        problem = judge(v, "diagnose", o, [d], folder)
        if problem:
            problems.append(f"{v.name}: {problem}")
        for p in out.iterdir():
            p.unlink()
    assert not problems, "\n".join(problems)
