"""CALIB.json, the output of ``adcpdyn calibrate``: one reader and one validation for every user.

Every key a reader may use is described by one line of :data:`KEYS` (its type, shape,
where ``null`` is allowed, its range and unit); :func:`validate_calibration` checks a
parsed file against it and :func:`read_calibration` opens, parses and validates a file.
Every problem is a one-line ``ValueError``::

    calibration FILE: KEY: expected ..., got ...

``null`` means "not determined": it is accepted wherever the table allows it, and the
typed record (:class:`~adcpdyn.estimators.calibration.record.CalibrationRecord`) refuses it
in one line only when a reader needs that value. Unknown keys are ignored (later versions
may add keys). Files without ``schema_version`` are version 1; versions 1 to 3 are read.

To accept a new key, add one line to :data:`KEYS`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["KEYS", "SCHEMA_VERSIONS", "Calibration", "read_calibration", "validate_calibration", "calibration_from_dict",
           "attitude_model_from", "source_prefix"]

SCHEMA_VERSIONS = (1, 2, 3)
MAX_LEVER_ARM_M = 100.0  # a transducer 100 m from the centre of rotation: no vessel carries one
MAX_MOVING_BED_M_S = 5.0
MAX_COMPASS_DEVIATION_RAD = 0.5
TWO_PI = 2 * math.pi

NONE, VALUE, ELEMENTS = "none", "value", "elements"  # where null is allowed


class Calibration(dict):
    """A validated CALIB.json: a dict that remembers the file it came from (``source``)."""

    source: str = ""


@dataclass(frozen=True)
class Key:
    """What one key of CALIB.json must hold.

    kind : ``number`` | ``integer`` | ``bool`` | ``string`` | ``array`` (nested lists of
        numbers of ``shape``) | ``object`` | ``list`` | ``any``
    shape : the shape of an ``array`` (e.g. ``(4, 3)``)
    nulls : ``none`` (never null), ``value`` (the whole value may be null: not determined)
        or ``elements`` (also any number of an array)
    low, high, unit : allowed closed range of every number, and its unit for messages
    choices : allowed values (``integer`` and ``string``)
    check : further check of a present, non-null value: ``check(value, path, fail)``
    """

    kind: str
    shape: tuple = ()
    nulls: str = VALUE
    low: float = -math.inf
    high: float = math.inf
    unit: str = ""
    choices: tuple = ()
    check: Callable | None = None


def _sin_cos(low: float, high: float, extra: dict | None = None):
    """An object {"sin": number, "cos": number} (each null when not determined); ``extra`` keys
    are checked when present, others ignored."""
    def check(value, path, fail):
        for k in ("sin", "cos"):
            if k not in value:
                fail(path, 'expected an object {"sin": number, "cos": number} or null', _show(value))
            _check(Key("number", low=low, high=high, unit="rad"), value[k], f"{path}.{k}", fail)
        for k, spec in (extra or {}).items():
            if k in value:
                _check(spec, value[k], f"{path}.{k}", fail)
    return check


def _norm_at_most(limit: float, unit: str):
    def check(value, path, fail):
        v = np.array([np.nan if x is None else x for x in value], dtype=float)
        if np.all(np.isfinite(v)) and np.hypot(*v) > limit:
            fail(path, f"expected a vector of magnitude <= {limit:g} {unit}", f"magnitude {np.hypot(*v):.6g}")
    return check


def _attitude_model(value, path, fail):
    """The damped-mode attitude model (``AttitudeParams.to_dict``)."""
    modes = _member(value, "modes", path, fail)
    if not isinstance(modes, list):
        fail(f"{path}.modes", "expected a list of modes", _show(modes))
    for i, m in enumerate(modes):
        p = f"{path}.modes[{i}]"
        if not isinstance(m, dict):
            fail(p, "expected an object {omega_rad_s, decay_1_s}", _show(m))
        _check(Key("number", nulls=NONE, low=0.0, high=1e3, unit="rad/s"), _member(m, "omega_rad_s", p, fail),
               f"{p}.omega_rad_s", fail)
        _check(Key("number", nulls=NONE, low=-1e3, high=1e3, unit="1/s"), _member(m, "decay_1_s", p, fail),
               f"{p}.decay_1_s", fail)
    for axis in ("roll", "pitch", "yaw"):
        p = f"{path}.{axis}"
        ax = _member(value, axis, path, fail)
        if not isinstance(ax, dict):
            fail(p, "expected an object {bias_rad, modes}", _show(ax))
        if axis == "yaw":
            _check(Key("array", shape=(-1,), nulls=NONE), _member(ax, "trend_coefficients", p, fail),
                   f"{p}.trend_coefficients", fail)
            if not ax["trend_coefficients"]:
                fail(f"{p}.trend_coefficients", "expected at least one coefficient", "[]")
        else:
            _check(Key("number", nulls=NONE, low=-TWO_PI, high=TWO_PI, unit="rad"), _member(ax, "bias_rad", p, fail),
                   f"{p}.bias_rad", fail)
        cs = _member(ax, "modes", p, fail)
        if not isinstance(cs, list) or len(cs) != len(modes):
            fail(f"{p}.modes", f"expected a list of {len(modes)} modes (one per {path}.modes)", _show(cs))
        for i, m in enumerate(cs):
            q = f"{p}.modes[{i}]"
            if not isinstance(m, dict):
                fail(q, "expected an object {cos_rad, sin_rad}", _show(m))
            for k in ("cos_rad", "sin_rad"):
                _check(Key("number", nulls=NONE, low=-TWO_PI, high=TWO_PI, unit="rad"), _member(m, k, q, fail),
                       f"{q}.{k}", fail)
    if "t_ref_s" in value:
        _check(Key("number", nulls=NONE), value["t_ref_s"], f"{path}.t_ref_s", fail)


def _config(value, path, fail):
    if "nominal_installation_ypr_rad" in value:
        _check(Key("array", (3,), ELEMENTS, -math.pi, math.pi, "rad"), value["nominal_installation_ypr_rad"],
               f"{path}.nominal_installation_ypr_rad", fail)


def _velocity_model(value, path, fail):
    times = _member(value, "knot_times_s", path, fail)
    _check(Key("array", (-1,), NONE), times, f"{path}.knot_times_s", fail)
    _check(Key("array", (len(times), 3), ELEMENTS, -100.0, 100.0, "m/s"), _member(value, "knot_velocities_m_s", path, fail),
           f"{path}.knot_velocities_m_s", fail)


def _runs(value, path, fail):
    for i, run in enumerate(value):
        p = f"{path}[{i}]"
        if not isinstance(run, dict):
            fail(p, 'expected an object {"case": ..., ...}', _show(run))
        _check(Key("string", nulls=NONE), _member(run, "case", p, fail), f"{p}.case", fail)
        for k in ("moving_bed_velocity_m_s", "moving_bed_velocity_se_m_s", "attitude_model", "attitude_source",
                  "velocity_model", "transducer_depth_offset_m", "transducer_depth_offset_se_m", "navigation",
                  "attitude_interpolation"):
            if k in run:
                _check(KEYS[k], run[k], f"{p}.{k}", fail)


def _own_effects(value, path, fail):
    from ...models.effects import CATALOG, effect_of

    effects = _member(value, "effects", path, fail)
    if not isinstance(effects, list) or any(e not in CATALOG for e in effects):
        fail(f"{path}.effects", f"expected a list of catalog effects ({', '.join(CATALOG)})", _show(effects))
    unknowns = _member(value, "unknowns", path, fail)
    if not isinstance(unknowns, dict):
        fail(f"{path}.unknowns", 'expected an object {"effect.unknown": {"value": ..., "se": ...}}', _show(unknowns))
    for name, v in unknowns.items():
        p = f"{path}.unknowns.{name}"
        if effect_of(name) not in effects:
            fail(p, f"expected an unknown of one of the effects {effects}", _show(name))
        if not isinstance(v, dict):
            fail(p, 'expected an object {"value": ..., "se": ...}', _show(v))
        _check(Key("number", nulls=NONE), _member(v, "value", p, fail), f"{p}.value", fail)
        _check(Key("number", low=0.0), _member(v, "se", p, fail), f"{p}.se", fail)
    if not all(any(effect_of(n) == e for n in unknowns) for e in effects):
        fail(f"{path}.unknowns", f"expected the unknowns of every effect {effects}", _show(sorted(unknowns)))
    _check(Key("string", choices=("knots", "random_walk")), _member(value, "navigation", path, fail),
           f"{path}.navigation", fail)


def _members(spec: dict):
    def check(value, path, fail):
        for k, key in spec.items():
            if k in value:
                _check(key, value[k], f"{path}.{k}", fail)
    return check


_instrument = _members({"make": Key("string"), "model": Key("string"), "serial_number": Key("string"),
                        "frequency_hz": Key("number", nulls=NONE, low=1e3, high=1e8, unit="Hz"),
                        "beam_angle_deg": Key("number", nulls=NONE, low=5.0, high=60.0, unit="deg"),
                        "n_beams": Key("integer", nulls=NONE), "sensor_frame": Key("string")})
_site = _members({"latitude_deg": Key("number", low=-90.0, high=90.0, unit="deg"),
                  "longitude_deg": Key("number", low=-180.0, high=180.0, unit="deg"),
                  "start_utc": Key("string"), "end_utc": Key("string")})


# One line per key: what `adcpdyn calibrate` writes and what readers use.
KEYS: dict[str, Key] = {
    "schema_version": Key("integer", nulls=NONE, choices=SCHEMA_VERSIONS),
    "radius_vectors_m": Key("array", (4, 3), ELEMENTS, -MAX_LEVER_ARM_M, MAX_LEVER_ARM_M, "m"),
    "radius_vectors_se_m": Key("array", (4, 3), ELEMENTS, 0.0, math.inf, "m"),
    "radius_vectors_head_m": Key("array", (4, 3), ELEMENTS, -MAX_LEVER_ARM_M, MAX_LEVER_ARM_M, "m"),
    "radius_vectors_head_se_m": Key("array", (4, 3), ELEMENTS, 0.0, math.inf, "m"),
    "installation_ypr_rad": Key("array", (3,), ELEMENTS, -math.pi, math.pi, "rad"),
    "installation_ypr_assumed_rad": Key("array", (3,), ELEMENTS, -math.pi, math.pi, "rad"),
    "installation_ypr_se_rad": Key("array", (3,), ELEMENTS, 0.0, math.inf, "rad"),
    "installation_determined": Key("bool"),
    "heading_misalignment_rad": Key("number", low=-TWO_PI, high=TWO_PI, unit="rad"),
    "heading_misalignment_se_rad": Key("number", low=0.0, unit="rad"),
    "attitude_frame": Key("string", choices=("vessel", "transducer")),
    "attitude_source": Key("string", choices=("model", "samples")),
    "transducer_depth_offset_m": Key("number", low=-2.0, high=2.0, unit="m"),  # per run (runs[i])
    "transducer_depth_offset_se_m": Key("number", low=0.0, unit="m"),
    "attitude_source_reason": Key("string"),
    "navigation": Key("string", choices=("knots", "random_walk")),  # per run (runs[i])
    "attitude_interpolation": Key("string", choices=("spline", "linear")),  # per run (runs[i]); null: a motion model
    "attitude_model": Key("object", check=_attitude_model),
    "velocity_model": Key("object", check=_velocity_model),
    "config": Key("object", check=_config),
    "objective": Key("number"),
    "max_constraint_violation": Key("number"),
    "formulation": Key("string"),
    "timing": Key("string"),
    "noise_sigma": Key("object"),
    "chi2_per_channel": Key("object"),
    "solver": Key("object"),
    "starts": Key("list"),
    "unobservable": Key("any"),
    "parameters": Key("object"),
    "warnings": Key("list"),
    "installation_yaw_is": Key("string"),
    # keys of the multi-run calibration (schema version 2)
    "moving_bed_velocity_m_s": Key("array", (2,), ELEMENTS, -MAX_MOVING_BED_M_S, MAX_MOVING_BED_M_S, "m/s",
                                   check=_norm_at_most(MAX_MOVING_BED_M_S, "m/s")),
    "moving_bed_velocity_se_m_s": Key("array", (2,), ELEMENTS, 0.0, math.inf, "m/s"),
    "moving_bed": Key("object"),
    "compass_deviation_rad": Key("object", check=_sin_cos(
        -MAX_COMPASS_DEVIATION_RAD, MAX_COMPASS_DEVIATION_RAD,
        {"mean_sin": Key("number", low=-1.0, high=1.0), "mean_cos": Key("number", low=-1.0, high=1.0)})),
    "compass_deviation_se_rad": Key("object", check=_sin_cos(0.0, math.inf)),
    "magnetic_declination_rad": Key("number", low=-math.pi, high=math.pi, unit="rad"),
    "magnetic_declination_note": Key("string"),
    "compass_error_rad": Key("number", low=-TWO_PI, high=TWO_PI, unit="rad"),
    "standard_errors": Key("object"),
    "confounded": Key("list"),
    "runs": Key("list", check=_runs),
    "provenance": Key("object"),  # adcpdyn version, source cases and their SHA-256, time written
    # schema version 3: whose calibration it is (cases.identity)
    "instrument": Key("object", check=_instrument),  # make, model, serial, frequency, beam angle, beams, sensor frame
    "site": Key("object", check=_site),  # the runs' mean position and UTC span
    "moving_bed_test": Key("object"),  # --moving-bed auto: speed, SE, threshold, percent of flow, decision
    "own_effects": Key("object", check=_own_effects),  # what the runs show on top of the calibration (diagnosed)
}

# A file holding none of these is not a calibration.
CALIBRATION_KEYS = ("radius_vectors_m", "radius_vectors_head_m", "installation_ypr_rad", "heading_misalignment_rad",
                    "attitude_model", "runs")


# ---------------------------------------------------------------------------- checks
def _show(value) -> str:
    """A value for a message: JSON text, at most 60 characters."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value).replace("nan", "NaN").replace("inf", "Infinity")
    try:
        text = json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        text = repr(value)
    text = " ".join(text.split())
    return text if len(text) <= 60 else text[:57] + "..."


