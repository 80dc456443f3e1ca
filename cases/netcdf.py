"""CF-1.8 netCDF / xarray export of cases and corrected results.

:func:`to_xarray` turns a case (and optionally a correction of it) into an
:class:`xarray.Dataset`; :func:`write_netcdf` writes one with xarray's ``h5netcdf``
engine (HDF5 through h5py, no netCDF-C library) through the atomic writer, with the
permissions the process umask gives a new file; :func:`export_file` does both from the
files ``adcpdyn`` writes (``adcpdyn export``, ``adcpdyn correct --out X.nc``).

Conventions of the exported file:

- Earth vectors in ENU (east, north, up), converted from the case's NED
  (east = y, north = x, up = -z); depths positive down.
- ``time``: UTC ``datetime64`` of each ping's transmit time, from the case's own clock
  (``time_origin_utc`` + ``/pings/time_s``; encoded as seconds since that origin, so the
  file holds the case clock's seconds exactly); ``case_time``, the seconds on the case
  clock, beside it. Without ``time_origin_utc`` (a simulated case, a clock never tied to
  UTC) there is no date to give, so no ``time`` variable (a CF time coordinate needs a
  reference date, and inventing one would pass the clock's zero off as a date): the pings'
  dimension is ``case_time``, its coordinate the case clock's seconds (units ``s``), and the
  global attribute ``time_origin_utc`` says so.
- dims ``(beam, time, depth)``, the order CF recommends (T, Z, Y, X rightmost, other
  dimensions to their left; ``case_time`` for ``time`` without dates): ``depth`` is the cell dimension (its coordinate the cell
  centre's depth below the surface), ``beam`` holds the instrument's own beam numbers
  (TRDI 1-4) in ascending order, with ``case_beam`` the adcpdyn case beam of each.
- CF standard names wherever CF has one: the vessel's horizontal velocity as
  ``vessel_speed`` and ``vessel_course`` (east = speed sin(course), north = speed
  cos(course)), its vertical as ``vessel_velocity_up`` (``platform_heave_rate_up``), the
  GNSS reference's likewise, the water's also as ``water_speed`` and ``water_direction``.
- ``adcp``: the instrument as a container variable (IOOS-1.2): make and model, serial
  number, frequency, beam angle, transducer depth (calibrated and entered).
- Discovery: ACDD-1.3 and IOOS-1.2 attributes and the CF discrete-sampling geometry
  (:mod:`adcpdyn.cases.discovery`), the people and terms from the user's
  :class:`~adcpdyn.cases.attribution.Attribution`.
- Provenance: files named by absolute path and SHA-256.
- Radial velocities follow CF's ``radial_velocity_of_scatterers_away_from_instrument``:
  positive away from the transducer, the opposite of TRDI's (and the case's) convention.
- Missing values are NaN (``_FillValue`` NaN); ``beams_used`` (int8) declares netCDF's byte fill, -127,
  which it never holds (xarray then reads it as floats; ``mask_and_scale=False`` keeps the integers).
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import h5py
import numpy as np

from .attribution import AttributionFile, as_attribution
from .case import Case, parse_utc
from .discovery import ADCP, NOT_DETERMINED, describe
from .hashing import adcpdyn_version, sha256_of
from .importers.rdi_frames import CASE_FROM_RDI_BEAM

ENGINE = "h5netcdf"
BEAMS_USED_FILL = np.int8(-127)  # netCDF's default fill of a byte variable: outside the counts 0-4


# ----------------------------------------------------------------------------------------------- helpers
def read_provenance(path) -> dict:
    """The ``/provenance`` attributes of a case file (an imported one), as Python values; {} when absent."""
    out = {}
    with h5py.File(path, "r") as f:
        if "provenance" not in f:
            return out
        for k, v in f["provenance"].attrs.items():
            if isinstance(v, bytes):
                v = v.decode("utf-8", "replace")
            elif isinstance(v, np.generic):
                v = v.item()
            elif isinstance(v, np.ndarray):
                v = v.tolist()
            out[k] = v
    return out


def instrument_beams(provenance: dict | None) -> tuple[np.ndarray, str]:
    """The instrument's number of case beams 1-4 and how it was found.

    TRDI files imported by adcpdyn: case beams 1, 2, 3, 4 are RDI beams 4, 3, 2, 1 (the
    importer's ``beam_mapping``). Anything else (simulated cases): the case's numbers.
    """
    if (provenance or {}).get("vendor") == "TRDI":
        return np.array(CASE_FROM_RDI_BEAM) + 1, ("TRDI beam numbers: case beams 1,2,3,4 = RDI beams 4,3,2,1 "
                                                  "(the importer's beam_mapping)")
    return np.arange(1, 5), "adcpdyn case beam numbers (no instrument numbering recorded: simulated or unknown)"


def _enu(ned: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(east, north, up) of NED vectors along the last axis."""
    ned = np.asarray(ned, dtype=np.float64)
    return ned[..., 1], ned[..., 0], -ned[..., 2]


def _time_coordinate(case: Case) -> tuple[np.ndarray | None, dict, dict, str]:
    """Values, attributes and encoding of ``time`` (None without a UTC origin), and the
    ``time_origin_utc`` global attribute."""
    t = np.asarray(case.pings.time_s, dtype=np.float64)
    if case.time_origin_utc is None:
        return None, {}, {}, ("unknown: the case has no time_origin_utc (no GNSS tied its clock to UTC); the pings "
                              "have no dates: no time variable, their dimension is case_time, seconds on the case "
                              "clock")
    origin = parse_utc(case.time_origin_utc).replace(tzinfo=None)
    origin64 = np.datetime64(origin, "ns")
    values = origin64 + np.round(t * 1e9).astype("timedelta64[ns]")
    iso = origin.strftime("%Y-%m-%dT%H:%M:%S.%f")
    attrs = {"standard_name": "time", "long_name": "transmit time of the ping (UTC)", "axis": "T"}
    encoding = {"units": f"seconds since {iso}", "calendar": "standard", "dtype": "float64", "_FillValue": None}
    return values, attrs, encoding, case.time_origin_utc


# ----------------------------------------------------------------------------------------------- dataset
def to_xarray(case: Case, correction=None, *, provenance: dict | None = None, source_case_path=None,
              history: str | None = None, attribution=None):
    """A case, and optionally a correction of it, as a CF-1.8 :class:`xarray.Dataset`.

    Parameters
    ----------
    case : Case
        The case (recorded radial velocities, attitude, bottom track, reference, profile).
    correction : Correction, optional
        A correction of this case (:func:`~adcpdyn.estimators.correction.correct_case.correct_case`):
        vessel and water velocities in ENU, the method and what it applied as attributes.
    provenance : dict, optional
        The case file's ``/provenance`` (:func:`read_provenance`): instrument beam numbers,
        the instrument file and its SHA-256, copied as ``import_*`` attributes.
    source_case_path : path, optional
        The case file, named with its SHA-256 in the attributes.
    history : str, optional
        What produced the export (a command line), for the ``history`` attribute.
    attribution : Attribution or path, optional
        Who made and distributes the data, their licence and naming authority (an
        :class:`~adcpdyn.cases.attribution.Attribution` or its TOML file, named with its SHA-256 in the
        attributes); without it the file named by ``ADCPDYN_ATTRIBUTION`` when set, else ``not stated``.

    Returns
    -------
    xarray.Dataset
        dims ``beam`` (4), ``time`` (N; ``case_time`` without dates), ``depth`` (K, with a profile); see
        the module docstring.

    Raises
    ------
    ValueError
        The correction does not belong to the case (its times differ).
    """
    import xarray as xr

    provenance = dict(provenance or {})
    stated = as_attribution(attribution)  # a bad file fails before the work
    N = case.pings.n
    t_values, t_attrs, t_enc, origin_note = _time_coordinate(case)
    beam_no, beam_note = instrument_beams(provenance)
    order = np.argsort(beam_no)  # export in the instrument's ascending beam order
    coords = {
        "beam": ("beam", beam_no[order].astype(np.int32),
                 {"long_name": "beam number of the instrument", "units": "1", "comment": beam_note}),
        "case_beam": ("beam", (order + 1).astype(np.int32),
                      {"long_name": "adcpdyn case beam number of this beam (case-format.md)", "units": "1"}),
        "case_time": ("time", np.asarray(case.pings.time_s, dtype=np.float64),
                      {"long_name": "transmit time of the ping on the case clock, seconds from its zero"
                                    + ("" if t_values is not None else " (the clock is not tied to UTC: no dates)"),
                       "units": "s"}),
    }
    if t_values is not None:
        coords["time"] = ("time", t_values, t_attrs)
    data = {}
    speed = "m s-1"
    away = "radial_velocity_of_scatterers_away_from_instrument"
    bt = np.asarray(case.pings.bt_radial_m_s, dtype=np.float64)[:, order].T  # (beam, time)
    data["bt_radial_velocity"] = (("beam", "time"), -bt, {
        "standard_name": away, "units": speed,
        "long_name": "radial velocity of the bed along each beam relative to the transducer, positive away from it",
        "comment": "= -(the instrument's bottom-track beam velocity, positive toward the transducer); NaN: rejected"})
    if case.pings.bt_range_m is not None:
        data["bt_slant_range"] = (("beam", "time"), np.asarray(case.pings.bt_range_m, dtype=np.float64)[:, order].T, {
            "long_name": "slant range along each beam from the transducer to the bed", "units": "m"})
    data["sea_floor_depth"] = (("time",), case.environment.depth_at_pings(N), {
        "standard_name": "sea_floor_depth_below_sea_surface", "units": "m", "positive": "down",
        "long_name": "depth of the bed below the surface under each ping (bottom track)"})
    applied = None if correction is None else correction.provenance
    calibrated = None if applied is None else applied.transducer_depth_calibrated_m
    entered = None if applied is None else applied.transducer_depth_entered_m  # None in files written before it was
    written = ((applied.calibration_provenance or {}).get("written_utc") if applied is not None else None)
    calibrated_by = None if applied is None or applied.calibration_file == "none" else applied.calibration_file
    data[ADCP] = _instrument_variable(case, calibrated, entered, written, calibrated_by)  # recorded: the case's
    if case.water is not None:
        coords["depth"] = ("depth", np.asarray(case.water.cell_depth_m, dtype=np.float64), {
            "standard_name": "depth", "long_name": "depth of the cell centre below the surface", "units": "m",
            "positive": "down", "axis": "Z"})
        w = np.asarray(case.water.radial_m_s, dtype=np.float64)[:, order, :].transpose(1, 0, 2)  # (4, N, K)
        data["water_radial_velocity"] = (("beam", "time", "depth"), -w, {
            "standard_name": away, "units": speed,
            "long_name": "radial velocity of the water along each beam relative to the transducer, positive away from it",
            "comment": "= -(the instrument's beam velocity, positive toward the transducer); NaN: rejected by the "
                       "instrument or lost"})
    _attitude_variables(case, data)
    _site_variables(case, data, coords)
    attrs = _global_attributes(case, provenance, source_case_path, origin_note, beam_note, history)
    if isinstance(stated, AttributionFile):
        attrs.update(stated.provenance_attributes())
        stated = stated.attribution
    if correction is not None:
        _correction_variables(case, correction, data, attrs)
        _absolute_paths(attrs)
    ds = xr.Dataset({k: xr.Variable(*v) for k, v in data.items()},
                    coords={k: xr.Variable(*v) for k, v in coords.items()}, attrs=attrs)
    if t_values is not None:
        ds["time"].encoding.update(t_enc)
    else:  # no dates: the case clock's seconds are the pings' coordinate
        ds = ds.swap_dims({"time": "case_time"})
    for name in ds.variables:
        if name in ds.dims:  # coordinate variables hold no missing values
            ds[name].encoding["_FillValue"] = None
        elif ds[name].dtype.kind == "f":
            ds[name].encoding["_FillValue"] = np.nan
        elif name == "beams_used":  # never written (every ping has a count, 0-4); xarray reads it as floats
            ds[name].encoding["_FillValue"] = BEAMS_USED_FILL
    return describe(ds, case, provenance, stated)


def _instrument_variable(case: Case, calibrated_depth_m, entered_depth_m=None, calibration_utc=None,
                         calibration_file=None) -> tuple:
    """The ADCP as a container variable (IOOS-1.2): what it is and how deep its transducer sat (as calibrated
    and used by a correction, and as entered; the case's when the entered depth is not recorded), and when the
    calibration a correction applied was made (``calibration_utc``, its CALIB.json's ``written_utc``); without
    that date no ``calibration_date`` (none is invented), a comment saying why."""
    ins = case.instrument
    entered = float(case.environment.transducer_depth_m if entered_depth_m is None else entered_depth_m)
    attrs = {"long_name": "the ADCP (a container variable: its value means nothing)",
             "make_model": " ".join(x for x in (ins.make, ins.model) if x) or "not recorded",
             "serial_number": ins.serial_number or "not recorded", "frequency_hz": float(ins.frequency_hz),
             "beam_angle_deg": float(np.rad2deg(ins.beam_angle_rad)), "beams": int(ins.n_beams),
             "transducer_depth_m": entered if calibrated_depth_m is None else float(calibrated_depth_m),
             "transducer_depth_comment": "depth of the transducer face below the surface when level, positive down"}
    if calibrated_depth_m is not None:  # what the velocities were computed with, and what the instrument was told
        attrs["transducer_depth_comment"] += "; as calibrated from the slant ranges (used by the correction)"
        attrs["transducer_depth_entered_m"] = entered
    if calibration_utc:
        attrs["calibration_date"] = str(calibration_utc)
        attrs["calibration_date_comment"] = ("when the adcpdyn calibration the correction applied (lever arms, installation "
                                             "angles, compass) was computed: its CALIB.json's written_utc")
    else:
        applied = (f"the calibration the correction applied ({calibration_file}) records no written_utc"
                   if calibration_file else "no adcpdyn calibration (CALIB.json) was applied to these data")
        attrs["calibration_date_comment"] = (f"no calibration date: {applied}, and the case holds no date of the "
                                             "instrument's own calibration (adcpdyn reads none from instrument files)")
    return (), np.int32(0), attrs


def _attitude_variables(case: Case, data: dict) -> None:
    """Heading, pitch and roll at the pings (the sensor's samples interpolated, as the static correction uses them)."""
    ypr = np.rad2deg(case.attitude.ypr_at(case.pings.time_s))
    frame = ("the ADCP head (internal sensor)" if case.attitude.frame == "transducer" else "the vessel")
    common = {"units": "degree", "comment": f"attitude sensor of {frame} (the CF platform), samples interpolated "
                                            "linearly to the pings, as recorded: no heading correction"}
    data["heading"] = (("time",), np.mod(ypr[:, 0], 360.0), {
        **common, "standard_name": "platform_orientation",
        "long_name": f"heading of {frame}, clockwise from the north of its compass (magnetic unless corrected)"})
    data["pitch"] = (("time",), ypr[:, 1], {**common, "standard_name": "platform_pitch_fore_up",
                                             "long_name": f"pitch of {frame}, x (bow) up positive"})
    data["roll"] = (("time",), ypr[:, 2], {**common, "standard_name": "platform_roll_starboard_down",
                                            "long_name": f"roll of {frame}, y (starboard) down positive"})


def _site_variables(case: Case, data: dict, coords: dict) -> None:
    """GNSS reference velocity and position at the pings (interpolated, never extrapolated)."""
    t = case.pings.time_s
    ref = case.reference
    if ref is not None and ref.velocity_m_s is not None:
        from .coverage import reference_at

        east, north, up = _enu(reference_at(case, t))
        note = ("reference velocity (GNSS) of the body point (" + ", ".join(f"{x:g}" for x in ref.point_body_m)
                + ") m, interpolated linearly to the pings; NaN beyond one sample interval of the reference's span")
        data["reference_speed"] = (("time",), np.hypot(east, north), {
            "standard_name": "platform_speed_wrt_ground", "units": "m s-1", "comment": note,
            "long_name": "horizontal speed over ground of the reference point"})
        data["reference_course"] = (("time",), np.mod(np.rad2deg(np.arctan2(east, north)), 360.0), {
            "standard_name": "platform_course", "units": "degree",
            "comment": note + "; east = reference_speed sin(course), north = reference_speed cos(course)",
            "long_name": "direction of the reference point's horizontal velocity over ground, clockwise from north"})
        data["reference_velocity_up"] = (("time",), up, {
            "standard_name": "platform_heave_rate_up", "units": "m s-1", "comment": note,
            "long_name": "upward velocity over ground of the reference point"})
    pos = case.position
    if pos is not None:
        inside = (t >= pos.time_s[0]) & (t <= pos.time_s[-1])
        for name, values, std, unit in (("latitude", pos.latitude_deg, "latitude", "degrees_north"),
                                        ("longitude", pos.longitude_deg, "longitude", "degrees_east")):
            v = np.full(t.size, np.nan)
            v[inside] = np.interp(t[inside], pos.time_s, values)
            coords[name] = ("time", v, {"standard_name": std, "units": unit,
                                        "long_name": f"{std} of the GNSS antenna at the ping",
                                        "comment": "fixes interpolated linearly to the pings; NaN outside them"})


def _speed_and_direction(east, north, attrs: dict) -> tuple:
    """CF sea_water_speed and sea_water_velocity_to_direction of the east and north water velocities."""
    dims, e, _ = east
    _, n, _ = north
    speed = (dims, np.hypot(e, n), {**attrs, "standard_name": "sea_water_speed",
                                    "long_name": "horizontal water speed (from water_velocity_east and _north)"})
    direction = (dims, np.mod(np.rad2deg(np.arctan2(e, n)), 360.0), {
        **attrs, "standard_name": "sea_water_velocity_to_direction", "units": "degree",
        "long_name": "direction the water flows toward, clockwise from north (from water_velocity_east and _north)"})
    return speed, direction


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _global_attributes(case, provenance, source_case_path, origin_note, beam_note, history) -> dict:
    version = adcpdyn_version()
    now = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    attrs = {
        "source": (f"vessel-mounted ADCP: {provenance['instrument']}" if "instrument" in provenance
                   else f"adcpdyn case: {case.description or case.name}"),
        "history": f"{now} adcpdyn {version}: {history or 'to_xarray'} (working folder {Path.cwd()})",
        "adcpdyn_version": version,
        "source_case": case.name,
        "time_origin_utc": origin_note,
        "earth_frame": ("ENU: east, north, up (from the case's NED: east = y, north = x, up = -z); north is the "
                        "compass's north unless a heading correction is listed in heading_correction"),
        "beam_numbering": beam_note,
        "radial_velocity_sign": "positive away from the transducer (CF); the instrument's and case's convention is "
                                "positive toward it",
        "instrument_beam_angle_deg": float(np.rad2deg(case.instrument.beam_angle_rad)),
        "instrument_frequency_hz": float(case.instrument.frequency_hz),
        "instrument_sound_speed_m_s": float(case.instrument.sound_speed_m_s),
        "attitude_sensor_frame": case.attitude.frame,
    }
    if source_case_path is not None:
        attrs["source_case_file"] = str(Path(source_case_path).resolve())
        attrs["source_case_sha256"] = sha256_of(source_case_path)
    if "source_file" in provenance:
        attrs["source_file"] = _absolute(provenance["source_file"])
        sha = provenance.get("source_file_sha256")
        if sha is None and Path(str(provenance["source_file"])).is_file():
            sha = sha256_of(provenance["source_file"])
        attrs["source_file_sha256"] = sha if sha is not None else "not available (file not found)"
    for k, v in provenance.items():
        attrs[f"import_{k}"] = _attr(v)
    return attrs


def _absolute(path) -> str:
    """A recorded file path made absolute when it names a file from here; else as recorded (its SHA-256
    beside it identifies the file)."""
    text = str(path)
    return str(Path(text).resolve()) if Path(text).is_file() else text


def _absolute_paths(attrs: dict) -> None:
    """The correction's recorded file paths (attributes and their JSON record) made absolute."""
    for key in ("calibration_file", "source_case_file"):
        if key in attrs:
            attrs[key] = _absolute(attrs[key])
    if "corrections_applied" in attrs:
        record = json.loads(attrs["corrections_applied"])
        for key in ("calibration_file", "source_case_file"):
            if record.get(key):
                record[key] = _absolute(record[key])
        attrs["corrections_applied"] = json.dumps(record)


def _attr(value):
    """A netCDF attribute value: numbers and strings as they are, anything else as JSON."""
    value = _jsonable(value)
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (int, float, str)):
        return value
    return json.dumps(value, default=_jsonable)


