"""Read and write case files (``docs/case-format.md``, version 1), every case validated on
the way (:mod:`.validation`); every problem with a file a one-line
:class:`.checks.CaseFormatError`: ``<file>: <HDF5 path>: expected ..., got ...``.
"""

from __future__ import annotations

import contextlib
import json
import os

import h5py
import numpy as np

from .atomic import atomic_path
from .case import (
    FORMAT_NAME,
    FORMAT_VERSION,
    Attitude,
    Case,
    Environment,
    Instrument,
    Pings,
    Position,
    Reference,
    Truth,
    Vessel,
    Water,
)
from .checks import SOUND_SPEED_INPUTS, VESSEL_FIELDS, Checker, attr_name, number_text, quoted
from .validation import validate_case

__all__ = ["read_case", "write_case"]


# ----------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------


class _Reader:
    def __init__(self, source: str):
        self.c = Checker(source)

    def _member(self, parent: h5py.Group, name: str, kind: type, required: bool):
        path = f"{parent.name.rstrip('/')}/{name}"
        obj = parent.get(name)
        word, other = ("group", "dataset") if kind is h5py.Group else ("dataset", "group")
        if obj is None:
            if required:
                self.c.fail(path, f"expected a required {word}, got none (missing)")
            return None, path
        if not isinstance(obj, kind):
            self.c.fail(path, f"expected a {word}, got a {other}")
        return obj, path

    def group(self, parent: h5py.Group, name: str, required: bool = True):
        return self._member(parent, name, h5py.Group, required)[0]

    def dataset(self, grp: h5py.Group, name: str, required: bool = True):
        obj, path = self._member(grp, name, h5py.Dataset, required)
        if obj is None:
            return None
        if obj.dtype.kind not in "iuf":
            self.c.fail(path, f"expected a numeric dataset, got dtype {obj.dtype}")
        return np.array(obj[()], dtype=np.float64)

    def _raw_attr(self, grp: h5py.Group, name: str, required: bool):
        if name not in grp.attrs:
            if required:
                self.c.fail(attr_name(grp.name, name),
                            "expected a required attribute, got none (missing)")
            return None
        try:
            return grp.attrs[name]
        except (OSError, TypeError) as exc:
            self.c.fail(attr_name(grp.name, name), f"expected a readable attribute, got {exc}")

    def _numeric(self, grp, name, v) -> np.ndarray:
        a = np.asarray(v) if not isinstance(v, (str, bytes)) else None
        if a is None or a.dtype.kind not in "iufb":
            shown = _text(v)
            self.c.fail(attr_name(grp.name, name),
                        f"expected a number, got {quoted(v if shown is None else shown)}")
        return a

    def scalar(self, grp, name, required=True, default=None):
        v = self._raw_attr(grp, name, required)
        if v is None:
            return default
        a = self._numeric(grp, name, v)
        if a.size != 1:
            self.c.fail(attr_name(grp.name, name), f"expected a scalar, got shape {a.shape}")
        return a.reshape(())[()]

    def float_attr(self, grp, name, required=True, default=None):
        v = self.scalar(grp, name, required, default)
        return None if v is None else float(v)

    def int_attr(self, grp, name, required=True, default=None):
        v = self.scalar(grp, name, required, default)
        if v is None:
            return None
        if not float(v).is_integer():
            self.c.fail(attr_name(grp.name, name), f"expected an integer, got {number_text(v)}")
        return int(v)

    def vector_attr(self, grp, name, required=True, default=None):
        v = self._raw_attr(grp, name, required)
        if v is None:
            return default
        return np.array(self._numeric(grp, name, v), dtype=np.float64)

    def str_attr(self, grp, name, required=True, default=None):
        v = self._raw_attr(grp, name, required)
        if v is None:
            return default
        s = _text(v)
        if s is None:
            self.c.fail(attr_name(grp.name, name), f"expected a string, got {quoted(v)}")
        return s


def _optional_number(v) -> float | None:
    """An attribute the format does not define, read where it is one finite number, else None (ignored)."""
    try:
        x = np.asarray(v, dtype=float).ravel()
    except (TypeError, ValueError):
        return None
    return float(x[0]) if x.size == 1 and np.isfinite(x[0]) else None


def _identity_text(v) -> str:
    """An identity attribute (make, model, serial number) as text, a numeric serial included; "" when absent."""
    if v is None:
        return ""
    text = _text(v)
    if text is None:
        v = np.asarray(v).ravel()
        text = str(v[0].item()) if v.size == 1 else ""
    return text.strip()


