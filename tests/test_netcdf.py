"""CF netCDF export: read back with xarray (same numbers, ENU, UTC time, beams), a CF check of
units/time/dims, atomic writing with the umask's permissions, provenance attributes."""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import noise_free

from adcpdyn.cases.io import write_case
from adcpdyn.cases.netcdf import export_file, to_xarray, write_netcdf
from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cli import main
from adcpdyn.estimators.correction.correct_case import correct_case
from adcpdyn.cases.simulation import simulate

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

REAL = Path(os.environ.get("ADCPDYN_REAL_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"))
ORIGIN = "2024-05-01T12:00:00.250000Z"

# The CF standard names the export uses, with their canonical units (CF standard name table, version 93).
CF_STANDARD_NAMES = {
    "time": None,  # a reference time: "<unit> since <date>"
    "depth": "m",
    "latitude": "degrees_north",
    "longitude": "degrees_east",
    "eastward_sea_water_velocity": "m s-1",
    "northward_sea_water_velocity": "m s-1",
    "upward_sea_water_velocity": "m s-1",
    "radial_velocity_of_scatterers_away_from_instrument": "m s-1",
    "sea_floor_depth_below_sea_surface": "m",
    "platform_speed_wrt_ground": "m s-1",
    "platform_course": "degree",
    "platform_orientation": "degree",
    "platform_pitch_fore_up": "degree",
    "platform_roll_starboard_down": "degree",
    "platform_heave_rate_up": "m s-1",
    "sea_water_speed": "m s-1",
    "sea_water_velocity_to_direction": "degree",
    "number_of_observations": "1",
}
TIME_UNITS = re.compile(r"^seconds since \d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?$")  # UTC (no zone: UDUNITS, CF)


def cf_problems(path) -> list[str]:
    """What in a written file breaks the CF-1.8 rules the export promises (units, time, dims), read raw with h5netcdf."""
    import h5netcdf

    out = []
    with h5netcdf.File(path, "r") as f:
        if "CF-1.8" not in str(f.attrs.get("Conventions")).split(", "):
            out.append(f"Conventions: {f.attrs.get('Conventions')!r}")
        for key in ("title", "history", "source"):
            if not f.attrs.get(key):
                out.append(f"global attribute {key} missing")
        # a DSG's instance dimension (named by an index variable's instance_dimension) has no coordinate variable
        instances = {v.attrs["instance_dimension"] for v in f.variables.values() if "instance_dimension" in v.attrs}
        for dim in f.dimensions:
            if dim not in instances and (dim not in f.variables or f.variables[dim].dimensions != (dim,)):
                out.append(f"dimension {dim}: no coordinate variable")
        containers = {v.attrs[k] for v in f.variables.values() for k in ("platform", "instrument") if k in v.attrs}
        for name, var in f.variables.items():
            a = dict(var.attrs)
            if name in containers or "cf_role" in a or "instance_dimension" in a:  # metadata holders, feature ids and
                # the index of the pings' feature: no physical quantity
                if "long_name" not in a:
                    out.append(f"{name}: no long_name")
                continue
            if "units" not in a or not isinstance(a["units"], str):
                out.append(f"{name}: units missing")
            if "long_name" not in a and "standard_name" not in a:
                out.append(f"{name}: neither long_name nor standard_name")
            std = a.get("standard_name")
            if std is not None:
                if std not in CF_STANDARD_NAMES:
                    out.append(f"{name}: standard_name {std!r} not one checked against the CF table")
                elif CF_STANDARD_NAMES[std] is not None and a.get("units") != CF_STANDARD_NAMES[std]:
                    out.append(f"{name}: units {a.get('units')!r} for {std} (canonical {CF_STANDARD_NAMES[std]})")
            if var.dtype.kind == "f" and name not in f.dimensions:
                fill = a.get("_FillValue")
                if fill is None or not np.isnan(fill):
                    out.append(f"{name}: _FillValue {fill!r}, expected NaN")
            if name in f.dimensions:
                values = var[...]
                if "_FillValue" in a:
                    out.append(f"{name}: a coordinate variable with _FillValue")
                if values.dtype.kind == "f" and not np.all(np.isfinite(values)):
                    out.append(f"{name}: missing values in a coordinate variable")
                if values.size > 1 and not np.all(np.diff(values.astype(float)) > 0):
                    out.append(f"{name}: coordinate not strictly increasing")
            for k, v in a.items():
                if not isinstance(v, (str, bytes, np.ndarray, np.generic, int, float)) and k not in ("DIMENSION_LIST",):
                    out.append(f"{name}.{k}: attribute of type {type(v).__name__}")
        if "time" in f.variables:
            t = f.variables["time"].attrs
            if t.get("standard_name") != "time" or not TIME_UNITS.match(str(t.get("units"))) \
                    or t.get("calendar") not in ("standard", "gregorian") or t.get("axis") != "T":
                out.append(f"time: standard_name {t.get('standard_name')!r}, units {t.get('units')!r}, "
                           f"calendar {t.get('calendar')!r}, axis {t.get('axis')!r}")
        elif "case_time" not in f.dimensions or f.variables["case_time"].attrs.get("units") != "s":
            out.append("without a UTC origin: expected the dimension case_time, its coordinate in s")
        if "depth" in f.variables:
            d = f.variables["depth"].attrs
            if (d.get("axis"), d.get("positive"), d.get("units"), d.get("standard_name")) != ("Z", "down", "m", "depth"):
                out.append(f"depth: axis/positive/units/standard_name {d.get('axis')}, {d.get('positive')}, "
                           f"{d.get('units')}, {d.get('standard_name')}")
    return out


