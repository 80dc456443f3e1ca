"""Output of a correction: ``/corrected`` in its own HDF5 file, written atomically.

Layout: ``/corrected/time_s`` (N,), ``vessel_velocity_m_s`` (N, 3),
``error_velocity_m_s`` (N,), ``beams_used`` (N,), and with a profile
``water_velocity_m_s`` (N, K, 3) (referenced: ``settings["water_reference"]``) and
``water_relative_velocity_m_s`` (N, K, 3) (not referenced); attributes ``method``,
``source_case`` and ``settings``: the :class:`CorrectionProvenance` as JSON, one key per field
(the method's settings, heading misalignment, declination and moving bed applied, calibrated
and entered transducer depth, calibration file and SHA-256, ...). Provenance: the root
attributes ``adcpdyn_version`` and ``written_utc``, ``/corrected`` attributes
``source_case_name`` and ``source_case_sha256``. Files written before the provenance was
typed are read too: a key they lack takes its field's default, a key no field names is ignored.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

import h5py
import numpy as np

from .atomic import atomic_path

DEVIATION_KEYS = ("sin", "cos", "mean_sin", "mean_cos")  # compass deviation's JSON object


def _frozen(value):
    """JSON-like values as immutable ones: lists and arrays as tuples, numpy scalars as Python numbers."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    if isinstance(value, np.generic):
        return value.item()
    return value


def _listed(value):
    """Tuples back as JSON lists."""
    return [_listed(v) for v in value] if isinstance(value, tuple) else value


@dataclass(frozen=True)
class CorrectionProvenance:
    """What a correction applied and where its numbers came from (``/corrected``'s ``settings``).

    Angles in radians, lengths in metres, velocities in m/s (the bed: north, east); ``None``
    where a field does not apply (a static correction has no lever arms, a run without a
    profile no water reference) or nothing was applied (no heading correction, no bed).
    """

    # the method's own settings
    timing: str | None = None  # dynamic methods: deep | shallow | exact
    installation_ypr_rad: tuple | None = None  # (3,) the installation angles the beams were turned by
    installation_note: str = ""  # the calibration's nominal angles were used, and why
    lever_arms_sensor_m: tuple | None = None  # (4, 3) in the attitude sensor's frame (dynamic methods)
    rootfinder_newton_pings: int | None = None  # pings that took more than the first Newton step
    rootfinder_fallback_pings: int | None = None  # pings handed to casadi.rootfinder
    rootfinder_unconverged_pings: int | None = None  # pings left above 1e-9 m/s (NaN velocities)
    rootfinder_max_residual_m_s: float | None = None  # the largest residual of the solved pings
    water_reference: str | None = None  # bt | gnss (a run with a water profile)
    water_reference_note: str = ""
    # the headings
    heading_misalignment_applied_rad: float | None = None  # None: headings as recorded
    compass_deviation_applied_rad: tuple | None = None  # (B, C, mean_sin, mean_cos) applied with it
    magnetic_declination_rad: float | None = None  # the calibration's (held by the misalignment, not applied again)
    compass_error_rad: float | None = None
    heading_correction_note: str = ""
    # the bed under the bottom track
    moving_bed_velocity_m_s: tuple | None = None  # (north, east) added back; None: none applied
    moving_bed_note: str = ""
    # the transducer depth
    transducer_depth_entered_m: float | None = None  # as entered in the instrument or case
    transducer_depth_calibrated_m: float | None = None  # as the calibration found it from the slant ranges (used)
    transducer_depth_note: str = ""
    # the calibration and the case
    calibration_file: str = "none"
    calibration_sha256: str | None = None
    calibration_provenance: dict | None = None  # CALIB.json's own provenance block
    source_case_name: str = ""
    source_case_file: str | None = None
    source_case_sha256: str | None = None
    warnings: tuple = ()

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name != "calibration_provenance" and isinstance(value, (list, tuple, np.ndarray, np.generic)):
                object.__setattr__(self, f.name, _frozen(value))

    def replace(self, **changes) -> "CorrectionProvenance":
        """A copy with ``changes`` (field names; an unknown one is a TypeError)."""
        return dataclasses.replace(self, **changes)

    def to_settings(self) -> dict:
        """The JSON object of ``/corrected``'s ``settings``: one key per field."""
        out = {f.name: _listed(getattr(self, f.name)) for f in dataclasses.fields(self)}
        if self.compass_deviation_applied_rad is not None:
            out["compass_deviation_applied_rad"] = dict(zip(DEVIATION_KEYS, self.compass_deviation_applied_rad))
        return out

    @classmethod
    def from_settings(cls, settings: dict) -> "CorrectionProvenance":
        """Read ``settings`` back, from this version's files and earlier ones (keys they lack
        take the defaults; keys no field names are ignored)."""
        names = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in (settings or {}).items() if k in names}
        deviation = values.get("compass_deviation_applied_rad")
        if isinstance(deviation, dict):  # the calibration's {sin, cos, mean_sin, mean_cos}; null: not applied (0)
            values["compass_deviation_applied_rad"] = tuple(float(deviation.get(k) or 0.0) for k in DEVIATION_KEYS)
        for k in ("heading_correction_note", "installation_note", "water_reference_note", "moving_bed_note",
                  "transducer_depth_note", "source_case_name"):
            if values.get(k) is None:
                values.pop(k, None)
        return cls(**values)


