"""The notebook-style example of docs/api.md and docs/netcdf.md runs on a real file: import, calibrate, correct, export, open."""

from __future__ import annotations

import json
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


@pytest.mark.slow  # 8 s: `make test-slow`, CI's second step
def test_real_file_to_netcdf_example(tmp_path):
    src = REAL / "RiverPro_test01.PD0"
    if not src.is_file():
        pytest.skip(f"{src} absent")
    pytest.importorskip("mhkit")
    xr = pytest.importorskip("xarray")
    import adcpdyn
    from adcpdyn.cases.hashing import sha256_of

    run = subprocess.run([sys.executable, str(SCRIPT), str(src), str(tmp_path)], capture_output=True, text=True,
                         cwd=tmp_path, preexec_fn=lambda: os.umask(0o027))
    assert run.returncode == 0, run.stderr[-2000:]
    out = run.stdout
    assert "imported RiverPro_test01.PD0" in out and "calibrated: converged" in out and "wrote" in out
    assert "median water speed over ground by depth" in out
    nc = tmp_path / "RiverPro_test01_asc.nc"
    case, calib = tmp_path / "RiverPro_test01.h5", tmp_path / "CALIB.json"
    for path in (nc, case, calib):  # the script's umask, not 0600
        assert path.stat().st_mode & 0o777 == 0o640, path.name
    assert cf_problems(nc) == []
    with xr.open_dataset(nc, engine="h5netcdf") as ds:
        a = ds.attrs
        assert a["processing_method"] == "asc" and a["calibration_file"] == str(calib)
        assert a["calibration_sha256"] == sha256_of(calib) and a["source_case_sha256"] == sha256_of(case)
        assert a["source_file_sha256"] == sha256_of(src) and a["adcpdyn_version"] == adcpdyn.__version__
        assert np.isfinite(a["heading_misalignment_deg"]) and np.isfinite(a["magnetic_declination_deg"])
        bed = json.loads(calib.read_text())["moving_bed_velocity_m_s"]  # the calibration's, as applied
        assert a["moving_bed_velocity_north_east_m_s"] == ("none applied" if bed is None else json.dumps(bed))
        speed = np.hypot(ds["water_velocity_east"], ds["water_velocity_north"]).median().item()
        assert 0.5 < speed < 2.5  # the Tanana River runs at about 1.3 m/s here
    prov = json.loads(calib.read_text())["provenance"]
    assert prov["cases"][0]["sha256"] == sha256_of(case) and prov["cases"][0]["source_file_sha256"] == sha256_of(src)
