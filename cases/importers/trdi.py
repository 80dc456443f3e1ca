"""TRDI PD0 (WinRiver, VmDAS, self-contained .000) -> case, through dolfyn.

Bottom track goes back to per-beam radial velocities whatever coordinates the file
used (see :mod:`.rdi_frames`), RDI's bad-value marker becomes NaN, vertical BT ranges
become slant ranges, attitude is converted to the case's Euler convention, and GNSS
from the file's NMEA becomes the reference velocity with the clock offset applied.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import numpy as np

from ..case import Attitude, Case, Environment, Instrument, Pings, Position, Reference, depth_from_vertical_ranges, format_utc
from ...models.sound_speed import sound_speed_m_s
from ..hashing import sha256_of
from . import gnss, rdi_frames, rdi_water
from .reader import ImportFailure, read_dolfyn
from .window import Window, select

ATTITUDE_RESOLUTION_DEG = 0.01  # PD0 variable leader: heading, pitch, roll in 0.01 deg
REFERENCE_MARGIN_S = 5.0


def _epoch_s(values) -> np.ndarray:
    return values.astype("datetime64[ns]").astype(np.int64) / 1e9


def _bits(text, n=8) -> str:
    return str(text or "").zfill(n)[-n:]


def _bt_radial(ds, path) -> tuple[np.ndarray, int]:
    """(N, 4) RDI-order BT velocities restored to the PD0's integer mm/s, bad marker -> NaN."""
    raw = np.asarray(ds["vel_bt"].values, dtype=np.float64).T[:, :4]
    if raw.shape[1] != 4:
        raise ImportFailure(f"{path}: vel_bt: expected 4 bottom-track components, got {raw.shape[1]}")
    mm = np.round(raw * 1000.0)
    bad = ~np.isfinite(mm) | (mm == rdi_frames.BAD_VELOCITY_MM_S)
    out = np.where(bad, np.nan, mm / 1000.0)
    return out, int(np.sum(bad))


def _angles(ds) -> dict:
    """Heading, tilt1, tilt2 in radians, float32 storage undone to the PD0's 0.01 deg."""
    r = ATTITUDE_RESOLUTION_DEG
    return {k: np.deg2rad(np.round(np.asarray(ds[k].values, dtype=np.float64) / r) * r)
            for k in ("heading", "pitch", "roll")}


def import_trdi(path, window: Window) -> tuple[Case, dict]:
    """Read a TRDI file into a case and the audit attributes of every conversion.

    Raises
    ------
    ImportFailure
        One line naming what is missing (no bottom track, unreadable file, ...).
    """
    with rdi_water.cell_size_history() as cell_sizes:
        ds, version = read_dolfyn(path)
    return _from_dataset(ds, version, window, path, getattr(path, "stem", str(path)), cell_sizes)


def import_trdi_dataset(ds, window: Window, name: str) -> tuple[Case, dict]:
    """A case from the :class:`xarray.Dataset` ``mhkit.dolfyn.read`` returned for a TRDI file.

    The same conversions as :func:`import_trdi`, with what only the file holds missing and
    said so in ``/provenance``: the GNSS comes from dolfyn's own fields only (NMEA text
    sentences in the file are not seen; dolfyn keeps positions as float32 unless read as
    adcpdyn reads them), the cell-size changes dolfyn merged are unknown, and there is no
    SHA-256 of the instrument file.
    """
    try:
        import mhkit

        version = f"a dolfyn Dataset handed over in memory (installed reader: mhkit {mhkit.__version__})"
    except ImportError:
        version = "a dolfyn Dataset handed over in memory"
    return _from_dataset(ds, version, window, None, name, None)