@dataclass(frozen=True)
class Correction:
    """Per-ping velocities from one correction method (what ``/corrected`` holds).

    vessel_velocity_m_s (N, 3) Earth frame; water_velocity_m_s (N, K, 3) or None, referenced
    to the bottom track or the GNSS (``provenance.water_reference``);
    water_relative_velocity_m_s (N, K, 3) or None, the water relative to the transducer (not
    referenced); error_velocity_m_s (N,) (NaN where fewer than four beams); beams_used (N,) int;
    ``provenance``: what the correction applied (:class:`CorrectionProvenance`).
    """

    method: str
    time_s: np.ndarray
    vessel_velocity_m_s: np.ndarray
    error_velocity_m_s: np.ndarray
    beams_used: np.ndarray
    water_velocity_m_s: np.ndarray | None = None
    provenance: CorrectionProvenance = field(default_factory=CorrectionProvenance)
    water_relative_velocity_m_s: np.ndarray | None = None

    def with_provenance(self, **changes) -> "Correction":
        """The same correction, its provenance with ``changes``."""
        return dataclasses.replace(self, provenance=self.provenance.replace(**changes))


def write_correction(correction, path, source_case: str = "") -> None:
    """Write a :class:`Correction` to ``path`` atomically."""
    import datetime as dt
    from pathlib import Path

    from .hashing import sha256_of
    from .hashing import adcpdyn_version

    sha = correction.provenance.source_case_sha256 or (
        sha256_of(source_case) if source_case and Path(source_case).is_file() else "not available (no case file)")
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = "adcp-corrected"
            f.attrs["version"] = 1
            f.attrs["adcpdyn_version"] = adcpdyn_version()
            f.attrs["written_utc"] = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
            g = f.create_group("corrected")
            g.attrs["method"] = correction.method
            g.attrs["source_case"] = str(source_case)
            g.attrs["source_case_name"] = str(correction.provenance.source_case_name)
            g.attrs["source_case_sha256"] = str(sha)
            g.attrs["settings"] = json.dumps(correction.provenance.to_settings())
            g.create_dataset("time_s", data=np.asarray(correction.time_s, dtype=float))
            g.create_dataset("vessel_velocity_m_s", data=np.asarray(correction.vessel_velocity_m_s, dtype=float))
            g.create_dataset("error_velocity_m_s", data=np.asarray(correction.error_velocity_m_s, dtype=float))
            g.create_dataset("beams_used", data=np.asarray(correction.beams_used, dtype=np.int8))
            if correction.water_velocity_m_s is not None:
                g.create_dataset("water_velocity_m_s", data=np.asarray(correction.water_velocity_m_s, dtype=float))
            if getattr(correction, "water_relative_velocity_m_s", None) is not None:
                g.create_dataset("water_relative_velocity_m_s",
                                 data=np.asarray(correction.water_relative_velocity_m_s, dtype=float))


def read_correction(path) -> dict:
    """The ``/corrected`` group of a file as a dict of arrays plus ``method`` and ``provenance``
    (:class:`CorrectionProvenance`, from this version's files and earlier ones)."""
    with h5py.File(path, "r") as f:
        if "corrected" not in f:
            raise ValueError(f"{path}: /corrected: group missing; expected the output of `adcpdyn correct`")
        g = f["corrected"]
        out = {k: g[k][()] for k in g}
        out["method"] = g.attrs["method"]
        out["provenance"] = CorrectionProvenance.from_settings(json.loads(g.attrs.get("settings", "{}")))
    return out