def _text(v) -> str | None:
    """A str from a str/bytes attribute value (possibly a 1-element array), else None."""
    if isinstance(v, np.ndarray) and v.size == 1:
        v = v.reshape(())[()]
    if isinstance(v, bytes):
        try:
            return v.decode("utf-8")
        except UnicodeDecodeError:
            return v.decode("latin-1")
    if isinstance(v, str):
        return str(v)
    return None


def _attr_as_text(v) -> str:
    s = _text(v)
    if s is not None:
        return s
    try:
        return json.dumps(np.asarray(v).tolist())
    except (TypeError, ValueError):
        return str(v)


def _read(f: h5py.File, rd: _Reader) -> Case:
    root = f["/"]
    fmt = rd.str_attr(root, "format")
    if fmt != FORMAT_NAME:
        rd.c.fail(attr_name("/", "format"), f'expected "{FORMAT_NAME}", got {quoted(fmt)}')
    version = rd.scalar(root, "version")
    if isinstance(version, (bool, np.bool_)) or version != FORMAT_VERSION:
        rd.c.fail(attr_name("/", "version"), f"expected {FORMAT_VERSION}, got {quoted(version)}")
    # A missing name is the only omission we forgive: the file's stem serves.
    name = rd.str_attr(root, "name", required=False, default=None) or os.path.splitext(os.path.basename(f.filename))[0]
    description = rd.str_attr(root, "description", required=False, default="")

    g = rd.group(root, "instrument")
    instrument = Instrument(
        beam_angle_rad=rd.float_attr(g, "beam_angle_rad"),
        transducer_radius_m=rd.float_attr(g, "transducer_radius_m"),
        frequency_hz=rd.float_attr(g, "frequency_hz"),
        sound_speed_m_s=rd.float_attr(g, "sound_speed_m_s"),
        n_beams=rd.int_attr(g, "n_beams"),
        layout=rd.str_attr(g, "layout"),
        beam_dirs_t=rd.dataset(g, "beam_dirs_t", required=False),
        beam_pos_t=rd.dataset(g, "beam_pos_t", required=False),
        **{k: _identity_text(rd._raw_attr(g, k, False)) for k in ("make", "model", "serial_number")},
        **{k: _optional_number(rd._raw_attr(g, k, False)) for k in SOUND_SPEED_INPUTS},
    )

    g = rd.group(root, "environment")
    environment = Environment(
        water_depth_m=rd.float_attr(g, "water_depth_m"),
        transducer_depth_m=rd.float_attr(g, "transducer_depth_m"),
        water_depth_per_ping_m=rd.dataset(g, "water_depth_m", required=False),
    )

    g = rd.group(root, "vessel", required=False)
    vessel = Vessel() if g is None else Vessel(
        **{k: rd.float_attr(g, k, required=False) for k in VESSEL_FIELDS})

    g = rd.group(root, "pings")
    pings = Pings(
        time_s=rd.dataset(g, "time_s"),
        bt_radial_m_s=rd.dataset(g, "bt_radial_m_s"),
        bt_range_m=rd.dataset(g, "bt_range_m", required=False),
    )

    g = rd.group(root, "water", required=False)
    water = None if g is None else Water(
        cell_depth_m=rd.dataset(g, "cell_depth_m"),
        radial_m_s=rd.dataset(g, "radial_m_s"),
    )

    g = rd.group(root, "attitude")
    attitude = Attitude(
        time_s=rd.dataset(g, "time_s"),
        heading_rad=rd.dataset(g, "heading_rad"),
        pitch_rad=rd.dataset(g, "pitch_rad"),
        roll_rad=rd.dataset(g, "roll_rad"),
        frame=rd.str_attr(g, "frame"),
    )

    reference = None
    g = rd.group(root, "reference", required=False)
    if g is not None:
        stationary = rd.int_attr(g, "stationary", required=False, default=0)
        if stationary not in (0, 1):
            rd.c.fail(attr_name(g.name, "stationary"), f"expected 0 or 1, got {stationary}")
        reference = Reference(
            time_s=rd.dataset(g, "time_s", required=False),
            velocity_m_s=rd.dataset(g, "velocity_m_s", required=False),
            point_body_m=rd.vector_attr(g, "point_body_m", required=False,
                                        default=np.zeros(3)),
            stationary=bool(stationary),
            window_s=rd.dataset(g, "window_s", required=False),
        )

    truth = None
    g = rd.group(root, "truth", required=False)
    if g is not None:
        text = rd.str_attr(g, "effects", required=False, default="[]")
        try:
            effects = json.loads(text)
        except json.JSONDecodeError as exc:
            rd.c.fail(attr_name(g.name, "effects"), f"expected a JSON list, got invalid JSON ({exc})")
        if not isinstance(effects, list):
            rd.c.fail(attr_name(g.name, "effects"),
                      f"expected a JSON list, got {type(effects).__name__}")
        extra = {}
        for key in g.attrs:
            if key == "effects":
                continue
            with contextlib.suppress(OSError, TypeError):
                extra[key] = _attr_as_text(g.attrs[key])
        truth = Truth(
            radius_vectors_m=rd.dataset(g, "radius_vectors_m"),
            installation_ypr_rad=rd.dataset(g, "installation_ypr_rad"),
            vessel_velocity_m_s=rd.dataset(g, "vessel_velocity_m_s"),
            water_velocity_m_s=rd.dataset(g, "water_velocity_m_s", required=False),
            moving_bed_velocity_m_s=rd.dataset(g, "moving_bed_velocity_m_s", required=False),
            effects=effects,
            extra_attrs=extra,
        )

    return Case(name=name, description=description, instrument=instrument,
                environment=environment, vessel=vessel, pings=pings, water=water,
                attitude=attitude, reference=reference, truth=truth, **_read_site(root, rd))