def _from_dataset(ds, version: str, window: Window, file, name: str, cell_sizes) -> tuple[Case, dict]:
    """The conversions of a dolfyn TRDI dataset; ``file`` is the instrument file (None for a Dataset in memory)."""
    path = file if file is not None else f"dataset {name!r}"
    recorded = str(Path(file).resolve()) if file is not None else path  # provenance: never relative to a working folder
    a = ds.attrs
    if "vel_bt" not in ds:
        raise ImportFailure(f"{path}: bottom track: none in this file (no TRDI bottom-track block); "
                            "a case needs per-beam bottom-track radial velocities (/pings/bt_radial_m_s)")
    if a.get("orientation", "down") != "down":
        raise ImportFailure(f"{path}: orientation: expected a down-looking head (vessel mount), got {a.get('orientation')!r}")
    coord = str(a.get("coord_sys", "")).lower()
    if coord not in ("beam", "inst", "ship", "earth"):
        raise ImportFailure(f"{path}: coord_sys: expected beam, inst, ship or earth, got {coord!r}")
    beam_angle = np.deg2rad(float(a["beam_angle"]))
    convex = str(a.get("beam_pattern", "convex")).lower() != "concave"
    ea, eb = float(a.get("heading_misalign_deg", 0.0)), float(a.get("magnetic_var_deg", 0.0))
    tilts = str(a.get("use_pitchroll", "no")).lower() == "yes"
    src = _bits(a.get("sensors_src"))
    internal = {"heading": src[3] == "1", "pitch": src[4] == "1", "roll": src[5] == "1"}
    if coord == "earth" and ea != 0.0:
        raise ImportFailure(f"{path}: heading_misalign_deg (EA): expected 0 for Earth-coordinate bottom track, got {ea}; "
                            "how the firmware combines EA with the heading is not verified against a file here")

    t_abs = _epoch_s(ds["time"].values)
    bt, n_bad_marker = _bt_radial(ds, path)
    ang = _angles(ds)
    vert = np.asarray(ds["dist_bt"].values, dtype=np.float64).T[:, :4]
    vert = np.where(vert > 0, vert, np.nan)
    keep, window_note = select(t_abs, window, str(path))
    t_abs, bt, vert = t_abs[keep], bt[keep], vert[keep]
    ang = {k: v[keep] for k, v in ang.items()}
    c_sound = np.asarray(ds["c_sound"].values, dtype=np.float64)[keep]
    depth_ed = np.asarray(ds["depth"].values, dtype=np.float64)[keep] if "depth" in ds else np.zeros(keep.sum())

    heading = np.mod(ang["heading"], 2 * np.pi)  # EB is already in it (heading_settings_applied)
    pitch = rdi_frames.gimbal_pitch(ang["pitch"], ang["roll"]) if internal["pitch"] else ang["pitch"]
    roll = ang["roll"]
    zero = np.zeros_like(roll)
    undone = "none (recorded in beam coordinates)"
    rot = None
    if coord == "earth":
        rot = rdi_frames.rdi_matrix(heading, pitch if tilts else zero, roll if tilts else zero)
        undone = "Earth -> instrument with M(heading, pitch, roll)^T" + ("" if tilts else " (tilts off: P = R = 0)")
    elif coord == "ship":
        rot = rdi_frames.rdi_matrix(np.full_like(roll, np.deg2rad(ea)), pitch if tilts else zero, roll if tilts else zero)
        undone = "ship -> instrument with M(EA, pitch, roll)^T (levelling and heading alignment)" + ("" if tilts else " (tilts off)")
    if coord != "beam":
        undone += "; instrument -> beam with the inverse of TRDI's 4x4 beam matrix (error velocity kept)"
    beams = rdi_frames.to_beam(bt, coord, beam_angle, convex, rot)
    radial = rdi_frames.case_beams(beams)
    slant = rdi_frames.case_beams(vert) / np.cos(beam_angle)

    transducer_depth = float(np.nanmedian(depth_ed)) if np.any(np.isfinite(depth_ed)) else 0.0
    t_rel = t_abs - t_abs[0]
    water_depth = depth_from_vertical_ranges(t_rel, vert, transducer_depth)
    if water_depth is None:
        raise ImportFailure(f"{path}: dist_bt: expected some valid bottom-track ranges, got none")
    frame = "transducer" if all(internal.values()) else "vessel"
    water, water_attrs = rdi_water.water_profile(ds, coord, beam_angle, convex, rot, keep, transducer_depth,
                                                 float(np.max(water_depth)), cell_sizes or ())
    if cell_sizes is None and water is not None:
        water_attrs["cell_size_changes"] = ("unknown: the Dataset was read outside adcpdyn, so the cell-size changes "
                                            "dolfyn merged were not seen")
    attitude_missing = bool(np.all(ang["heading"] == 0) and np.all(ang["pitch"] == 0) and np.all(ang["roll"] == 0))

    case = Case(
        name=str(name),
        description=f"imported from {recorded} by adcpdyn import ({version})",
        instrument=Instrument(beam_angle_rad=float(beam_angle), transducer_radius_m=0.0,
                              frequency_hz=float(a["carrier_freq"]) * 1e3, sound_speed_m_s=float(np.nanmedian(c_sound)),
                              make="TRDI", model=str(a.get("inst_model") or ""), serial_number=str(a.get("serialnum") or ""),
                              temperature_c=_median(ds, "temp", keep), salinity_psu=_median(ds, "salinity", keep)),
        environment=Environment(water_depth_m=float(np.nanmedian(water_depth)), transducer_depth_m=transducer_depth,
                                water_depth_per_ping_m=water_depth),
        pings=Pings(time_s=t_rel, bt_radial_m_s=radial, bt_range_m=slant),
        attitude=Attitude(time_s=t_rel.copy(), heading_rad=heading, pitch_rad=pitch, roll_rad=roll, frame=frame),
        water=water,
    )
    attrs = {
        "/provenance": {
            "source_file": recorded if file is not None else f"{name} (a dolfyn Dataset in memory; its file not known)",
            "source_file_sha256": sha256_of(file) if file is not None else "not available (a Dataset in memory, not the file)",
            "reader": version, "vendor": "TRDI",
            "instrument": f"{a.get('inst_model', '?')} {a.get('carrier_freq', '?')} kHz, SN {a.get('serialnum', '?')}, "
                          f"firmware {a.get('firmware_ver', '?')}",
            "source_program": str(a.get("source_program") or "unknown"),
            "coordinate_system_found": coord, "transforms_undone": undone,
            "use_tilts_EX": int(tilts), "heading_alignment_EA_deg": ea, "heading_bias_EB_deg": eb,
            **_heading_settings(ea, eb),
            "sensor_source_EZ_bits": src, "orientation": str(a.get("orientation")), "beam_pattern": "convex" if convex else "concave",
            "beam_mapping": "case beams 1,2,3,4 = RDI beams 4,3,2,1 (case x_t = RDI Y toward beam 3, y_t = RDI X, z_t = -Z)",
            "time_origin_adcp_clock": str(np.datetime64(int(round(t_abs[0] * 1e9)), "ns")),
            "pings_read": int(ds["time"].size), "selection": window_note,
            "water_profile": water_attrs.pop("water_profile", f"imported: {0 if water is None else water.cell_depth_m.size} "
                                                               "cells (/water; conversions in its attributes)"),
        },
        "/pings": {
            "bt_velocity_source": f"dolfyn vel_bt in {coord} coordinates, restored to the PD0's integer mm/s, float64",
            "bt_bad_value_marker": f"-32768 mm/s and missing values -> NaN ({n_bad_marker} values)",
            "bt_sign": "positive toward the transducer (TRDI beam convention = case convention)",
            "bt_range_conversion": "TRDI vertical range per beam / cos(beam angle) = slant range; 0 (no detection) -> NaN",
        },
        "/attitude": {
            "frame_reason": f"EZ sensor source bits {src}: heading/pitch/roll internal = "
                            f"{int(internal['heading'])}/{int(internal['pitch'])}/{int(internal['roll'])}",
            "heading_conversion": "case yaw = TRDI heading as recorded (it already holds EB), radians, clockwise from "
                                  "north (the compass's reference: magnetic unless EB held the declination)",
            "pitch_conversion": "gimbal pitch atan(tan(tilt1) cos(tilt2)) (internal tilt sensor)" if internal["pitch"]
                                else "as recorded (external sensor)",
            "roll_conversion": "as recorded; TRDI roll (starboard down positive) = case roll",
            "resolution_deg": ATTITUDE_RESOLUTION_DEG,
            "attitude_recorded": int(not attitude_missing),
        },
        "/environment": {
            "transducer_depth_source": "median of the PD0 depth field (ED); 0 when the instrument was not told",
            "water_depth_source": "transducer depth + mean of the four vertical BT ranges, interpolated where BT was lost",
        },
        **({"/water": water_attrs} if water is not None else {}),
        "/instrument": {
            "transducer_radius_source": "not in the file: 0 (all four transducers at P)",
            "sound_speed_source": f"median of the PD0 sound speed ({np.nanmin(c_sound):.1f}-{np.nanmax(c_sound):.1f} m/s)",
            "sound_speed_check": _sound_speed_check(ds, keep, c_sound, transducer_depth),
        },
    }
    if attitude_missing:
        attrs["/attitude"]["attitude_warning"] = ("every heading, pitch and roll sample in the file is exactly 0: the file "
                                                  "holds no attitude (e.g. a VmDAS ENR without its navigation files); the "
                                                  "zeros are passed through as recorded and nothing that uses attitude is meaningful")
    return _with_reference(case, attrs, ds, file, t_abs)


