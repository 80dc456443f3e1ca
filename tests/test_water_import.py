"""Water profiles of the real TRDI files: back in beam coordinates, and with the static correction
equal to the instrument's own Earth-frame water velocities (dolfyn), relative and referenced to the
bottom track, to 1e-6 m/s."""

from __future__ import annotations


import h5py
import numpy as np
import pytest
from conftest import dolfyn_dataset, real
from dolfyn_reference import dolfyn_earth

from adcpdyn.cases.importers import Window, import_file, write_imported
from adcpdyn.cases.io import read_case
from adcpdyn.estimators.asc import asc, earth_rotation
from adcpdyn.estimators.water import static_relative_water

EARTH_WATER_TOL = 1e-6  # m/s
FLOAT32_EPS = float(np.finfo(np.float32).eps)

FILES = [("RiverPro_test01.PD0", "beam"), ("winriver01.PD0", "ship"), ("winriver02_transect.PD0", "ship"),
         ("RDI_withBT.000", "earth"), ("vmdas02_os.ENR", "beam")]


def _dolfyn(name, case, float64=True):
    """dolfyn's Earth (E, N, U) water (N, K, 3) and bottom-track (N, 3) velocities at the case's pings."""
    from adcpdyn.cases.importers.window import select

    ds = dolfyn_dataset(name)
    keep, _ = select(ds["time"].values.astype("datetime64[ns]").astype(np.int64) / 1e9, Window(), name)
    vel, vel_bt = dolfyn_earth(ds, float64=float64)
    K = case.water.cell_depth_m.size
    return vel[:3, :K][:, :, keep].transpose(2, 1, 0), vel_bt[:3, keep].T


def _enu(ned):
    return np.stack([ned[..., 1], ned[..., 0], -ned[..., 2]], axis=-1)


def _ours(case):
    """Static correction without calibration: (relative, BT-referenced) Earth water velocities in ENU."""
    rel = static_relative_water(case, earth_rotation(case, case.pings.time_s, np.zeros(3)))
    return _enu(rel), _enu(asc(case).water_velocity_m_s)


def _max_diff(a, b, min_count):
    both = np.isfinite(a).all(-1) & np.isfinite(b).all(-1)
    assert both.sum() >= min_count
    return float(np.max(np.abs(a[both] - b[both]))), int(both.sum())


@pytest.mark.parametrize("name, frame", FILES)
def test_static_water_equals_the_instrument_earth_velocities(imported, name, frame):
    """Relative water velocity = dolfyn's Earth ``vel``; referenced to the bottom track = ``vel - vel_bt``
    (the bottom track's Earth velocity is the bed's relative to the ADCP): like for like, dolfyn's own
    rotation evaluated in float64 (:mod:`dolfyn_reference`), to 1e-6 m/s."""
    case, attrs = imported(name)
    assert attrs["/provenance"]["coordinate_system_found"] == frame
    rel, ref = _ours(case)
    theirs, bt = _dolfyn(name, case)
    n_theirs = int(np.isfinite(theirs).all(-1).sum())
    d_rel, n_rel = _max_diff(rel, theirs, min_count=0.6 * n_theirs)
    d_ref, n_ref = _max_diff(ref, theirs - bt[:, None, :], min_count=0.3 * n_theirs)
    assert d_rel < EARTH_WATER_TOL and d_ref < EARTH_WATER_TOL, (name, d_rel, n_rel, d_ref, n_ref)
    # what the instrument solved but the case cannot hold: its three-beam cells (ship/Earth files) only
    lost = np.isfinite(theirs).all(-1) & ~np.isfinite(rel).all(-1)
    assert int(lost.sum()) == attrs["/water"]["three_beam_cells"]


@pytest.mark.parametrize("name, frame", FILES)
def test_dolfyn_float32_output_differs_by_its_rounding_only(imported, name, frame):
    """dolfyn's own float32 output, unpatched: differences within a few float32 steps of the velocity."""
    case, _ = imported(name)
    rel, _ = _ours(case)
    theirs, _ = _dolfyn(name, case, float64=False)
    both = np.isfinite(rel).all(-1) & np.isfinite(theirs).all(-1)
    excess = np.abs(rel - theirs)[both] - 4 * FLOAT32_EPS * np.maximum(np.abs(theirs[both]), 1.0)
    assert both.sum() > 1000 and np.max(excess) < EARTH_WATER_TOL