@pytest.fixture(scope="module")
def ocean():
    """deep_ocean (water profile, GNSS reference) for 40 s, noise-free, with a UTC origin."""
    sc = noise_free(get_scenario("deep_ocean"))
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=40.0)), seed=3)
    return case.replace(time_origin_utc=ORIGIN)


def test_read_back_gives_the_same_numbers_in_enu(tmp_path, ocean):
    corr = correct_case(ocean, "asc", None, reference="gnss")
    path = tmp_path / "o.nc"
    write_netcdf(to_xarray(ocean, corr), path)
    assert cf_problems(path) == []
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        N, K = ocean.pings.n, ocean.water.cell_depth_m.size
        assert dict(ds.sizes) == {"time": N, "depth": K, "beam": 4}
        assert ds["water_velocity_east"].dims == ("time", "depth")
        assert ds["water_radial_velocity"].dims == ("beam", "time", "depth")  # CF: T, Z rightmost
        # UTC datetime64 from the case clock
        assert ds["time"].dtype == np.dtype("datetime64[ns]")
        expected = np.datetime64(ORIGIN[:-1], "ns") + np.round(ocean.pings.time_s * 1e9).astype("timedelta64[ns]")
        np.testing.assert_array_equal(ds["time"].values, expected)
        np.testing.assert_array_equal(ds["case_time"].values, ocean.pings.time_s)
        # ENU from NED
        w = corr.water_velocity_m_s
        np.testing.assert_array_equal(ds["water_velocity_east"].values, w[..., 1])
        np.testing.assert_array_equal(ds["water_velocity_north"].values, w[..., 0])
        np.testing.assert_array_equal(ds["water_velocity_up"].values, -w[..., 2])
        rel = corr.water_relative_velocity_m_s
        np.testing.assert_array_equal(ds["water_relative_velocity_up"].values, -rel[..., 2])
        v = corr.vessel_velocity_m_s  # horizontal as CF's speed and course, east = speed sin(course)
        course = np.deg2rad(ds["vessel_course"].values)
        np.testing.assert_allclose(ds["vessel_speed"].values * np.sin(course), v[:, 1], atol=1e-12)
        np.testing.assert_allclose(ds["vessel_speed"].values * np.cos(course), v[:, 0], atol=1e-12)
        np.testing.assert_array_equal(ds["vessel_velocity_up"].values, -v[:, 2])
        np.testing.assert_allclose(ds["vessel_course"].values, np.rad2deg(np.arctan2(v[:, 1], v[:, 0])) % 360, atol=1e-12)
        np.testing.assert_allclose(ds["water_speed"].values, np.hypot(w[..., 0], w[..., 1]), atol=1e-12)
        # simulated case: case beam numbers, radials positive away from the transducer
        np.testing.assert_array_equal(ds["beam"].values, [1, 2, 3, 4])
        np.testing.assert_array_equal(ds["water_radial_velocity"].values, -ocean.water.radial_m_s.transpose(1, 0, 2))
        np.testing.assert_array_equal(ds["bt_radial_velocity"].values, -ocean.pings.bt_radial_m_s.T)
        np.testing.assert_array_equal(ds["depth"].values, ocean.water.cell_depth_m)
        assert ds["water_velocity_north"].attrs["standard_name"] == "northward_sea_water_velocity"
        assert ds.attrs["water_reference"] == "gnss" and ds.attrs["processing_method"] == "asc"