def _median(ds, name: str, keep) -> float | None:
    """The median of a per-ensemble variable over the pings kept (None where the file has none)."""
    if name not in ds:
        return None
    v = np.asarray(ds[name].values, dtype=np.float64)[keep]
    return round(float(np.nanmedian(v)), 2) if np.any(np.isfinite(v)) else None  # the PD0 resolution: 0.01 deg C, 1 ppt


def _sound_speed_check(ds, keep, c_sound, transducer_depth: float) -> str:
    """Whether the PD0's sound speed is what TRDI's formula gives from its own temperature and salinity
    setting (:func:`~adcpdyn.models.sound_speed.sound_speed_m_s`): computed (the salinity setting then
    decides it) or entered by hand."""
    T, S = _median(ds, "temp", keep), _median(ds, "salinity", keep)
    if T is None or S is None:
        return "not checked: no temperature or salinity in the file"
    c = float(sound_speed_m_s(T, S, transducer_depth))
    verdict = "computed from them" if abs(c - float(np.nanmedian(c_sound))) <= 1.0 else "not from them (set by hand?)"
    return (f"PD0 {np.nanmedian(c_sound):.0f} m/s; Medwin's formula at the recorded {T:.2f} deg C, salinity setting {S:g} ppt, "
            f"{transducer_depth:.1f} m: {c:.1f} m/s ({verdict}); a salinity entered wrong scales every velocity and range by "
            "c_recorded / c_true")