def _member(obj: dict, key: str, path: str, fail):
    if key not in obj:
        fail(f"{path}.{key}", "expected a key here", "none (missing)")
    return obj[key]


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _range_text(spec: Key) -> str:
    unit = f" {spec.unit}" if spec.unit else ""
    if math.isinf(spec.low) and math.isinf(spec.high):
        return f"a finite number{unit}"
    if math.isinf(spec.high):
        return f"a number >= {spec.low:g}{unit}"
    if math.isinf(spec.low):
        return f"a number <= {spec.high:g}{unit}"
    return f"a number in [{spec.low:g}, {spec.high:g}]{unit}"


def _number(spec: Key, x, path, fail, null_ok: bool) -> None:
    what = _range_text(spec) + (" or null" if null_ok else "")
    if x is None:
        if not null_ok:
            fail(path, what, "null")
        return
    if not _is_number(x):
        fail(path, what, _show(x))
    if not math.isfinite(x):
        fail(path, what, _show(float(x)))
    if not (spec.low <= x <= spec.high):
        fail(path, what, _show(x))


def _array(spec: Key, value, path, fail) -> None:
    shape_text = "(" + ", ".join("n" if n < 0 else str(n) for n in spec.shape) + ("," if len(spec.shape) == 1 else "") + ")"

    def walk(v, dims, p):
        if not dims:
            _number(spec, v, p, fail, spec.nulls == ELEMENTS)
            return
        if not isinstance(v, list) or (dims[0] >= 0 and len(v) != dims[0]):
            got = f"a list of {len(v)}" if isinstance(v, list) else _show(v)
            items = "numbers" if len(dims) == 1 else "lists"
            want = f"a list of {dims[0]} {items}" if dims[0] >= 0 else f"a list of {items}"
            fail(p, f"{want} (an array of shape {shape_text})", got)
        for i, item in enumerate(v):
            walk(item, dims[1:], f"{p}[{i}]")

    walk(value, list(spec.shape), path)