def test_cf_check_finds_what_it_checks(tmp_path, ocean):
    """The CF check is not vacuous: a file with a wrong unit, a fill value on a coordinate and no Conventions fails."""
    ds = to_xarray(ocean, correct_case(ocean, "asc", None))
    ds["water_velocity_east"].attrs["units"] = "cm/s"
    del ds.attrs["Conventions"]
    ds["depth"].encoding["_FillValue"] = -1.0
    path = tmp_path / "bad.nc"
    write_netcdf(ds, path)
    problems = " | ".join(cf_problems(path))
    assert "Conventions" in problems and "cm/s" in problems and "depth: a coordinate variable with _FillValue" in problems


def test_without_utc_origin_the_pings_are_on_the_case_clock(tmp_path, ocean):
    """No date is invented: no time coordinate (CF's needs a reference date), the case clock's seconds instead."""
    case = ocean.replace(time_origin_utc=None)
    path = tmp_path / "s.nc"
    write_netcdf(to_xarray(case), path)
    assert cf_problems(path) == []
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        assert "time" not in ds.variables and ds["water_radial_velocity"].dims == ("beam", "case_time", "depth")
        np.testing.assert_array_equal(ds["case_time"].values, case.pings.time_s)
        assert ds["case_time"].attrs["units"] == "s" and "not tied to UTC" in ds["case_time"].attrs["long_name"]
        assert ds.attrs["time_origin_utc"].startswith("unknown") and "featureType" not in ds.attrs
        assert "time_coverage_start" not in ds.attrs and ds.attrs["time_coverage_duration"].startswith("PT")


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o077, 0o002])
def test_permissions_follow_the_umask(tmp_path, ocean, mask):
    old = os.umask(mask)
    try:
        write_netcdf(to_xarray(ocean), tmp_path / "p.nc")
    finally:
        os.umask(old)
    assert (tmp_path / "p.nc").stat().st_mode & 0o777 == 0o666 & ~mask