def _correction_variables(case, correction, data: dict, attrs: dict) -> None:
    """ENU vessel and water velocities of a correction, and what it applied as attributes."""
    t = np.asarray(correction.time_s, dtype=np.float64)
    if t.shape != case.pings.time_s.shape or np.any(np.abs(t - case.pings.time_s) > 1e-9):
        raise ValueError(f"correction: time_s: expected the case's {case.pings.n} ping times, got {t.size} other times")
    s = correction.provenance
    method = correction.method
    north_ref = ("true north (heading misalignment applied)" if s.heading_misalignment_applied_rad is not None
                 else "the compass's north (no heading correction applied)")
    east, north, up = _enu(correction.vessel_velocity_m_s)
    bed = s.moving_bed_velocity_m_s is not None
    over = "over ground" if bed else "over the bed (taken as fixed)"
    point = "the transducer (static correction: rotation ignored)" if method == "asc" else "the centre of rotation G"
    vc = {"units": "m s-1", "comment": f"method {method}, velocity of {point}; north: {north_ref}",
          "ancillary_variables": "error_velocity beams_used"}
    data["vessel_velocity_up"] = (("time",), up, {**vc, "standard_name": "platform_heave_rate_up",
                                                  "long_name": f"upward velocity of the vessel {over} from bottom track"})
    data["vessel_speed"] = (("time",), np.hypot(east, north), {
        "standard_name": "platform_speed_wrt_ground", "units": "m s-1", "ancillary_variables": vc["ancillary_variables"],
        "long_name": f"horizontal speed of the vessel {over} from bottom track", "comment": vc["comment"]})
    data["vessel_course"] = (("time",), np.mod(np.rad2deg(np.arctan2(east, north)), 360.0), {
        "standard_name": "platform_course", "units": "degree", "ancillary_variables": vc["ancillary_variables"],
        "long_name": "direction of the vessel's horizontal velocity, clockwise from north",
        "comment": vc["comment"] + "; east = vessel_speed sin(course), north = vessel_speed cos(course)"})
    data["error_velocity"] = (("time",), np.asarray(correction.error_velocity_m_s, dtype=np.float64), {
        "units": "m s-1", "long_name": "error velocity of the bottom-track solution (NaN with fewer than four beams)"})
    data["beams_used"] = (("time",), np.asarray(correction.beams_used, dtype=np.int8), {
        "standard_name": "number_of_observations", "units": "1",
        "long_name": "number of beams in the bottom-track solution", "valid_range": np.array([0, 4], dtype=np.int8)})
    if correction.water_velocity_m_s is not None and "depth" in _dims_of(data):
        reference = s.water_reference or "bt"
        note = s.water_reference_note
        wc = {"units": "m s-1", "comment": f"method {method}; {note}; north: {north_ref}"}
        for j, (std, word) in enumerate((("eastward_sea_water_velocity", "east"),
                                         ("northward_sea_water_velocity", "north"),
                                         ("upward_sea_water_velocity", "up"))):
            data[f"water_velocity_{word}"] = (("time", "depth"), _enu(correction.water_velocity_m_s)[j], {
                **wc, "standard_name": std,
                "long_name": f"{std.split('_')[0]} water velocity "
                             + ("over ground (referenced to the GNSS)" if reference == "gnss" else
                                "over ground (referenced to the bottom track and the moving bed)" if bed else
                                "relative to the bed (referenced to the bottom track, the bed taken as fixed)")})
        data["water_speed"], data["water_direction"] = _speed_and_direction(
            data["water_velocity_east"], data["water_velocity_north"], wc)
        rel = getattr(correction, "water_relative_velocity_m_s", None)
        if rel is not None:
            whom = "the transducer" if method == "asc" else "the vessel's centre of rotation"
            for j, word in enumerate(("east", "north", "up")):
                data[f"water_relative_velocity_{word}"] = (("time", "depth"), _enu(rel)[j], {
                    "units": "m s-1", "comment": f"method {method}; not referenced; north: {north_ref}",
                    "long_name": f"{['eastward', 'northward', 'upward'][j]} water velocity relative to {whom}"})
        attrs["water_reference"] = reference
    attrs["processing_method"] = method
    attrs["north_reference"] = north_ref
    attrs["calibration_file"] = str(s.calibration_file)
    if s.calibration_sha256 is not None:
        attrs["calibration_sha256"] = s.calibration_sha256
    heading = s.heading_misalignment_applied_rad
    attrs["heading_correction"] = (s.heading_correction_note or "none recorded" if heading is None else
                                   f"heading misalignment {np.rad2deg(heading):+.4f} deg applied to the recorded "
                                   "headings (holds the magnetic declination)")
    attrs["heading_misalignment_deg"] = NOT_DETERMINED if heading is None else float(np.rad2deg(heading))
    decl = s.magnetic_declination_rad
    attrs["magnetic_declination_deg"] = NOT_DETERMINED if decl is None else float(np.rad2deg(decl))
    bed = s.moving_bed_velocity_m_s
    attrs["moving_bed_velocity_north_east_m_s"] = "none applied" if bed is None else json.dumps(list(bed))
    attrs["corrections_applied"] = json.dumps(s.to_settings(), default=_jsonable)