def test_three_beam_cells_and_screening_are_recorded(imported):
    _, attrs = imported("winriver01.PD0")
    w = attrs["/water"]
    assert w["three_beam_cells"] > 1000 and "which beam was missing" in w["three_beam_solutions"]
    assert "bin mapping" in w["bin_mapping_EX"]
    for name in ("RiverPro_test01.PD0", "vmdas02_os.ENR"):  # beam files: the marker already holds the screening
        _, attrs = imported(name)
        assert attrs["/water"]["screened_values"] == 0 and attrs["/water"]["three_beam_cells"] == 0


def test_cell_depths_follow_the_instrument_geometry(imported):
    case, attrs = imported("winriver01.PD0")
    ds = dolfyn_dataset("winriver01.PD0")
    cells = case.water.cell_depth_m
    rng = np.asarray(ds["range"].values, dtype=float)
    assert np.allclose(cells, case.environment.transducer_depth_m + rng[:cells.size], atol=1e-12)
    assert cells[-1] < np.max(case.environment.depth_at_pings(case.pings.n)) <= cells[-1] + np.diff(rng)[0]
    assert cells.size < rng.size == attrs["/water"]["cells_in_file"]


def test_cell_size_changes_are_reported(imported):
    _, attrs = imported("RiverPro_test01.PD0")
    w = attrs["/water"]
    assert w["merged_pings"] > 100 and "depth-averaged" in w["cell_size_changes"]
    _, attrs = imported("winriver02_transect.PD0")
    assert attrs["/water"]["merged_pings"] == 0


def test_water_round_trip_through_the_case_file(tmp_path, imported):
    case, attrs = imported("RiverPro_test01.PD0")
    out = tmp_path / "rp.h5"
    write_imported(case, attrs, out, source=real("RiverPro_test01.PD0"))
    back = read_case(out)
    np.testing.assert_array_equal(back.water.radial_m_s, case.water.radial_m_s)  # NaN where NaN
    np.testing.assert_array_equal(back.water.cell_depth_m, case.water.cell_depth_m)
    assert back.water.radial_m_s.shape == (case.pings.n, 4, case.water.cell_depth_m.size)
    with h5py.File(out) as f:
        assert "RDI beams 4,3,2,1" in f["/water"].attrs["beam_mapping"]
        assert "toward the transducer" in f["/water"].attrs["sign"]
        assert f["/provenance"].attrs["water_profile"].startswith("imported")
        assert len(f["/provenance"].attrs["source_file_sha256"]) == 64


def test_window_selects_the_same_water(imported):
    full, _ = imported("RiverPro_test01.PD0")
    part, _ = import_file(real("RiverPro_test01.PD0"), Window(start_s=20.0, end_s=120.0, every=2))
    t0 = np.flatnonzero(full.pings.time_s >= 20.0)[0]
    rows = np.arange(t0, t0 + 2 * part.pings.n, 2)
    k = part.water.cell_depth_m.size  # the cells above the deepest bed of the selected pings
    assert 0 < k <= full.water.cell_depth_m.size
    np.testing.assert_array_equal(part.water.cell_depth_m, full.water.cell_depth_m[:k])
    np.testing.assert_array_equal(part.water.radial_m_s, full.water.radial_m_s[rows][:, :, :k])


@pytest.mark.parametrize("name, frame", FILES)
def test_exported_netcdf_equals_the_instrument_earth_velocities(tmp_path, imported, name, frame):
    """The same check through ``correct_case`` and the CF export read back with xarray (ENU, beams, time)."""
    xr = pytest.importorskip("xarray")
    from adcpdyn.cases.netcdf import to_xarray, write_netcdf
    from adcpdyn.estimators.correction.correct_case import correct_case

    case, attrs = imported(name)
    write_netcdf(to_xarray(case, correct_case(case, "asc", None), provenance=attrs["/provenance"]), tmp_path / "w.nc")
    theirs, bt = _dolfyn(name, case)
    with xr.open_dataset(tmp_path / "w.nc", engine="h5netcdf") as ds:
        rel = np.stack([ds[f"water_relative_velocity_{c}"].values for c in ("east", "north", "up")], axis=-1)
        ref = np.stack([ds[f"water_velocity_{c}"].values for c in ("east", "north", "up")], axis=-1)
        pings = "time" if case.time_origin_utc else "case_time"  # undated files: the case clock is the axis
        assert ds["water_velocity_east"].dims == (pings, "depth") and ds["case_time"].size == case.pings.n
    n_theirs = int(np.isfinite(theirs).all(-1).sum())
    d_rel, _ = _max_diff(rel, theirs, min_count=0.6 * n_theirs)
    d_ref, _ = _max_diff(ref, theirs - bt[:, None, :], min_count=0.3 * n_theirs)
    assert d_rel < EARTH_WATER_TOL and d_ref < EARTH_WATER_TOL, (name, d_rel, d_ref)