def test_a_failed_write_leaves_nothing(tmp_path, ocean, monkeypatch):
    ds = to_xarray(ocean)
    target = tmp_path / "out.nc"
    target.write_bytes(b"previous")

    def half_then_fail(self, path, **kw):
        Path(path).write_bytes(b"partial netCDF")
        raise OSError("disk full")

    monkeypatch.setattr(type(ds), "to_netcdf", half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_netcdf(ds, target)
    assert target.read_bytes() == b"previous" and sorted(p.name for p in tmp_path.iterdir()) == ["out.nc"]


def test_export_command_from_a_corrected_file_with_provenance(tmp_path, capsys, ocean):
    case_path, corr_path, out = tmp_path / "c.h5", tmp_path / "c_asc.h5", tmp_path / "c.nc"
    write_case(ocean, case_path)
    assert main(["correct", str(case_path), "--out", str(corr_path)]) == 0
    assert main(["export", str(corr_path), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert cf_problems(out) == []
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        a = ds.attrs
        for key in ("Conventions", "history", "adcpdyn_version", "source_case", "source_case_file", "source_case_sha256",
                    "source_corrected_file", "source_corrected_sha256", "processing_method", "calibration_file",
                    "heading_correction", "moving_bed_velocity_north_east_m_s", "corrections_applied", "water_reference",
                    "time_origin_utc"):
            assert key in a, key
        from importlib.metadata import version

        assert a["adcpdyn_version"] == version("adcpdyn") and a["source_case"] == ocean.name
        from adcpdyn.cases.hashing import sha256_of

        assert a["source_case_sha256"] == sha256_of(case_path) and "adcpdyn export" in a["history"]
        assert ds["water_velocity_east"].shape == (ocean.pings.n, ocean.water.cell_depth_m.size)


def test_correct_writes_netcdf_directly(tmp_path, ocean):
    case_path, out = tmp_path / "c.h5", tmp_path / "c.nc"
    write_case(ocean, case_path)
    assert main(["correct", str(case_path), "--method", "asc", "--reference", "gnss", "--out", str(out)]) == 0
    assert cf_problems(out) == []
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.attrs["water_reference"] == "gnss" and "--reference gnss" in ds.attrs["history"]


def test_export_errors_are_one_line(tmp_path, capsys, ocean):
    case_path = tmp_path / "c.h5"
    write_case(ocean, case_path)
    for argv, words in ((["export", str(case_path), "--out", str(tmp_path / "x.h5")], "--out: expected a netCDF"),
                        (["export", str(case_path), "--case", str(case_path), "--out", str(tmp_path / "x.nc")],
                         "--case: only with a corrected file")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1
    corr = tmp_path / "k.h5"
    assert main(["correct", str(case_path), "--out", str(corr)]) == 0
    case_path.unlink()
    assert main(["export", str(corr), "--out", str(tmp_path / "x.nc")]) == 2
    err = capsys.readouterr().err
    assert "--case: the case of" in err and err.count("\n") == 1
    assert not (tmp_path / "x.nc").exists()


def test_real_file_beams_are_the_instruments(tmp_path):
    """RiverPro (beam coordinates): exported radial velocity of TRDI beam j = -(dolfyn's beam j velocity)."""
    src = REAL / "RiverPro_test01.PD0"
    if not src.is_file():
        pytest.skip(f"{src} absent")
    pytest.importorskip("mhkit")
    from adcpdyn.cases.importers import import_file, write_imported
    from adcpdyn.cases.importers.reader import read_dolfyn

    case, attrs = import_file(src)
    case_path = tmp_path / "rp.h5"
    write_imported(case, attrs, case_path, source=src)
    ds = export_file(case_path, tmp_path / "rp.nc")
    assert cf_problems(tmp_path / "rp.nc") == []
    np.testing.assert_array_equal(ds["beam"].values, [1, 2, 3, 4])
    np.testing.assert_array_equal(ds["case_beam"].values, [4, 3, 2, 1])
    raw, _ = read_dolfyn(src)
    K = case.water.cell_depth_m.size
    vel = np.asarray(raw["vel"].values[:4, :K], dtype=np.float64).transpose(0, 2, 1)  # (RDI beam, N, K)
    mine = ds["water_radial_velocity"].values
    ok = np.isfinite(vel) & np.isfinite(mine)
    assert ok.sum() > 5000 and np.max(np.abs(mine[ok] + vel[ok])) < 1e-6
    assert ds.attrs["source_file_sha256"] == "08a09529e588ca9741b079b31fbdb5b66833bdb474aa460ae5dbd50808c4cf9e"
    assert ds["time"].dtype.kind == "M" and str(ds["time"].values[0]).startswith("2022-08-19T20:14")
    assert np.isfinite(ds["latitude"].values).mean() > 0.9


def test_no_netcdf_c_library_is_loaded(tmp_path, ocean):
    """Writing and reading back go through h5netcdf (h5py): the netCDF4 module (netCDF-C) is never imported."""
    import subprocess
    import sys

    case_path = tmp_path / "c.h5"
    write_case(ocean, case_path)
    code = ("import sys; from adcpdyn.cases.netcdf import export_file; import xarray as xr; "
            f"export_file({str(case_path)!r}, {str(tmp_path / 'c.nc')!r}); "
            f"xr.open_dataset({str(tmp_path / 'c.nc')!r}, engine='h5netcdf').load(); print('netCDF4' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