def _read_site(root: h5py.Group, rd: _Reader) -> dict:
    """``/position`` and ``/.attrs["time_origin_utc"]`` (both optional)."""
    g = rd.group(root, "position", required=False)
    position = None if g is None else Position(
        time_s=rd.dataset(g, "time_s"),
        latitude_deg=rd.dataset(g, "latitude_deg"),
        longitude_deg=rd.dataset(g, "longitude_deg"),
    )
    return {"position": position,
            "time_origin_utc": rd.str_attr(root, "time_origin_utc", required=False, default=None)}


def read_case(path) -> Case:
    """Read and validate a case file.

    Parameters
    ----------
    path : str or os.PathLike
        The HDF5 case file.

    Returns
    -------
    Case
        Arrays as float64; optional groups and datasets that are absent are ``None``
        (``/vessel`` absent gives ``Vessel()``). Unknown groups and attributes are
        ignored, except that unknown ``/truth`` attributes go to
        ``Truth.extra_attrs`` as strings.

    Raises
    ------
    CaseFormatError
        If the file is not HDF5 or does not follow the format (one-line message
        prefixed by the file name, naming the field).
    FileNotFoundError
        If the file does not exist.
    """
    source = os.fspath(path)
    rd = _Reader(source)
    if not os.path.exists(source):
        raise FileNotFoundError(f"{source}: no such file")
    if os.path.isdir(source):
        rd.c.fail("/", "expected an HDF5 file, got a folder")
    kind = _other_file_kind(source)
    if kind:
        rd.c.fail("/", f"expected an adcpdyn case (HDF5, format adcp-case), got {kind}")
    try:
        f = h5py.File(source, "r")
    except FileNotFoundError:
        raise FileNotFoundError(f"{source}: no such file") from None
    except OSError as exc:
        rd.c.fail("/", f"expected an HDF5 file, got an unreadable file ({exc})")
    with f:
        if "format" not in f["/"].attrs and ("_NCProperties" in f["/"].attrs or "Conventions" in f["/"].attrs):
            rd.c.fail("/", "expected an adcpdyn case (HDF5, format adcp-case), got a netCDF file (an export: "
                           "`adcpdyn export` writes these from a case; give the case itself)")
        case = _read(f, rd)
    validate_case(case, source=source)
    return case


def _other_file_kind(source: str) -> str | None:
    """What a file that is not HDF5 evidently is (a CALIB.json, an instrument file), from its first bytes."""
    with open(source, "rb") as fh:
        head = fh.read(64)
    if head.startswith(b"\x89HDF"):
        return None
    text = head.lstrip()
    if text.startswith(b"{"):
        return "a JSON file (a CALIB.json or DIAG.json? `adcpdyn calibrate` writes them; cases are .h5)"
    if head[:2] == b"\x7f\x7f":
        return "a TRDI PD0 file (run `adcpdyn import` on it first)"
    return None


# ----------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------


def _ds(grp: h5py.Group, name: str, data) -> None:
    if data is not None:
        grp.create_dataset(name, data=np.asarray(data, dtype=np.float64))