def _heading_settings(ea: float, eb: float) -> dict:
    """What the file's heading settings did to the headings the case holds."""
    return {
        "heading_settings_applied": {
            "heading_bias_EB_deg": eb, "EB_in_case_heading": True,
            "heading_alignment_EA_deg": ea, "EA_in_case_heading": False,
            "declination_in_case_heading_deg": eb, "magnetic_variation_in_file": False,
        },
        "heading_settings_note": (
            f"EB = {eb:+.2f} deg (heading bias, the PD0's only heading correction: dolfyn's magnetic_var_deg) is "
            "already in the recorded heading (TRDI's firmware applies it to the heading it records, as dolfyn reads "
            "the PD0): the case heading is the recorded one, EB not added again, so any declination in the headings is "
            f"EB's; EA = {ea:+.2f} deg (heading alignment of the head in the ship) is not in the heading: it only "
            "turns ship coordinates and is undone with them. The PD0 holds no other magnetic variation (dolfyn exposes "
            "none); one that WinRiver applied in its own processing lives in its measurement file, not in the PD0"),
    }


def _position(track, offset: float, t_abs, case: Case) -> tuple[Position | None, str]:
    """GGA fixes on the case clock (float64) and the UTC of the clock's zero."""
    origin = format_utc(dt.datetime.fromtimestamp(float(t_abs[0]) + offset, tz=dt.timezone.utc))
    if track.fix_time_utc_s is None:
        return None, origin
    t = track.fix_time_utc_s - offset - t_abs[0]
    keep = (t >= case.pings.time_s[0] - REFERENCE_MARGIN_S) & (t <= case.pings.time_s[-1] + REFERENCE_MARGIN_S)
    if not keep.any():
        return None, origin
    return Position(time_s=t[keep], latitude_deg=np.asarray(track.latitude_deg, dtype=np.float64)[keep],
                    longitude_deg=np.asarray(track.longitude_deg, dtype=np.float64)[keep]), origin


