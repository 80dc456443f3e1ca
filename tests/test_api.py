"""The Python API at the package top (import, calibrate, correct, compare, export), the provenance of
what it writes, the figures, and a dolfyn Dataset as an import source."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import adcpdyn
from conftest import assert_provenance

ROOT = Path(__file__).resolve().parents[1]
REAL = Path(os.environ.get("ADCPDYN_REAL_DATA", ROOT / ".." / "shared" / "data" / "real"))


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """pool_m0 calibrated through the API (2 starts), its CALIB.json, and pool_m1 to correct."""
    folder = tmp_path_factory.mktemp("api")
    m0, m1 = folder / "m0.h5", folder / "m1.h5"
    adcpdyn.simulate("pool_m0", seed=1, out=m0)
    adcpdyn.simulate("pool_m1", seed=1, out=m1)
    result = adcpdyn.calibrate(m0, n_starts=2)
    path = folder / "CALIB.json"
    result.to_json(path)
    return result, path, m0, m1


# ----------------------------------------------------------------------------------------------- the API
def test_import_adcpdyn_is_light_and_exposes_the_api():
    code = ("import sys, adcpdyn; heavy = [m for m in ('casadi', 'xarray', 'h5py', 'mhkit') if m in sys.modules]; "
            "print(heavy, sorted(n for n in adcpdyn.__all__ if not hasattr(adcpdyn, n)))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="/")
    assert run.stdout.strip() == "[] []"
    for name in ("read_case", "import_file", "simulate", "calibrate", "read_calibration", "correct", "compare",
                 "diagnose", "to_xarray", "export"):
        doc = getattr(adcpdyn, name).__doc__
        assert "Parameters" in doc or "Returns" in doc, name  # numpydoc
    assert adcpdyn.CalibrationResult.__name__ == "CalibrationResult"  # types on first use


def test_correct_takes_the_result_its_dict_its_file_and_its_record_with_the_same_numbers(calibrated):
    from adcpdyn.estimators.calibration.record import as_record
    from adcpdyn.estimators.correction.correct_case import correct_case

    result, path, _, m1 = calibrated
    forms = {"result": result, "dict": result.to_dict(), "path": path, "str": str(path),
             "record": adcpdyn.CalibrationResult.from_json(path)}
    for method in ("asc", "adc"):
        out = {k: adcpdyn.correct(m1, method, c) for k, c in forms.items()}
        ref = out["path"].vessel_velocity_m_s
        assert np.isfinite(ref).all()
        for k, r in out.items():
            np.testing.assert_array_equal(r.vessel_velocity_m_s, ref, err_msg=f"{method} with the {k}")
    # the estimators read the record the API reads every form into once
    case = adcpdyn.read_case(m1)
    direct = correct_case(case, "adc", as_record(result)).vessel_velocity_m_s
    np.testing.assert_array_equal(direct, adcpdyn.correct(case, "adc", result).vessel_velocity_m_s)
    with pytest.raises(ValueError, match=r"^calibration: expected a CALIB.json path, a dict, a CalibrationResult"):
        adcpdyn.correct(m1, "adc", 3.0)
    with pytest.raises(ValueError, match=r"^method: expected one of"):
        adcpdyn.correct(m1, "magic")


def test_the_pipeline_on_a_simulated_case_in_memory(calibrated, tmp_path):
    result, _, _, m1 = calibrated
    case = adcpdyn.read_case(m1)
    corrected = adcpdyn.correct(case, "adc", result)
    assert corrected.provenance.calibration_file.startswith("none (a CalibrationResult in memory")
    assert corrected.provenance.source_case_file is None and corrected.provenance.source_case_name == "pool_m1"
    ds = adcpdyn.to_xarray(case, corrected)
    assert ds["case_time"].size == case.pings.n and ds.attrs["processing_method"] == "adc"
    north = ds["vessel_speed"].values * np.cos(np.deg2rad(ds["vessel_course"].values))  # CF: speed and course
    np.testing.assert_allclose(north, corrected.vessel_velocity_m_s[:, 0], atol=1e-12)
    comparison = adcpdyn.compare(m1, result)
    assert comparison.against == "truth" and {"asc", "adc", "oracle", "truth"} <= set(comparison.table)
    assert comparison.format_table().splitlines()[0].startswith("method")
    with pytest.raises(ValueError, match=r"^out: expected a netCDF file name ending in .nc"):
        adcpdyn.export(case, tmp_path / "x.h5", corrected)
    with pytest.raises(ValueError, match=r"^options: unknown calibration option 'starts'"):
        adcpdyn.calibrate(case, starts=2)
    with pytest.raises(ValueError, match=r"^case: expected a case file path, a Case or an ImportedCase"):
        adcpdyn.correct(42)


# ----------------------------------------------------------------------------------------------- provenance
def test_provenance_of_calibration_corrected_and_netcdf_files_written_by_the_api(calibrated, tmp_path):
    result, _, m0, m1 = calibrated
    calib, h5, nc = tmp_path / "CALIB.json", tmp_path / "m1.h5", tmp_path / "m1.nc"
    old = os.umask(0o027)
    try:
        result.to_json(calib)
        adcpdyn.correct(m1, "adc", calib, out=h5)
        adcpdyn.export(m1, nc, adcpdyn.correct(m1, "asc", calib))
    finally:
        os.umask(old)
    assert_provenance(calib, h5, nc, m0, m1, m0_path=m0)


@pytest.mark.parametrize("fmt, magic", [("pdf", b"%PDF"), ("svg", b"<svg"), ("png", b"\x89PNG")])
def test_compare_writes_its_figure_in_the_format_asked(calibrated, tmp_path, fmt, magic):
    _, calib, _, m1 = calibrated
    comparison = adcpdyn.compare(m1, calib, out=tmp_path, fmt=fmt)
    assert comparison.files == [tmp_path / "pool_m1_compare.json", tmp_path / f"pool_m1_compare.{fmt}"]
    assert magic in comparison.files[1].read_bytes()[:400]
    with pytest.raises(ValueError, match=r"^fmt: expected one of \['png', 'pdf', 'svg'\]"):
        adcpdyn.compare(m1, calib, fmt="gif")


# ----------------------------------------------------------------------------------------------- figures
def _captured(monkeypatch):
    from adcpdyn import plots

    figs = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figs.append((fig, path)))
    return plots, figs


def test_velocity_figure_labels_a_measured_reference_gnss_and_courses_0_360(monkeypatch):
    plots, figs = _captured(monkeypatch)
    t = np.arange(4.0)
    west_north_west = np.array([[0.3, -1.0, 0.0]] * 4)  # NED: course 286.7 deg, not -73.3
    plots.velocity_figure(t, {"asc": west_north_west}, west_north_west, "x", "v.png", reference_label="GNSS")
    fig, _ = figs[-1]
    speed, course = fig.axes
    labels = [h.get_label() for h in speed.get_legend().legend_handles]
    assert "GNSS" in labels and "truth" not in labels
    assert course.get_ylim() == (0.0, 360.0)
    np.testing.assert_allclose(course.lines[0].get_ydata(), np.rad2deg(np.arctan2(-1.0, 0.3)) + 360.0)
    assert [tx.get_text() for ax in fig.axes for tx in ax.texts] == ["(a)", "(b)"]
    np.testing.assert_allclose(plots.course_deg(np.array([[1.0, -1e-9, 0], [-1.0, 0.0, 0], [0.0, -1.0, 0]])),
                               [360.0 - 5.7e-8, 180.0, 270.0], atol=1e-6)


def test_attitude_panels_are_roll_pitch_yaw_lettered(monkeypatch):
    from adcpdyn.estimators.attitude_fit import fit_attitude

    plots, figs = _captured(monkeypatch)
    case = adcpdyn.simulate("pool_m0", seed=1)
    plots.attitude_fit_figure(case, fit_attitude(case).params, "a.png")
    fig, _ = figs[-1]
    assert [ax.get_ylabel() for ax in fig.axes] == ["roll (deg)", "pitch (deg)", "yaw (deg)"]
    assert [tx.get_text() for ax in fig.axes for tx in ax.texts] == ["(a)", "(b)", "(c)"]


def test_radius_vector_panels_are_lettered_and_say_truth_only_with_one(monkeypatch):
    plots, figs = _captured(monkeypatch)
    r = np.array([[0.1, 0.2, 0.3]] * 4)
    for truth in (r, None):
        plots.radius_vectors_figure(r, np.full((4, 3), 0.01), truth, "head", "r.svg")
        fig, _ = figs[-1]
        assert [tx.get_text() for ax in fig.axes for tx in ax.texts] == ["(a)", "(b)"]
        assert ("truth" in fig.axes[1].get_title()) == (truth is not None)


def test_compare_on_a_measured_reference_never_says_truth(tmp_path, monkeypatch):
    """A case with a reference velocity and no truth is compared against the reference, labelled GNSS."""
    from adcpdyn import plots

    labels = []
    monkeypatch.setattr(plots, "velocity_figure", lambda *a, reference_label, **k: labels.append((a[3], reference_label)))
    case = adcpdyn.simulate("deep_ship", seed=1)
    case = case.replace(truth=None)
    comparison = adcpdyn.compare(case, out=tmp_path, fmt="svg")
    assert comparison.against == "reference" and "reference" in comparison.table and "truth" not in comparison.table
    assert json.loads((tmp_path / f"{case.name}_compare.json").read_text())["against"] == "reference"
    (title, label), = labels
    assert label == "GNSS" and "truth" not in title and "GNSS" in title


# ----------------------------------------------------------------------------------------------- real files
def test_import_file_takes_the_dolfyn_dataset_too():
    src = REAL / "RiverPro_test01.PD0"
    if not src.is_file():
        pytest.skip(f"{src} absent")
    pytest.importorskip("mhkit")
    from adcpdyn.cases.importers.reader import read_dolfyn

    from_file = adcpdyn.import_file(src)
    ds, _ = read_dolfyn(src)
    from_ds = adcpdyn.import_file(ds, name="RiverPro_test01")
    a, b = from_file.case, from_ds.case
    assert b.name == "RiverPro_test01" and a.time_origin_utc == b.time_origin_utc
    for x, y in ((a.pings.bt_radial_m_s, b.pings.bt_radial_m_s), (a.pings.bt_range_m, b.pings.bt_range_m),
                 (a.water.radial_m_s, b.water.radial_m_s), (a.attitude.heading_rad, b.attitude.heading_rad),
                 (a.reference.velocity_m_s, b.reference.velocity_m_s)):
        np.testing.assert_array_equal(x, y)
    assert from_ds.provenance["source_file_sha256"].startswith("not available")
    assert from_ds.audit["/water"]["cell_size_changes"].startswith("unknown")
    with pytest.raises(ValueError, match=r"^source: expected an instrument file path or a dolfyn xarray.Dataset"):
        adcpdyn.import_file(object())


def test_a_correction_of_a_case_the_coverage_step_cut_exports(tmp_path):
    """Pings outside the attitude record are left out by correct; export (command and API) leaves them out too
    (it refused: 'expected the case's 57 ping times, got 50')."""
    import dataclasses

    case = adcpdyn.simulate("pool_m1", seed=1)
    a = case.attitude
    k = a.time_s <= case.pings.time_s[-1] - 5.0
    case = case.replace(attitude=dataclasses.replace(a, time_s=a.time_s[k], heading_rad=a.heading_rad[k],
                                                     pitch_rad=a.pitch_rad[k], roll_rad=a.roll_rad[k]))
    path = tmp_path / "cut.h5"
    from adcpdyn.cases.io import write_case
    from adcpdyn.cli import main

    write_case(case, path)
    corrected = adcpdyn.correct(path, "asc", out=tmp_path / "cut_asc.h5")
    assert 0 < corrected.time_s.size < case.pings.n and "left out" in corrected.provenance.warnings[-1]
    assert main(["export", str(tmp_path / "cut_asc.h5"), "--out", str(tmp_path / "cut.nc")]) == 0
    ds = adcpdyn.to_xarray(path, corrected)
    assert ds["case_time"].size == corrected.time_s.size
