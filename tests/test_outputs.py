"""Outputs: checked before the work, written atomically with the umask, no temporary left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from adcpdyn.cases import atomic
from adcpdyn.cases.atomic import TMP_TAG, atomic_path, check_output_file, check_output_folder, remove_stale_temporaries
from adcpdyn.cli import main


def _temporaries(folder):
    return sorted(p.name for p in folder.iterdir() if TMP_TAG in p.name)


def test_outputs_follow_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_path(tmp_path / "a.txt") as tmp:
            tmp.write_text("x")
        os.umask(0o002)
        with atomic_path(tmp_path / "b.txt") as tmp:
            tmp.write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o640
    assert (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o664


def test_stale_temporaries_of_dead_processes_are_removed_and_live_ones_kept(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    host = atomic._host()
    stale = tmp_path / f".out.h5{TMP_TAG}{host}-{dead_pid}-abcd_123.tmp"
    live = tmp_path / f".out.h5{TMP_TAG}{host}-{os.getppid()}-abcd_123.tmp"  # pytest's parent: alive
    other_host = tmp_path / f".out.h5{TMP_TAG}{host}x-{dead_pid}-abcd_123.tmp"
    unrelated = tmp_path / ".out.h5.abcd1234.tmp"  # not ours: never touched
    for p in (stale, live, other_host, unrelated):
        p.write_text("partial")
    assert remove_stale_temporaries(tmp_path) == [stale]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in (live, other_host, unrelated))


KILLED_WRITER = textwrap.dedent("""
    import sys, time
    from adcpdyn.cases import io
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate

    write = io._write
    def slow_write(f, case):
        write(f, case)
        f.flush()
        print("writing", flush=True)
        time.sleep(120)
    io._write = slow_write
    io.write_case(simulate(get_scenario("pool_m0"), seed=1), sys.argv[1])
""")


def test_a_write_killed_midway_leaves_no_output_and_the_next_run_removes_its_temporary(tmp_path, capsys):
    out = tmp_path / "case.h5"
    proc = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    assert not out.exists()
    left = _temporaries(tmp_path)
    assert len(left) == 1 and left[0].startswith(".case.h5" + TMP_TAG)
    assert main(["simulate", "pool_m0", "--seed", "1", "--out", str(out)]) == 0
    assert out.exists() and _temporaries(tmp_path) == []


def test_sigterm_during_a_command_removes_the_temporary(tmp_path):
    out = tmp_path / "case.h5"
    code = KILLED_WRITER.replace("io.write_case(simulate(get_scenario(\"pool_m0\"), seed=1), sys.argv[1])",
                                 "from adcpdyn.cli import main\nsys.exit(main(['simulate', 'pool_m0', '--out', sys.argv[1]]))")
    proc = subprocess.Popen([sys.executable, "-c", code, str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate()
    finally:
        proc.wait()
    assert proc.returncode == 128 + signal.SIGTERM
    assert err.count("\n") == 1 and "terminated" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_out_in_a_missing_folder_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    import adcpdyn.cases.simulation as simulator

    def never(*a, **k):
        raise AssertionError("the work started before --out was checked")

    monkeypatch.setattr(simulator, "simulate", never)
    assert main(["simulate", "pool_m0", "--out", str(tmp_path / "missing" / "m0.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err and "does not exist" in err
    assert main(["simulate", "pool_m0", "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("verb", ["correct", "calibrate", "diagnose"])
def test_impossible_out_is_refused_before_reading_the_case(tmp_path, capsys, verb, monkeypatch):
    import adcpdyn.cases.io as case_io

    monkeypatch.setattr(case_io, "read_case", lambda path: (_ for _ in ()).throw(AssertionError("case read before --out")))
    case = tmp_path / "c.h5"
    case.write_bytes(b"whatever")
    assert main([verb, str(case), "--out", str(tmp_path / "no" / "such" / "out.x")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err


def test_output_folders_are_created_only_below_an_existing_folder(tmp_path):
    assert check_output_folder(tmp_path / "new") == tmp_path / "new"
    assert not (tmp_path / "new").exists()  # created by the first output written into it, not before
    with pytest.raises(ValueError, match="parent folder .* does not exist"):
        check_output_folder(tmp_path / "a" / "b")
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="is a file"):
        check_output_folder(tmp_path / "f")
    with pytest.raises(ValueError, match="input file"):
        check_output_file(tmp_path / "f", tmp_path / "f")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(ValueError, match="cannot write"):
            check_output_file(ro / "x.h5")
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize("fails", [True, False])
def test_solver_chatter_on_the_descriptor_is_dropped_only_when_the_command_fails(tmp_path, capfd, monkeypatch, fails):
    import adcpdyn.cli.parser as cli

    def chatty(args):
        os.write(2, b'CasADi - WARNING("nlp_grad_f failed: NaN detected")\nanother line\n')
        if fails:
            raise ValueError("case.h5: /pings/bt_range_m: expected slant ranges > 0, got -1.0")
        print("summary")
        return 0

    monkeypatch.setattr(cli, "cmd_info", chatty)
    assert main(["info", "case.h5"]) == (2 if fails else 0)
    out, err = capfd.readouterr()
    if fails:
        assert err == "adcpdyn info: error: case.h5: /pings/bt_range_m: expected slant ranges > 0, got -1.0\n"
    else:
        assert "NaN detected" in err and "another line" in err and out == "summary\n"