def _dims_of(data: dict) -> set:
    return {d for v in data.values() for d in v[0]}


# ----------------------------------------------------------------------------------------------- writing
def write_netcdf(dataset, path, *inputs) -> None:
    """Write a dataset as netCDF-4 with the ``h5netcdf`` engine, atomically.

    The file appears complete or not at all (temporary file beside it, then renamed),
    with the permissions the process umask gives a new file (``0o666 & ~umask``).
    An output path that names one of ``inputs`` is refused.

    Raises
    ------
    ValueError
        ``path`` is one of the inputs.
    """
    from .atomic import atomic_path, refuse_overwrite_input

    refuse_overwrite_input(path, *inputs)
    with atomic_path(path) as tmp:  # the atomic writer gives the umask's permissions
        dataset.to_netcdf(tmp, engine=ENGINE)


def correction_from_file(path):
    """A :class:`~adcpdyn.cases.corrected.Correction` and its source case path from a file of ``adcpdyn correct``."""
    from .corrected import Correction, read_correction

    d = read_correction(path)
    with h5py.File(path, "r") as f:
        source = f["corrected"].attrs.get("source_case", "")
    source = source.decode() if isinstance(source, bytes) else str(source)
    corr = Correction(method=str(d["method"]), time_s=d["time_s"], vessel_velocity_m_s=d["vessel_velocity_m_s"],
                      error_velocity_m_s=d["error_velocity_m_s"], beams_used=d["beams_used"],
                      water_velocity_m_s=d.get("water_velocity_m_s"), provenance=d["provenance"],
                      water_relative_velocity_m_s=d.get("water_relative_velocity_m_s"))
    return corr, source


