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
  file holds the case clock's seconds exactly). Without ``time_origin_utc`` the time stays
  in seconds of the case clock and the global attribute ``time_origin_utc`` says so.
- dims ``(time, depth, beam)``: ``depth`` is the cell dimension (its coordinate the cell
  centre's depth below the surface), ``beam`` holds the instrument's own beam numbers
  (TRDI 1-4) in ascending order, with ``case_beam`` the adcpdyn case beam of each.
- Radial velocities follow CF's ``radial_velocity_of_scatterers_away_from_instrument``:
  positive away from the transducer, the opposite of TRDI's (and the case's) convention.
- Missing values are NaN (``_FillValue`` NaN).
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import h5py
import numpy as np

from .case import Case, parse_utc
from .hashing import adcpdyn_version, sha256_of
from .importers.rdi_frames import CASE_FROM_RDI_BEAM

CONVENTIONS = "CF-1.8"
ENGINE = "h5netcdf"
NOT_DETERMINED = "not determined"


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


def _time_coordinate(case: Case) -> tuple[np.ndarray, dict, dict, str]:
    """Values, attributes and encoding of ``time``, and the ``time_origin_utc`` global attribute."""
    t = np.asarray(case.pings.time_s, dtype=np.float64)
    if case.time_origin_utc is None:
        attrs = {"long_name": "transmit time of the ping, seconds from the case clock's zero (UTC origin unknown)",
                 "units": "s", "axis": "T"}
        return t, attrs, {"dtype": "float64", "_FillValue": None}, (
            "unknown: the case has no time_origin_utc (no GNSS tied its clock to UTC); time is in seconds of the case "
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
              history: str | None = None):
    """A case, and optionally a correction of it, as a CF-1.8 :class:`xarray.Dataset`.

    Parameters
    ----------
    case : Case
        The case (recorded radial velocities, attitude, bottom track, reference, profile).
    correction : Correction, optional
        A correction of this case (:func:`~adcpdyn.estimators.correct_case.correct_case`):
        vessel and water velocities in ENU, the method and what it applied as attributes.
    provenance : dict, optional
        The case file's ``/provenance`` (:func:`read_provenance`): instrument beam numbers,
        the instrument file and its SHA-256, copied as ``import_*`` attributes.
    source_case_path : path, optional
        The case file, named with its SHA-256 in the attributes.
    history : str, optional
        What produced the export (a command line), for the ``history`` attribute.

    Returns
    -------
    xarray.Dataset
        dims ``time`` (N), ``depth`` (K, with a profile), ``beam`` (4); see the module docstring.

    Raises
    ------
    ValueError
        The correction does not belong to the case (its times differ).
    """
    import xarray as xr

    provenance = dict(provenance or {})
    N = case.pings.n
    t_values, t_attrs, t_enc, origin_note = _time_coordinate(case)
    beam_no, beam_note = instrument_beams(provenance)
    order = np.argsort(beam_no)  # export in the instrument's ascending beam order
    coords = {
        "time": ("time", t_values, t_attrs),
        "beam": ("beam", beam_no[order].astype(np.int32),
                 {"long_name": "beam number of the instrument", "units": "1", "comment": beam_note}),
        "case_beam": ("beam", (order + 1).astype(np.int32),
                      {"long_name": "adcpdyn case beam number of this beam (case-format.md)", "units": "1"}),
        "case_time": ("time", np.asarray(case.pings.time_s, dtype=np.float64),
                      {"long_name": "transmit time on the case clock", "units": "s"}),
    }
    data = {}
    speed = "m s-1"
    away = "radial_velocity_of_scatterers_away_from_instrument"
    bt = np.asarray(case.pings.bt_radial_m_s, dtype=np.float64)[:, order]
    data["bt_radial_velocity"] = (("time", "beam"), -bt, {
        "standard_name": away, "units": speed,
        "long_name": "radial velocity of the bed along each beam relative to the transducer, positive away from it",
        "comment": "= -(the instrument's bottom-track beam velocity, positive toward the transducer); NaN: rejected"})
    if case.pings.bt_range_m is not None:
        data["bt_slant_range"] = (("time", "beam"), np.asarray(case.pings.bt_range_m, dtype=np.float64)[:, order], {
            "long_name": "slant range along each beam from the transducer to the bed", "units": "m"})
    data["sea_floor_depth"] = (("time",), case.environment.depth_at_pings(N), {
        "standard_name": "sea_floor_depth_below_sea_surface", "units": "m", "positive": "down",
        "long_name": "depth of the bed below the surface under each ping (bottom track)"})
    applied = None if correction is None else correction.provenance
    calibrated = None if applied is None else applied.transducer_depth_calibrated_m
    if calibrated is None:
        data["transducer_depth"] = ((), float(case.environment.transducer_depth_m), {
            "long_name": "depth of the transducer face below the surface when level", "units": "m", "positive": "down"})
    else:  # what the velocities were computed with, and what the instrument was told
        data["transducer_depth"] = ((), float(calibrated), {
            "long_name": "depth of the transducer face below the surface when level, as calibrated from the slant "
                         "ranges (used by the correction)", "units": "m", "positive": "down"})
        entered = applied.transducer_depth_entered_m  # None in files written before it was recorded: the case's
        data["transducer_depth_entered"] = ((), float(case.environment.transducer_depth_m if entered is None else entered), {
            "long_name": "depth of the transducer face below the surface as entered in the instrument or case",
            "units": "m", "positive": "down"})
    if case.water is not None:
        coords["depth"] = ("depth", np.asarray(case.water.cell_depth_m, dtype=np.float64), {
            "standard_name": "depth", "long_name": "depth of the cell centre below the surface", "units": "m",
            "positive": "down", "axis": "Z"})
        w = np.asarray(case.water.radial_m_s, dtype=np.float64)[:, order, :].transpose(0, 2, 1)  # (N, K, 4)
        data["water_radial_velocity"] = (("time", "depth", "beam"), -w, {
            "standard_name": away, "units": speed,
            "long_name": "radial velocity of the water along each beam relative to the transducer, positive away from it",
            "comment": "= -(the instrument's beam velocity, positive toward the transducer); NaN: rejected by the "
                       "instrument or lost"})
    _attitude_variables(case, data)
    _site_variables(case, data, coords)
    attrs = _global_attributes(case, provenance, source_case_path, origin_note, beam_note, history)
    if correction is not None:
        _correction_variables(case, correction, data, attrs)
    ds = xr.Dataset({k: xr.Variable(*v) for k, v in data.items()},
                    coords={k: xr.Variable(*v) for k, v in coords.items()}, attrs=attrs)
    ds["time"].encoding.update(t_enc)
    for name in ds.variables:
        if name != "time" and ds[name].dtype.kind == "f":
            ds[name].encoding["_FillValue"] = None if name in ds.coords and name in ds.dims else np.nan
    return ds


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
        for name, values, word in (("reference_velocity_east", east, "eastward"),
                                   ("reference_velocity_north", north, "northward"),
                                   ("reference_velocity_up", up, "upward")):
            data[name] = (("time",), values, {"long_name": f"{word} velocity over ground of the reference point",
                                              "units": "m s-1", "comment": note})
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
        "Conventions": CONVENTIONS,
        "title": f"ADCP case {case.name} exported by adcpdyn",
        "source": (f"vessel-mounted ADCP: {provenance['instrument']}" if "instrument" in provenance
                   else f"adcpdyn case: {case.description or case.name}"),
        "history": f"{now} adcpdyn {version}: {history or 'to_xarray'}",
        "adcpdyn_version": version,
        "source_case": case.name,
        "time_origin_utc": origin_note,
        "earth_frame": ("ENU: east, north, up (from the case's NED: east = y, north = x, up = -z); north is the "
                        "compass's north unless a heading correction is listed in heading_correction"),
        "beam_numbering": beam_note,
        "radial_velocity_sign": "positive away from the transducer (CF); the instrument's and case's convention is "
                                "positive toward it",
        "featureType_note": "profiles from a moving platform; not written as a CF discrete-sampling geometry",
        "instrument_beam_angle_deg": float(np.rad2deg(case.instrument.beam_angle_rad)),
        "instrument_frequency_hz": float(case.instrument.frequency_hz),
        "instrument_sound_speed_m_s": float(case.instrument.sound_speed_m_s),
        "attitude_sensor_frame": case.attitude.frame,
    }
    if source_case_path is not None:
        attrs["source_case_file"] = str(source_case_path)
        attrs["source_case_sha256"] = sha256_of(source_case_path)
    if "source_file" in provenance:
        attrs["source_file"] = str(provenance["source_file"])
        sha = provenance.get("source_file_sha256")
        if sha is None and Path(str(provenance["source_file"])).is_file():
            sha = sha256_of(provenance["source_file"])
        attrs["source_file_sha256"] = sha if sha is not None else "not available (file not found)"
    for k, v in provenance.items():
        attrs[f"import_{k}"] = _attr(v)
    return attrs


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
    vc = {"units": "m s-1", "comment": f"method {method}, velocity of {point}; north: {north_ref}"}
    for name, values, word in (("vessel_velocity_east", east, "eastward"), ("vessel_velocity_north", north, "northward"),
                               ("vessel_velocity_up", up, "upward")):
        data[name] = (("time",), values, {**vc, "long_name": f"{word} velocity of the vessel {over} from bottom track"})
    data["vessel_speed"] = (("time",), np.hypot(east, north), {
        "standard_name": "platform_speed_wrt_ground", "units": "m s-1",
        "long_name": f"horizontal speed of the vessel {over} from bottom track", "comment": vc["comment"]})
    data["vessel_course"] = (("time",), np.mod(np.rad2deg(np.arctan2(east, north)), 360.0), {
        "standard_name": "platform_course", "units": "degree",
        "long_name": "direction of the vessel's horizontal velocity, clockwise from north", "comment": vc["comment"]})
    data["error_velocity"] = (("time",), np.asarray(correction.error_velocity_m_s, dtype=np.float64), {
        "units": "m s-1", "long_name": "error velocity of the bottom-track solution (NaN with fewer than four beams)"})
    data["beams_used"] = (("time",), np.asarray(correction.beams_used, dtype=np.int8), {
        "units": "1", "long_name": "number of beams in the bottom-track solution"})
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


def export_file(input_path, out, case_path=None, history: str | None = None):
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
    ds = to_xarray(case, correction, provenance=read_provenance(case_path), source_case_path=case_path, history=history)
    if correction is not None:
        ds.attrs["source_corrected_file"] = str(input_path)
        ds.attrs["source_corrected_sha256"] = sha256_of(input_path)
    write_netcdf(ds, out, input_path, case_path)
    return ds
