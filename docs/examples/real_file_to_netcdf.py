"""From a real TRDI file to a CF netCDF file that xarray opens: import, calibrate, correct the
bottom track and the water profile, export, read back.

Run from the repository root (``tests/test_example.py`` runs it too)::

    .venv/bin/python docs/examples/real_file_to_netcdf.py [FILE.PD0] [OUT_DIR]

Defaults: ``../shared/data/real/RiverPro_test01.PD0`` and ``example_out/``. Each ``# %%``
block is one notebook cell.
"""

# %% Inputs
import json
import sys
from pathlib import Path

import numpy as np
import xarray as xr

from adcpdyn.cases.importers import import_file, write_imported
from adcpdyn.cases.io import read_case
from adcpdyn.cases.netcdf import read_provenance, to_xarray, write_netcdf
from adcpdyn.estimators.calibration import CalibrationConfig, calibrate
from adcpdyn.estimators.correct_case import correct_case

ROOT = Path(__file__).resolve().parents[2]
source = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / ".." / "shared" / "data" / "real" / "RiverPro_test01.PD0"
out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("example_out")
out.mkdir(parents=True, exist_ok=True)

# %% 1. Import: bottom track and water profile back in beam coordinates, GNSS, attitude, provenance
case, audit = import_file(source)
case_path = out / f"{case.name}.h5"
write_imported(case, audit, case_path, source=source)
case = read_case(case_path)
print(f"imported {source.name}: {case.pings.n} pings, {case.water.cell_depth_m.size} cells "
      f"({case.water.cell_depth_m[0]:.2f}-{case.water.cell_depth_m[-1]:.2f} m), file frame "
      f"{audit['/provenance']['coordinate_system_found']}, UTC origin {case.time_origin_utc}")

# %% 2. Calibrate (two starts are enough for a look; `adcpdyn calibrate` uses 24)
result = calibrate(case, CalibrationConfig(n_starts=2))  # its warnings are in result.warnings
calib_path = out / "CALIB.json"
result.to_json(calib_path)
calibration = json.loads(calib_path.read_text())
print(f"calibrated: {'converged' if result.success else 'NOT converged'}, heading misalignment "
      f"{np.rad2deg(result.heading_misalignment_rad):+.2f} +- {np.rad2deg(result.heading_misalignment_se_rad):.2f} deg")

# %% 3. Correct bottom track and water: static correction, water referenced to the bottom track
corrected = correct_case(case, "asc", calibration, reference="bt")
corrected.attrs.update(calibration_file=str(calib_path))
v = corrected.vessel_velocity_m_s
print(f"corrected ({corrected.method}): vessel speed {np.nanmedian(np.hypot(v[:, 0], v[:, 1])):.3f} m/s median, "
      f"{int(np.isfinite(corrected.water_velocity_m_s[..., 0]).sum())} water cell velocities")

# %% 4. Export CF-1.8 netCDF (ENU, UTC time, instrument beam numbers)
nc_path = out / f"{case.name}_asc.nc"
write_netcdf(to_xarray(case, corrected, provenance=read_provenance(case_path), source_case_path=case_path,
                       history="docs/examples/real_file_to_netcdf.py"), nc_path)
print(f"wrote {nc_path}")

# %% 5. Open it with xarray
ds = xr.open_dataset(nc_path, engine="h5netcdf")
print(ds)
# cells in the bed's side-lobe layer hold the bed's echo, not water: keep those above
# transducer + (bed - transducer) cos(beam angle), as a hydrographer's processing would
cos_beam = np.cos(np.deg2rad(ds.attrs["instrument_beam_angle_deg"]))
clean = ds.depth < ds.transducer_depth + (ds.sea_floor_depth - ds.transducer_depth) * cos_beam
speed = np.hypot(ds["water_velocity_east"], ds["water_velocity_north"]).where(clean)
profile = speed.median("time")
print(f"time {ds.time.values[0]} .. {ds.time.values[-1]} (UTC), beams {ds.beam.values.tolist()} "
      f"(case beams {ds.case_beam.values.tolist()})")
print("median water speed over ground by depth, above the side-lobe layer (m/s; pings with the cell there):")
for depth, value, n in zip(ds.depth.values, profile.values, speed.count("time").values):
    print(f"  {depth:6.2f} m  {value:.3f}  ({int(n)} pings)")
print(f"method {ds.attrs['processing_method']}, water referenced to {ds.attrs['water_reference']}, "
      f"{ds.attrs['heading_correction']}")
ds.close()