def _check(spec: Key, value, path: str, fail) -> None:
    """Check one value (present) against its key's line."""
    if value is None:
        if spec.nulls == NONE:
            fail(path, f"expected {spec.kind if spec.kind != 'array' else 'an array'}, not null", "null")
        return
    kind = spec.kind
    if kind == "number":
        _number(spec, value, path, fail, spec.nulls != NONE)
    elif kind == "integer":
        if not isinstance(value, int) or isinstance(value, bool) or (spec.choices and value not in spec.choices):
            allowed = " or ".join(map(str, spec.choices)) if spec.choices else "an integer"
            fail(path, allowed, _show(value))
    elif kind == "bool":
        if not isinstance(value, bool):
            fail(path, "true or false", _show(value))
    elif kind == "string":
        if not isinstance(value, str) or (spec.choices and value not in spec.choices):
            allowed = " or ".join(json.dumps(c) for c in spec.choices) if spec.choices else "a string"
            fail(path, allowed, _show(value))
    elif kind == "array":
        _array(spec, value, path, fail)
    elif kind == "object":
        if not isinstance(value, dict):
            fail(path, "an object", _show(value))
    elif kind == "list":
        if not isinstance(value, list):
            fail(path, "a list", _show(value))
    if spec.check is not None:
        spec.check(value, path, fail)


