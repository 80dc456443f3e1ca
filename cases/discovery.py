"""What an exported dataset is, for catalogues and checkers: the CF discrete-sampling geometry, the
ACDD-1.3 global and variable attributes and the IOOS-1.2 platform and instrument variables.

Everything is read from the dataset :func:`~adcpdyn.cases.netcdf.to_xarray` built (extents,
coverage, standard names), from its case (instrument, scenario or instrument file) and from
the user's :class:`~adcpdyn.cases.attribution.Attribution` (people, licence, naming authority).
Nothing is guessed: what is not known is left out or said to be unknown.

The geometry: pings with UTC times and GNSS positions are profiles along one vessel track,
CF ``trajectoryProfile`` (``trajectory`` without a water profile) with one trajectory: its id on an
instance dimension of length 1 (IOOS-1.2 checks that length; CF's single-feature form, a scalar id,
fails it) and each ping indexed to it (``trajectory_index``, CF's indexed ragged array, H.4.4 and
H.6.3, with every profile on the one trajectory); without dates or
positions the file is no discrete-sampling geometry (CF needs time, latitude and longitude of
every feature) and has no ``featureType``.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import re
from pathlib import Path

import numpy as np

from .attribution import Attribution

CONVENTIONS = "CF-1.8, ACDD-1.3, IOOS-1.2"
STANDARD_NAME_TABLE = "CF Standard Name Table v93"  # the table the export's names were checked against
STANDARD_NAME_URL = "https://cfconventions.org/Data/cf-standard-names/93/build/cf-standard-name-table.html#{}"
PAPER = ("Sun Z., Yao S., Gao N., Zhang K. (2024) An ADCP attitude dynamic errors correction method based on angular "
         "velocity tensor and radius vector estimation. J. Mar. Sci. Eng. 12, 2018")
METHOD_REFERENCE = PAPER + " (the corrections adcpdyn implements, static (ASC) and dynamic)"
SIMULATION_REFERENCE = PAPER + " (the echo equations adcpdyn's simulator evaluates: Eqs. 65-70 and 88)"
GCMD_OCEAN_CURRENTS = "EARTH SCIENCE > OCEANS > OCEAN CIRCULATION > OCEAN CURRENTS"
GCMD_ADCP = "ADCP > Acoustic Doppler Current Profiler"  # GCMD instrument keyword (under Acoustic Sounders)
# the platform category of a vessel-mounted ADCP when the attribution states none: IOOS's "ship" (= SeaVoX L06 30,
# a surface vessel; the vocabulary IOOS-1.2 recommends); the files do not record the vessel's size
PLATFORM_CATEGORY, PLATFORM_VOCABULARY = "ship", "https://mmisw.org/ont/ioos/platform"
VESSEL, ADCP = "vessel", "adcp"  # the IOOS platform and instrument container variables
TRAJECTORY = "trajectory"  # the instance dimension of the one vessel track (length 1)
NOT_DETERMINED = "not determined"
# ISO 19115-1 coverage content types of the data variables that are not measurements
QUALITY = ("error_velocity", "beams_used")
# recording quanta of TRDI PD0 fields (velocities in mm/s, angles in 0.01 degree, bottom-track range in cm)
TRDI_RESOLUTION = {"bt_radial_velocity": 0.001, "water_radial_velocity": 0.001, "bt_slant_range": 0.01,
                   "heading": 0.01, "pitch": 0.01, "roll": 0.01}
FROM_ADCP = ("bt_radial_velocity", "bt_slant_range", "water_radial_velocity", "sea_floor_depth", "vessel_", "water_",
             "error_velocity", "beams_used")


def feature_type(ds) -> str | None:
    """``trajectoryProfile``, ``trajectory`` or None (see the module docstring)."""
    if "time" not in ds.coords or "latitude" not in ds.coords or not np.isfinite(ds["latitude"].values).any():
        return None
    return "trajectoryProfile" if "depth" in ds.dims else "trajectory"


def describe(ds, case, provenance: dict, attribution: Attribution | None = None):
    """``ds`` with its geometry, platform variable and discovery attributes (its variables' attributes are
    completed in place)."""
    import xarray as xr

    attribution = attribution or Attribution()
    feature = feature_type(ds)
    sensor = _instrument_label(case)
    attrs = {"long_name": "the vessel carrying the ADCP (the IOOS platform)",
             "comment": "value: the case's name" + ("; the trajectory's id" if feature else "")}
    if feature:  # one trajectory, on an instance dimension of its own (IOOS-1.2 asks for its length, 1)
        attrs["cf_role"] = "trajectory_id"
        ds = ds.assign({VESSEL: xr.Variable((TRAJECTORY,), np.array([case.name], dtype=object), attrs),
                        "trajectory_index": xr.Variable("time", np.zeros(ds.sizes["time"], dtype=np.int32), {
                            "instance_dimension": TRAJECTORY,
                            "long_name": "the trajectory each ping (profile) belongs to: the one vessel track"})})
    else:
        ds = ds.assign({VESSEL: xr.Variable((), case.name, attrs)})
    if feature == "trajectoryProfile":
        ds = ds.assign_coords(profile=("time", np.arange(ds.sizes["time"], dtype=np.int32), {
            "cf_role": "profile_id", "long_name": "profile (ping) number in this file, from 0"}))
    _variable_attributes(ds, case, provenance)
    ds.attrs.update(_global_attributes(ds, case, provenance, attribution, feature, sensor))
    return ds


def _instrument_label(case) -> str:
    from .identity import identity_of

    return identity_of(case).label()


# ----------------------------------------------------------------------------------------------- variables
def _variable_attributes(ds, case, provenance: dict) -> None:
    trdi = provenance.get("vendor") == "TRDI"
    internal_attitude = case.attitude.frame == "transducer"
    for name, var in ds.variables.items():
        if name in (VESSEL, ADCP):
            continue
        if name == "trajectory_index":
            var.attrs["coverage_content_type"] = "referenceInformation"
            continue
        if name in ds.coords:
            var.attrs["coverage_content_type"] = "coordinate"
            continue
        var.attrs["coverage_content_type"] = "qualityInformation" if name in QUALITY else "physicalMeasurement"
        var.attrs["platform"] = VESSEL
        from_adcp = name.startswith(FROM_ADCP) or (name in ("heading", "pitch", "roll") and internal_attitude)
        if from_adcp:
            var.attrs["instrument"] = ADCP
        std = var.attrs.get("standard_name")
        if std:
            var.attrs["standard_name_url"] = STANDARD_NAME_URL.format(std.split()[0])
        resolution = TRDI_RESOLUTION.get(name) if trdi else None
        if name in ("heading", "pitch", "roll") and not internal_attitude:
            resolution = None  # an external sensor's: not in the instrument file
        var.attrs["resolution"] = NOT_DETERMINED if resolution is None else resolution
        var.attrs["accuracy"] = NOT_DETERMINED
        var.attrs["precision"] = NOT_DETERMINED
        if "_FillValue" in var.encoding:  # CF's legacy twin, for readers that look for it
            var.encoding["missing_value"] = var.encoding["_FillValue"]


# ----------------------------------------------------------------------------------------------- globals
def _global_attributes(ds, case, provenance, attribution: Attribution, feature, sensor: str) -> dict:
    now = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    method = ds.attrs.get("processing_method")
    out = {
        "Conventions": CONVENTIONS,
        "title": _title(ds, case, sensor, method),
        "summary": _summary(ds, case, provenance, sensor, method),
        "keywords": ", ".join(_keywords(ds)),
        "keywords_vocabulary": "GCMD:GCMD Science Keywords, CF:" + STANDARD_NAME_TABLE,
        "standard_name_vocabulary": STANDARD_NAME_TABLE,
        "id": _identifier(ds, case),
        "date_created": now,
        "product_version": ds.attrs.get("adcpdyn_version", ""),
        "processing_level": (f"corrected by adcpdyn (method {method}): vessel and water velocities in ENU" if method
                             else "instrument records in SI units, radial velocities per beam; not corrected"),
        "instrument": GCMD_ADCP,
        "instrument_vocabulary": "GCMD Instrument Keywords",
        "platform": PLATFORM_CATEGORY,
        "platform_vocabulary": PLATFORM_VOCABULARY,
        "platform_name": f"vessel carrying the {sensor}",
        "comment": ("velocities in ENU (east, north, up); radial velocities positive away from the transducer; "
                    "accuracy and precision not determined: the instrument's specification is not in its file. "
                    "See earth_frame, beam_numbering, time_origin_utc."
                    + ("" if attribution.platform else
                       f" platform: IOOS's category {PLATFORM_CATEGORY!r} for the vessel carrying the ADCP (its size "
                       "is not recorded; an attribution file states another category)")),
    }
    if feature:
        out["featureType"] = feature
    else:
        out["featureType_note"] = ("not a CF discrete-sampling geometry: the pings have no "
                                   + ("UTC dates" if "time" not in ds.coords else "GNSS positions")
                                   + " (CF needs time, latitude and longitude of every feature)")
    out.update(_time_coverage(ds))
    out.update(_geospatial(ds))
    stated = attribution.global_attributes()
    references = [x for x in (stated.get("references"), *_references(case, provenance, method)) if x]
    if references:
        stated["references"] = ", ".join(references)
    out.update(stated)
    return out


def _references(case, provenance, method) -> list[str]:
    """What describes how the data were made: the paper of the correction (or of the simulator's equations) and
    the reader that decoded the instrument file."""
    out = [METHOD_REFERENCE] if method else [SIMULATION_REFERENCE] if case.truth is not None else []
    if "reader" in provenance:
        out.append(f"instrument file decoded by {provenance['reader']} (the reader of adcpdyn's importer)")
    return out


def _title(ds, case, sensor: str, method) -> str:
    when = f" on {str(ds['time'].values[0])[:10]}" if "time" in ds.coords else " (case clock, no UTC dates)"
    what = f"ADCP velocities corrected by adcpdyn ({method})" if method else "ADCP record"
    return f"{case.name}: {what} from the {sensor}{when}"


def _summary(ds, case, provenance, sensor: str, method) -> str:
    n = ds["case_time"].size
    span = float(ds["case_time"].values[-1] - ds["case_time"].values[0]) if n else 0.0
    parts = [f"Vessel-mounted ADCP ({sensor}), case {case.name}: {n} pings over {span:.1f} s"]
    if "time" in ds.coords:
        parts.append(f"from {_iso(ds['time'].values[0])} UTC")
    parts.append("bottom-track radial velocities per beam, bed depth, heading, pitch and roll")
    if "depth" in ds.dims:
        d = ds["depth"].values
        parts.append(f"water profile of {d.size} cells from {d.min():.2f} to {d.max():.2f} m depth")
    if "latitude" in ds.coords:
        parts.append("GNSS positions")
    if any(k.startswith("reference_velocity") for k in ds.data_vars):
        parts.append("GNSS reference velocity")
    origin = (f"imported from the instrument file {Path(str(provenance['source_file'])).name} (SHA-256 "
              f"{provenance.get('source_file_sha256', 'not recorded')})" if "source_file" in provenance else
              "simulated by adcpdyn" if case.truth is not None else "from an adcpdyn case file")
    text = "; ".join(parts) + f". {origin[0].upper()}{origin[1:]}."
    if method:
        text += (f" Corrected by adcpdyn for the vessel's motion (method {method}): vessel velocity over the bed "
                 "from the bottom track and water velocities in east, north, up.")
    return text


def _keywords(ds) -> list[str]:
    names = sorted({v.attrs["standard_name"].split()[0] for v in ds.variables.values() if "standard_name" in v.attrs})
    out = ["GCMD:" + GCMD_OCEAN_CURRENTS] if "eastward_sea_water_velocity" in names else []
    return out + [f"CF:{n}" for n in names] + ["ADCP", "acoustic Doppler current profiler", "bottom track"]


def _identifier(ds, case) -> str:
    """``adcpdyn-NAME-DIGEST``: DIGEST the first 16 hex digits of the SHA-256 of the data values (the
    same data, the same id; no blanks)."""
    h = hashlib.sha256()
    for name in sorted(ds.data_vars):
        values = ds[name].values
        if values.dtype.kind in "fiu":
            h.update(name.encode())
            h.update(np.ascontiguousarray(values).tobytes())
    return f"adcpdyn-{re.sub(r'[^A-Za-z0-9_.-]', '_', case.name)}-{h.hexdigest()[:16]}"


def _iso(t64) -> str:
    return np.datetime_as_string(np.datetime64(t64, "us"), unit="us") + "Z"


def _iso_duration(seconds: float) -> str:
    return f"PT{seconds:.3f}S".replace(".000S", "S")


def _time_coverage(ds) -> dict:
    case_t = ds["case_time"].values
    out = {}
    if case_t.size > 1:
        out["time_coverage_duration"] = _iso_duration(float(case_t[-1] - case_t[0]))
        out["time_coverage_resolution"] = _iso_duration(float(np.median(np.diff(case_t))))
    if "time" in ds.coords:
        t = ds["time"].values
        out["time_coverage_start"], out["time_coverage_end"] = _iso(t.min()), _iso(t.max())
    return out


def _geospatial(ds) -> dict:
    out = {}
    if "latitude" in ds.coords:
        lat, lon = ds["latitude"].values, ds["longitude"].values
        ok = np.isfinite(lat) & np.isfinite(lon)
        if ok.any():
            s, n, w, e = float(lat[ok].min()), float(lat[ok].max()), float(lon[ok].min()), float(lon[ok].max())
            out.update(geospatial_lat_min=s, geospatial_lat_max=n, geospatial_lat_units="degrees_north",
                       geospatial_lon_min=w, geospatial_lon_max=e, geospatial_lon_units="degrees_east",
                       geospatial_bounds_crs="EPSG:4326",  # WGS 84, latitude first
                       geospatial_bounds=(f"POLYGON (({s} {w}, {n} {w}, {n} {e}, {s} {e}, {s} {w}))"
                                          if s < n and w < e else f"POINT ({s} {w})"))
    if "depth" in ds.coords:
        lo, hi = float(ds["depth"].values.min()), float(ds["depth"].values.max())
    else:  # bottom track only: from the transducer to the deepest bed
        bed = ds["sea_floor_depth"].values
        lo, hi = ds[ADCP].attrs["transducer_depth_m"], float(np.nanmax(bed)) if np.isfinite(bed).any() else np.nan
    if np.isfinite(lo) and np.isfinite(hi):
        out.update(geospatial_vertical_min=lo, geospatial_vertical_max=hi, geospatial_vertical_units="m",
                   geospatial_vertical_positive="down",
                   geospatial_bounds_vertical_crs="EPSG:5831")  # instantaneous water level depth
    return out
