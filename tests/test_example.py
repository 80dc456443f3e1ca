"""The notebook-style example of the README runs on a real file: import, calibrate, correct, export, open."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_netcdf import cf_problems

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "docs" / "examples" / "real_file_to_netcdf.py"
REAL = Path(os.environ.get("ADCPDYN_REAL_DATA", ROOT / ".." / "shared" / "data" / "real"))


def test_real_file_to_netcdf_example(tmp_path):
    src = REAL / "RiverPro_test01.PD0"
    if not src.is_file():
        pytest.skip(f"{src} absent")
    pytest.importorskip("mhkit")
    xr = pytest.importorskip("xarray")
    run = subprocess.run([sys.executable, str(SCRIPT), str(src), str(tmp_path)], capture_output=True, text=True,
                         cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    out = run.stdout
    assert "imported RiverPro_test01.PD0" in out and "calibrated: converged" in out and "wrote" in out
    assert "median water speed over ground by depth" in out
    nc = tmp_path / "RiverPro_test01_asc.nc"
    assert cf_problems(nc) == []
    with xr.open_dataset(nc, engine="h5netcdf") as ds:
        assert ds.attrs["processing_method"] == "asc" and ds.attrs["calibration_file"].endswith("CALIB.json")
        speed = np.hypot(ds["water_velocity_east"], ds["water_velocity_north"]).median().item()
        assert 0.5 < speed < 2.5  # the Tanana River runs at about 1.3 m/s here