def source_prefix(source: str) -> str:
    """How a one-line error names a calibration: ``calibration FILE: `` (``calibration: `` in memory)."""
    return f"calibration {source}: " if source else "calibration: "


def validate_calibration(d, source: str = "") -> Calibration:
    """Check a parsed CALIB.json against :data:`KEYS`; return it as a :class:`Calibration`.

    Parameters
    ----------
    d : object
        The parsed JSON (a dict when valid).
    source : str
        The file's name, for messages (default: the ``source`` of a Calibration, else none).

    Raises
    ------
    ValueError
        ``calibration SOURCE: KEY: expected ..., got ...`` on the first problem.
    """
    source = source or getattr(d, "source", "") or ""
    head = source_prefix(source)

    def fail(path, expected, got):
        expected = expected if expected.startswith("expected") else f"expected {expected}"
        raise ValueError(f"{head}{path}: {expected}, got {got}")

    if not isinstance(d, dict):
        raise ValueError(f"{head}expected a JSON object (the CALIB.json of `adcpdyn calibrate`), got {_show(d)}")
    if not any(k in d for k in CALIBRATION_KEYS):
        keys = ", ".join(sorted(map(str, d))[:6]) or "none"
        raise ValueError(f"{head}expected the output of `adcpdyn calibrate` (at least one of "
                         f"{', '.join(CALIBRATION_KEYS)}), got an object with keys: {keys}")
    for key, spec in KEYS.items():
        if key in d:
            _check(spec, d[key], key, fail)
    out = Calibration(d)
    out.source = source
    return out