def _with_reference(case: Case, attrs: dict, ds, path, t_abs) -> tuple[Case, dict]:
    """Attach the GNSS reference velocity when the file carries usable NMEA (``path`` None: a Dataset in
    memory, only dolfyn's own GNSS fields)."""
    from ...models.frames import beams_to_earth, sensed_rotation

    try:
        coarse = gnss.coarse_offset(ds)
        raw = b""
        if path is not None:
            with open(path, "rb") as fh:
                raw = fh.read()
        track = gnss.read_track(raw, ds, coarse, float(t_abs[0]))
    except ValueError as exc:
        attrs["/provenance"]["gnss"] = f"none: {exc}"
        attrs["/provenance"]["time_origin_utc_source"] = "none: no GNSS ties the ADCP clock to UTC (time_origin_utc absent)"
        return case, attrs
    t = case.pings.time_s  # bottom track turned to the Earth with the recorded attitude (no lever arms)
    v_bt = beams_to_earth(case.pings.bt_radial_m_s, case.instrument.beam_directions(),
                          sensed_rotation(case.attitude.ypr_at(t), case.attitude.frame))[0]
    offset, peak, refined = gnss.refine_offset(track, t_abs, v_bt, coarse)
    stats = gnss.compare(track, offset, t_abs, v_bt)
    position, origin = _position(track, offset, t_abs, case)
    case = case.replace(position=position, time_origin_utc=origin)
    attrs["/provenance"]["time_origin_utc_source"] = ("first ping's ADCP time stamp + clock_offset_s (GNSS UTC - ADCP "
                                                      "clock)")
    if position is not None:
        attrs["/position"] = {
            "source": f"{track.source} GGA fixes, float64 degrees (WGS84); time on the ADCP clock "
                      "(GNSS UTC - clock_offset_s), fixes within 5 s of the selected pings",
            "point": "the GNSS antenna (its position in the vessel is not in the file)",
        }
    t_ref = track.time_utc_s - offset - t_abs[0]
    inside = (t_ref >= case.pings.time_s[0] - REFERENCE_MARGIN_S) & (t_ref <= case.pings.time_s[-1] + REFERENCE_MARGIN_S)
    vel = track.velocity_ned_m_s[inside].copy()
    vel[:, 2] = np.nan  # not measured: a velocity from VTG or differenced GGA has no usable vertical
    if inside.sum() < gnss.MIN_FIXES:
        attrs["/provenance"]["gnss"] = f"none: {int(inside.sum())} GNSS velocities inside the selected pings"
        return case, attrs
    window = track.window_s[inside] - offset - t_abs[0]
    averaged = bool(np.all(window[:, 1] > window[:, 0]))  # differenced positions: each velocity a mean over its fixes
    case = case.replace(reference=Reference(time_s=t_ref[inside], velocity_m_s=vel, point_body_m=np.zeros(3),
                                            window_s=window if averaged else None))
    attrs["/provenance"].update({
        "gnss": f"{track.source}: {track.n_fixes} GGA fixes; velocity from {track.velocity_from}",
        "clock_offset_s": offset, "clock_offset_coarse_s": coarse,
        "clock_offset_method": ("coarse: median GNSS UTC - ADCP time stamp from the reader; refined by maximising the "
                                "correlation of BT speed and GNSS speed over +-5 s" if refined else
                                "coarse only: the BT/GNSS speed correlation peak was too weak to refine"),
        "clock_offset_correlation": peak,
        **{f"bt_vs_gnss_{k}": v for k, v in stats.items()},
    })
    attrs["/reference"] = {
        "source": "GNSS over ground, Earth frame (N, E, D), time on the ADCP clock (GNSS UTC - clock_offset_s)",
        "vertical_velocity": "NaN: not measured (VTG and differenced GGA carry no usable vertical velocity)",
        "point_body_source": "antenna position not in the file: zeros (taken at G)",
        "window": ("window_s: the interval between the two GGA fixes each velocity is differenced from (the velocity is "
                   "the mean over it, stamped at its middle)" if averaged else
                   "none: VTG velocities, instantaneous at their time stamps"),
    }
    return case, attrs
