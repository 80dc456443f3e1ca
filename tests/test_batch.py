"""Many cases through `adcpdyn calibrate` / `correct`: serial and on a Dask LocalCluster agree."""

from __future__ import annotations

import json

import numpy as np
import pytest

from adcpdyn.cli import main

SAME = 1e-12  # serial and cluster run the same deterministic solves


@pytest.fixture(scope="module")
def three_cases(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cases")
    for seed in (1, 2, 3):
        assert main(["simulate", "pool_m0", "--seed", str(seed), "--out", str(folder / f"m0_s{seed}.h5")]) == 0
    return folder


def _numbers(path):
    d = json.loads(path.read_text())
    return np.array(d["radius_vectors_head_m"] + [[d["objective"]] * 3], dtype=float)


@pytest.mark.slow  # 7.6 s on 2026-12-02's host: `make test-slow`, CI's second step
def test_calibrate_batch_serial_and_local_cluster_agree(three_cases, tmp_path, capsys):
    common = ["calibrate", str(three_cases), "--starts", "2", "--formulation", "minimal"]
    assert main(common + ["--scheduler", "none", "--out", str(tmp_path / "serial")]) == 0
    assert main(common + ["--scheduler", "local", "--workers", "2", "--out", str(tmp_path / "cluster")]) == 0
    text = capsys.readouterr().out
    assert "3 cases on scheduler 'local'" in text and "summary.json" in text
    for seed in (1, 2, 3):
        a, b = _numbers(tmp_path / "serial" / f"m0_s{seed}.json"), _numbers(tmp_path / "cluster" / f"m0_s{seed}.json")
        np.testing.assert_allclose(a, b, rtol=SAME, atol=SAME)
    rows = json.loads((tmp_path / "cluster" / "summary.json").read_text())
    assert [r["case"].endswith(f"m0_s{k}.h5") for k, r in zip((1, 2, 3), rows)] == [True] * 3


def test_correct_batch_with_a_glob_and_a_bad_case(three_cases, tmp_path, capsys):
    (three_cases.parent / "bad").mkdir(exist_ok=True)
    bad = three_cases.parent / "bad" / "broken.h5"
    bad.write_bytes(b"not hdf5")
    code = main(["correct", str(three_cases / "m0_s*.h5"), str(bad), "--method", "asc", "--scheduler", "none",
                 "--out", str(tmp_path / "corr")])
    out = capsys.readouterr().out
    assert code == 2  # one case failed; the others were written
    assert sorted(p.name for p in (tmp_path / "corr").glob("*.h5")) == [f"m0_s{k}_asc.h5" for k in (1, 2, 3)]
    broken = [line for line in out.splitlines() if line.startswith("broken")]
    assert len(broken) == 1 and "error" in broken[0]


@pytest.mark.parametrize("argv, word", [
    (["calibrate", "/nonexistent/*.h5", "--out", "x"], "case"),
    (["calibrate", "A", "B", "--scheduler", "nowhere", "--out", "x"], "--scheduler"),
])
def test_batch_bad_arguments_are_one_line_errors(argv, word, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert word in err and "\n" not in err


def test_batch_out_must_be_a_folder(three_cases, tmp_path, capsys):
    f = tmp_path / "file.json"
    f.write_text("{}")
    assert main(["calibrate", str(three_cases), "--out", str(f), "--scheduler", "none"]) == 2
    assert "--out" in capsys.readouterr().err


@pytest.mark.slow  # 7 s: `make test-slow`, CI's second step
def test_joint_calibration_starts_on_a_local_cluster_agree_with_this_process(tmp_path, capsys):
    """`calibrate --joint --scheduler local`: every start solved on a Dask worker that built the problem
    itself; the combined multistart is the one solved here, start by start (same objectives, same best,
    same estimates), and CALIB.json says where it ran."""
    from adcpdyn.cases.survey import survey_scenarios
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.cases.io import write_case

    import dataclasses

    paths = []
    for k, sc in enumerate(survey_scenarios("river_survey", 2, 5)):
        paths.append(tmp_path / f"t{k}.h5")
        short = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=60.0))  # ~100 pings each
        write_case(simulate(short, seed=5 + k), paths[-1])
    common = ["calibrate", *map(str, paths), "--joint", "--starts", "3"]
    assert main(common + ["--out", str(tmp_path / "here.json")]) == 0
    assert main(common + ["--scheduler", "local", "--workers", "2", "--out", str(tmp_path / "cluster.json")]) == 0
    here, cluster = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("here", "cluster"))
    assert cluster["config"]["scheduler"] == "local" and here["config"]["scheduler"] == "none"
    assert [s["objective"] for s in cluster["starts"]] == pytest.approx([s["objective"] for s in here["starts"]], rel=SAME)
    assert [s["index"] for s in cluster["starts"]] == [0, 1, 2]
    assert cluster["solver"]["best_start"] == here["solver"]["best_start"]
    np.testing.assert_allclose(cluster["heading_misalignment_rad"], here["heading_misalignment_rad"], rtol=SAME, atol=SAME)
    assert main(common + ["--scheduler", "tcp://nowhere", "--out", str(tmp_path / "x.json")]) == 2
    assert "--scheduler" in capsys.readouterr().err