def _plain(obj):
    """Python numbers and lists from numpy; NaN and infinities as None (as the writer turns them into null)."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain(v) for v in (obj.tolist() if isinstance(obj, np.ndarray) else obj)]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def calibration_from_dict(d, source: str = "") -> Calibration:
    """A calibration handed over as a dict, validated: with the writer's convention (numpy values
    as numbers, NaN and infinities as null: not determined; a file is stricter, NaN or Infinity
    there is an error); a :class:`Calibration` as it is.

    Raises
    ------
    ValueError
        One line naming the key.
    """
    return d if isinstance(d, Calibration) else validate_calibration(_plain(d), source)


def read_calibration(path) -> Calibration:
    """Open, parse and validate a CALIB.json.

    Raises
    ------
    ValueError
        One line naming the file (and the key): unreadable, empty, not JSON, not an
        object, or a key of the wrong type, shape or range (:func:`validate_calibration`).
    """
    source = str(path)
    head = source_prefix(source)
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{head}cannot read the file ({exc.strerror or exc})") from None
    if not raw.strip():
        raise ValueError(f"{head}expected a JSON object (the CALIB.json of `adcpdyn calibrate`), got an empty file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{head}expected a JSON object (the CALIB.json of `adcpdyn calibrate`), got a binary file "
                         "(not UTF-8 text)") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{head}expected a JSON object (the CALIB.json of `adcpdyn calibrate`), got invalid JSON "
                         f"({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    except RecursionError:
        raise ValueError(f"{head}expected a JSON object (the CALIB.json of `adcpdyn calibrate`), got JSON nested too "
                         "deeply") from None
    return validate_calibration(d, source)


# ---------------------------------------------------------------------------- the attitude model (also in a case's /truth)
def attitude_model_from(value, where: str):
    """An ``AttitudeParams`` from its dict (``AttitudeParams.to_dict``) or JSON text, checked as
    CALIB.json's ``attitude_model`` is; ``where`` names it in the one-line error."""
    from ...models.motion import AttitudeParams

    if isinstance(value, (str, bytes)):
        try:
            value = json.loads(value)
        except (json.JSONDecodeError, RecursionError, UnicodeDecodeError) as exc:
            raise ValueError(f"{where}: expected a JSON attitude model, got invalid JSON ({exc})") from None

    def fail(path, expected, got):
        expected = expected if expected.startswith("expected") else f"expected {expected}"
        raise ValueError(f"{where}: {path}: {expected}, got {got}")

    _check(Key("object", nulls=NONE, check=_attitude_model), value, "attitude_model", fail)
    return AttitudeParams.from_dict(value)