def _write(f: h5py.File, case: Case) -> None:
    f.attrs["format"] = FORMAT_NAME
    f.attrs["version"] = np.int64(FORMAT_VERSION)
    f.attrs["name"] = case.name
    f.attrs["description"] = case.description

    ins = case.instrument
    g = f.create_group("instrument")
    g.attrs["beam_angle_rad"] = np.float64(ins.beam_angle_rad)
    g.attrs["transducer_radius_m"] = np.float64(ins.transducer_radius_m)
    g.attrs["frequency_hz"] = np.float64(ins.frequency_hz)
    g.attrs["sound_speed_m_s"] = np.float64(ins.sound_speed_m_s)
    g.attrs["n_beams"] = np.int64(ins.n_beams)
    g.attrs["layout"] = str(ins.layout)
    for key in ("make", "model", "serial_number"):  # the instrument's identity (attributes the format lets producers add)
        if getattr(ins, key):
            g.attrs[key] = str(getattr(ins, key))
    for key in SOUND_SPEED_INPUTS:  # what its sound speed was computed from, where known
        if getattr(ins, key) is not None:
            g.attrs[key] = np.float64(getattr(ins, key))
    _ds(g, "beam_dirs_t", ins.beam_dirs_t)
    _ds(g, "beam_pos_t", ins.beam_pos_t)

    env = case.environment
    g = f.create_group("environment")
    g.attrs["water_depth_m"] = np.float64(env.water_depth_m)
    g.attrs["transducer_depth_m"] = np.float64(env.transducer_depth_m)
    _ds(g, "water_depth_m", env.water_depth_per_ping_m)

    present = {k: getattr(case.vessel, k) for k in VESSEL_FIELDS
               if getattr(case.vessel, k) is not None}
    if present:
        g = f.create_group("vessel")
        for k, v in present.items():
            g.attrs[k] = np.float64(v)

    g = f.create_group("pings")
    _ds(g, "time_s", case.pings.time_s)
    _ds(g, "bt_radial_m_s", case.pings.bt_radial_m_s)
    _ds(g, "bt_range_m", case.pings.bt_range_m)

    if case.water is not None:
        g = f.create_group("water")
        _ds(g, "cell_depth_m", case.water.cell_depth_m)
        _ds(g, "radial_m_s", case.water.radial_m_s)

    a = case.attitude
    g = f.create_group("attitude")
    for name in ("time_s", "heading_rad", "pitch_rad", "roll_rad"):
        _ds(g, name, getattr(a, name))
    g.attrs["frame"] = str(a.frame)

    if case.reference is not None:
        r = case.reference
        g = f.create_group("reference")
        _ds(g, "time_s", r.time_s)
        _ds(g, "velocity_m_s", r.velocity_m_s)
        _ds(g, "window_s", r.window_s)
        g.attrs["point_body_m"] = np.asarray(r.point_body_m, dtype=np.float64)
        g.attrs["stationary"] = np.int64(1 if r.stationary else 0)

    if case.truth is not None:
        t = case.truth
        g = f.create_group("truth")
        _ds(g, "radius_vectors_m", t.radius_vectors_m)
        _ds(g, "installation_ypr_rad", t.installation_ypr_rad)
        _ds(g, "vessel_velocity_m_s", t.vessel_velocity_m_s)
        _ds(g, "water_velocity_m_s", t.water_velocity_m_s)
        g.attrs["effects"] = json.dumps(t.effects)
        for k, v in t.extra_attrs.items():
            g.attrs[k] = str(v)
    _write_site(f, case)


def _write_site(f: h5py.File, case: Case) -> None:
    """``/position``, ``/.attrs["time_origin_utc"]``, ``/truth/moving_bed_velocity_m_s`` when present."""
    if case.time_origin_utc is not None:
        f.attrs["time_origin_utc"] = str(case.time_origin_utc)
    if case.position is not None:
        g = f.create_group("position")
        for name in ("time_s", "latitude_deg", "longitude_deg"):
            _ds(g, name, getattr(case.position, name))
    if case.truth is not None:
        _ds(f["truth"], "moving_bed_velocity_m_s", case.truth.moving_bed_velocity_m_s)


def write_case(case: Case, path) -> None:
    """Validate a case and write it atomically as a version-1 case file.

    The file is written to a temporary file in the destination directory, flushed
    to disk and moved onto ``path`` with :func:`os.replace`, so ``path`` is either
    left untouched or holds the complete new file.

    Parameters
    ----------
    case : Case
        The case to write.
    path : str or os.PathLike
        Destination file; replaced if it exists.

    Raises
    ------
    CaseFormatError
        If the case is invalid (nothing is written).
    OSError
        If the file cannot be written (no temporary file is left behind).
    """
    target = os.fspath(path)
    validate_case(case, source=target)
    with atomic_path(target) as tmp:
        with h5py.File(tmp, "w") as f:
            _write(f, case)
