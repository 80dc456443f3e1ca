"""From a real TRDI file to a CF netCDF file that xarray opens: import, calibrate, correct the
bottom track and the water profile, export, read back.

Run from the repository root (``tests/test_example.py`` runs it too)::

    .venv/bin/python docs/examples/real_file_to_netcdf.py [FILE.PD0] [OUT_DIR]

Defaults: ``../shared/data/real/RiverPro_test01.PD0`` and ``example_out/``. Each ``# %%``
block is one notebook cell.
"""

# %% Inputs
import sys
from pathlib import Path

import numpy as np
import xarray as xr

import adcpdyn

ROOT = Path(__file__).resolve().parents[2]
source = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / ".." / "shared" / "data" / "real" / "RiverPro_test01.PD0"
out = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("example_out")
out.mkdir(parents=True, exist_ok=True)
print(f"adcpdyn {adcpdyn.__version__}")

# %% 1. Import: bottom track and water profile back in beam coordinates, GNSS, attitude, provenance
imported = adcpdyn.import_file(source, out=out / f"{source.stem}.h5")  # also writes the case file
case = imported.case
print(f"imported {source.name}: {case.pings.n} pings, {case.water.cell_depth_m.size} cells "
      f"({case.water.cell_depth_m[0]:.2f}-{case.water.cell_depth_m[-1]:.2f} m), file frame "
      f"{imported.provenance['coordinate_system_found']}, UTC origin {case.time_origin_utc}")

# %% 2. Calibrate (two starts are enough for a look; `adcpdyn calibrate` uses 24)
result = adcpdyn.calibrate(imported, n_starts=2)  # a list of cases calibrates them jointly
calib_path = out / "CALIB.json"
result.to_json(calib_path)  # schema 2, with provenance: adcpdyn version, the case and its SHA-256
print(f"calibrated: {'converged' if result.success else 'NOT converged'}, heading misalignment "
      f"{np.rad2deg(result.heading_misalignment_rad):+.2f} +- {np.rad2deg(result.heading_misalignment_se_rad):.2f} deg")
calibration = adcpdyn.read_calibration(calib_path)  # typed: CalibrationRecord (CalibrationResult.from_json)
print(f"CALIB.json: schema {calibration.schema_version}, sensor frame {calibration.attitude_frame}, "
      f"moving bed {calibration.moving_bed}")

# %% 3. Correct bottom track and water: static correction, water referenced to the bottom track
# (the calibration may be the file, the record or the result in memory: the same numbers)
corrected = adcpdyn.correct(imported, "asc", calib_path, reference="bt")
v = corrected.vessel_velocity_m_s
print(f"corrected ({corrected.method}): vessel speed {np.nanmedian(np.hypot(v[:, 0], v[:, 1])):.3f} m/s median, "
      f"{int(np.isfinite(corrected.water_velocity_m_s[..., 0]).sum())} water cell velocities")

# %% 4. Export CF-1.8 / ACDD-1.3 / IOOS-1.2 netCDF (ENU, UTC time, instrument beam numbers, provenance)
nc_path = adcpdyn.export(imported, out / f"{case.name}_asc.nc", corrected,
                         history="docs/examples/real_file_to_netcdf.py")
print(f"wrote {nc_path}")

# %% 5. Open it with xarray
ds = xr.open_dataset(nc_path, engine="h5netcdf")
print(ds)
# cells in the bed's side-lobe layer hold the bed's echo, not water: keep those above
# transducer + (bed - transducer) cos(beam angle), as a hydrographer's processing would
cos_beam = np.cos(np.deg2rad(ds.attrs["instrument_beam_angle_deg"]))
transducer = ds["adcp"].attrs["transducer_depth_m"]  # the instrument's container variable
clean = ds.depth < transducer + (ds.sea_floor_depth - transducer) * cos_beam
speed = ds["water_speed"].where(clean)
profile = speed.median("time")
print(f"time {ds.time.values[0]} .. {ds.time.values[-1]} (UTC), beams {ds.beam.values.tolist()} "
      f"(case beams {ds.case_beam.values.tolist()})")
print("median water speed over ground by depth, above the side-lobe layer (m/s; pings with the cell there):")
for depth, value, n in zip(ds.depth.values, profile.values, speed.count("time").values):
    print(f"  {depth:6.2f} m  {value:.3f}  ({int(n)} pings)")
print(f"method {ds.attrs['processing_method']}, water referenced to {ds.attrs['water_reference']}, "
      f"{ds.attrs['heading_correction']}")
print(f"provenance: adcpdyn {ds.attrs['adcpdyn_version']}, case {ds.attrs['source_case']} "
      f"(sha256 {ds.attrs['source_case_sha256'][:12]}...), calibration {ds.attrs['calibration_file']}, "
      f"instrument file sha256 {ds.attrs['source_file_sha256'][:12]}...")
ds.close()