def file_format(path) -> str:
    """``adcp-case`` or ``adcp-corrected`` (the root ``format`` attribute), or a one-line ValueError."""
    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format", "")
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise ValueError(f"{path}: expected an HDF5 case or corrected file, got an unreadable file ({exc})") from exc
    fmt = fmt.decode() if isinstance(fmt, bytes) else str(fmt)
    if fmt not in ("adcp-case", "adcp-corrected"):
        raise ValueError(f"{path}: /.attrs[\"format\"]: expected \"adcp-case\" or \"adcp-corrected\", got {fmt!r}")
    return fmt


def export_file(input_path, out, case_path=None, history: str | None = None, attribution=None):
    """Export a case file, or a corrected file with its case, to CF netCDF ``out``; returns the dataset.

    Parameters
    ----------
    input_path : path
        A case file (``adcp-case``) or a file of ``adcpdyn correct`` (``adcp-corrected``).
    out : path
        The netCDF file to write (atomically; never one of the inputs).
    case_path : path, optional
        A corrected file's case; default its ``source_case`` attribute.
    history : str, optional
        The command line, for ``history``.
    attribution : Attribution or path, optional
        Who made and distributes the data (:func:`to_xarray`).

    Raises
    ------
    ValueError
        One line naming the field: unreadable input, a corrected file whose case cannot be
        found or does not match, an output that is an input.
    """
    from .io import read_case

    correction = None
    if file_format(input_path) == "adcp-corrected":
        correction, source = correction_from_file(input_path)
        case_path = case_path or source
        if not case_path or not Path(case_path).is_file():
            raise ValueError(f"--case: the case of {input_path} is needed (its source_case {source!r} is not a file); "
                             "give it with --case CASE.h5")
    else:
        if case_path is not None:
            raise ValueError(f"--case: only with a corrected file; {input_path} is a case file itself")
        case_path = input_path
    case = read_case(case_path)
    if correction is not None:  # corrected as `correct` did: the pings the attitude record covers
        from .coverage import restrict_to_coverage

        case = restrict_to_coverage(case, source=str(case_path))[0]
    ds = to_xarray(case, correction, provenance=read_provenance(case_path), source_case_path=case_path, history=history,
                   attribution=attribution)
    if correction is not None:
        ds.attrs["source_corrected_file"] = str(Path(input_path).resolve())
        ds.attrs["source_corrected_sha256"] = sha256_of(input_path)
    write_netcdf(ds, out, input_path, case_path)
    return ds
