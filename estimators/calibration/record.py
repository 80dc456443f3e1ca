"""A CALIB.json as a typed, read-only record, and the one conversion every reader goes through.

:class:`CalibrationRecord` is what :meth:`CalibrationResult.from_json
<adcpdyn.estimators.calibration.result.CalibrationResult.from_json>` and
:func:`adcpdyn.read_calibration` return: the numbers the corrections and the diagnosis
read (lever arms, installation angles, heading misalignment, compass deviation,
declination, moving bed per run, attitude model and source, noise levels, runs), typed,
in SI units, NaN or ``None`` where the file says "not determined" (``null``). It is a
view of a validated file, not a rebuilt :class:`CalibrationResult`: the solver's
per-start table, the uncertainty object and the configuration dataclass are not in a
CALIB.json in a form worth rebuilding; the parsed file stays available (:attr:`data`).

:func:`calibration_dict` turns any way a calibration is handed over (a CALIB.json path,
a parsed dict, a :class:`CalibrationResult`, a :class:`CalibrationRecord`, or None) into the
validated dict (:class:`~adcpdyn.estimators.calibration.file.Calibration`) the
estimators read, through :func:`~adcpdyn.estimators.calibration.file.as_calibration`, which
knows every form by its shape (path, dict, ``to_dict()``): the file, record and result modules
import one way only (result -> record -> file).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...cases.identity import InstrumentIdentity, Site
from .file import Calibration, as_calibration, moving_bed_velocity, read_calibration

__all__ = ["CalibrationRecord", "RunRecord", "calibration_dict"]


def _array(value, shape) -> np.ndarray:
    """A float array from JSON (null -> NaN); all NaN when the whole value is null."""
    if value is None:
        return np.full(shape, np.nan)
    return np.array(_nan_for_none(value), dtype=float).reshape(shape)


def _nan_for_none(value):
    if isinstance(value, list):
        return [_nan_for_none(v) for v in value]
    return np.nan if value is None else value


def _vector_or_none(value) -> np.ndarray | None:
    """A vector, or None when it is absent or any component is not determined."""
    if value is None or any(v is None for v in value):
        return None
    return np.asarray(value, dtype=float)


def _float_or_none(value) -> float | None:
    return None if value is None else float(value)


def _attitude(value, where: str):
    if not value:
        return None
    from .file import attitude_model_from

    return attitude_model_from(value, where)


@dataclass(frozen=True, eq=False)
class RunRecord:
    """One run of a calibration (CALIB.json ``runs[i]``)."""

    case: str
    n_pings: int | None
    moving_bed_velocity_m_s: np.ndarray | None  # (2,) north, east; None: not estimated or not determined
    moving_bed_velocity_se_m_s: np.ndarray | None
    attitude_source: str | None  # "model" | "samples"
    attitude_model: object | None  # AttitudeParams of this run (None when absent)
    transducer_depth_offset_m: float | None
    noise_sigma: dict
    chi2_per_channel: dict


@dataclass(frozen=True, eq=False)
class CalibrationRecord:
    """A validated CALIB.json, typed (see the module docstring).

    Angles in radians, lengths in metres, velocities in m/s (north, east for the bed).
    Arrays hold NaN where the file has ``null`` (not determined); scalars and vectors that
    are not determined as a whole are ``None``.

    Attributes
    ----------
    schema_version : int
        1 (no ``schema_version`` key), 2 or 3.
    attitude_frame : str
        ``vessel`` (sensor in the vessel frame) or ``transducer`` (sensor in the head).
    lever_arms_m, lever_arms_se_m : ndarray (4, 3)
        Lever arms in the attitude sensor's frame (the head frame for a head sensor:
        ``radius_vectors_head_m``, else ``radius_vectors_m``) and their standard errors.
    radius_vectors_m, radius_vectors_se_m : ndarray (4, 3)
        Lever arms in the body (vessel) frame.
    installation_ypr_rad, installation_ypr_se_rad : ndarray (3,)
        Installation yaw, pitch, roll (for a head sensor on a moving run the yaw is the
        heading misalignment, pitch and roll NaN).
    installation_determined : bool
    nominal_installation_ypr_rad : ndarray (3,) or None
        The mounting as configured (``config.nominal_installation_ypr_rad``).
    heading_misalignment_rad, heading_misalignment_se_rad : float or None
        True heading = sensor heading + misalignment (+ compass deviation).
    compass_deviation_rad : tuple (B, C) or None
        B (sin psi - mean_sin) + C (cos psi - mean_cos); ``compass_deviation_centre`` holds
        (mean_sin, mean_cos).
    magnetic_declination_rad, compass_error_rad : float or None
    moving_bed : str
        ``off``, ``constant`` or ``section`` (``off`` when the file has no bed).
    moving_bed_velocity_m_s, moving_bed_velocity_se_m_s : ndarray (2,) or None
        The site's bed (north, east); each run's own is in ``runs``.
    attitude_model : AttitudeParams or None
    attitude_source : str
        ``model`` or ``samples``: the attitude the beams used.
    noise_sigma, chi2_per_channel : dict
    timing, formulation : str
    success : bool or None
        The solver's verdict (``solver.success``), None when the file does not say.
    objective : float or None
    runs : tuple of RunRecord
    warnings : tuple of str
    provenance : dict
        adcpdyn version, source cases and their SHA-256, time written (empty for older files).
    instrument : InstrumentIdentity or None
        Whose calibration it is (schema 3; None for older files).
    site : Site or None
        The runs' mean position and UTC span (schema 3).
    source : str
        The file it was read from ('' when built from a dict in memory).
    data : Calibration
        The validated dict itself (what :func:`calibration_dict` returns for this record).
    """

    schema_version: int
    attitude_frame: str
    lever_arms_m: np.ndarray
    lever_arms_se_m: np.ndarray
    radius_vectors_m: np.ndarray
    radius_vectors_se_m: np.ndarray
    installation_ypr_rad: np.ndarray
    installation_ypr_se_rad: np.ndarray
    installation_determined: bool
    nominal_installation_ypr_rad: np.ndarray | None
    heading_misalignment_rad: float | None
    heading_misalignment_se_rad: float | None
    compass_deviation_rad: tuple | None
    compass_deviation_centre: tuple
    compass_deviation_se_rad: tuple | None
    magnetic_declination_rad: float | None
    compass_error_rad: float | None
    moving_bed: str
    moving_bed_velocity_m_s: np.ndarray | None
    moving_bed_velocity_se_m_s: np.ndarray | None
    attitude_model: object | None
    attitude_source: str
    noise_sigma: dict
    chi2_per_channel: dict
    timing: str
    formulation: str
    success: bool | None
    objective: float | None
    runs: tuple
    warnings: tuple
    provenance: dict
    source: str
    data: Calibration = field(repr=False)
    instrument: InstrumentIdentity | None = None
    site: Site | None = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_json(cls, path) -> "CalibrationRecord":
        """Read, validate (:func:`~adcpdyn.estimators.calibration.file.read_calibration`) and type a CALIB.json.

        Raises
        ------
        ValueError
            One line naming the file and the key (see ``read_calibration``).
        """
        return cls.from_dict(read_calibration(path))

    @classmethod
    def from_dict(cls, d) -> "CalibrationRecord":
        """Type a parsed CALIB.json (validated first unless it already is a ``Calibration``)."""
        c = as_calibration(d)
        where = f"calibration {c.source}" if c.source else "calibration"
        frame = c.get("attitude_frame") or "vessel"
        head_key = "radius_vectors_head_m" if frame == "transducer" and "radius_vectors_head_m" in c else "radius_vectors_m"
        head_se = "radius_vectors_head_se_m" if head_key == "radius_vectors_head_m" else "radius_vectors_se_m"
        deviation = c.get("compass_deviation_rad")
        dev = None if not deviation or deviation.get("sin") is None or deviation.get("cos") is None else (
            float(deviation["sin"]), float(deviation["cos"]))
        centre = (float((deviation or {}).get("mean_sin", 0.0)), float((deviation or {}).get("mean_cos", 0.0)))
        dev_se = c.get("compass_deviation_se_rad") or {}
        dev_se = None if dev_se.get("sin") is None or dev_se.get("cos") is None else (float(dev_se["sin"]),
                                                                                     float(dev_se["cos"]))
        bed = c.get("moving_bed")
        nominal = (c.get("config") or {}).get("nominal_installation_ypr_rad")
        runs = tuple(RunRecord(
            case=str(r["case"]), n_pings=r.get("n_pings"),
            moving_bed_velocity_m_s=_vector_or_none(r.get("moving_bed_velocity_m_s")),
            moving_bed_velocity_se_m_s=_vector_or_none(r.get("moving_bed_velocity_se_m_s")),
            attitude_source=r.get("attitude_source"),
            attitude_model=_attitude(r.get("attitude_model"), f"{where}: runs[{i}]"),
            transducer_depth_offset_m=_float_or_none(r.get("transducer_depth_offset_m")),
            noise_sigma=dict(r.get("noise_sigma") or {}), chi2_per_channel=dict(r.get("chi2_per_channel") or {}),
        ) for i, r in enumerate(c.get("runs") or []))
        solver = c.get("solver") or {}
        return cls(
            schema_version=int(c.get("schema_version", 1)),
            attitude_frame=frame,
            lever_arms_m=_array(c.get(head_key), (4, 3)),
            lever_arms_se_m=_array(c.get(head_se), (4, 3)),
            radius_vectors_m=_array(c.get("radius_vectors_m"), (4, 3)),
            radius_vectors_se_m=_array(c.get("radius_vectors_se_m"), (4, 3)),
            installation_ypr_rad=_array(c.get("installation_ypr_rad"), (3,)),
            installation_ypr_se_rad=_array(c.get("installation_ypr_se_rad"), (3,)),
            installation_determined=bool(c.get("installation_determined", False)),
            nominal_installation_ypr_rad=None if nominal is None else _array(nominal, (3,)),
            heading_misalignment_rad=_float_or_none(c.get("heading_misalignment_rad")),
            heading_misalignment_se_rad=_float_or_none(c.get("heading_misalignment_se_rad")),
            compass_deviation_rad=dev, compass_deviation_centre=centre, compass_deviation_se_rad=dev_se,
            magnetic_declination_rad=_float_or_none(c.get("magnetic_declination_rad")),
            compass_error_rad=_float_or_none(c.get("compass_error_rad")),
            moving_bed=str((bed or {}).get("model", "off")) if isinstance(bed, dict) else "off",
            moving_bed_velocity_m_s=_vector_or_none(c.get("moving_bed_velocity_m_s")),
            moving_bed_velocity_se_m_s=_vector_or_none(c.get("moving_bed_velocity_se_m_s")),
            attitude_model=_attitude(c.get("attitude_model"), where),
            attitude_source=str(c.get("attitude_source") or "model"),
            noise_sigma=dict(c.get("noise_sigma") or {}),
            chi2_per_channel=dict(c.get("chi2_per_channel") or {}),
            timing=str(c.get("timing") or ""), formulation=str(c.get("formulation") or ""),
            success=solver.get("success") if isinstance(solver.get("success"), bool) else None,
            objective=_float_or_none(c.get("objective")),
            runs=runs, warnings=tuple(str(w) for w in c.get("warnings") or []),
            provenance=dict(c.get("provenance") or {}) if isinstance(c.get("provenance"), dict) else {},
            source=c.source, data=c,
            instrument=InstrumentIdentity.from_dict(c["instrument"]) if c.get("instrument") else None,
            site=Site.from_dict(c["site"]) if c.get("site") else None,
        )

    # ------------------------------------------------------------------ views
    def run_for(self, case_name: str) -> RunRecord | None:
        """The run of that case name, or None."""
        return next((r for r in self.runs if r.case == case_name), None)

    def moving_bed_for(self, case_name: str) -> np.ndarray | None:
        """The bed velocity (north, east) that applies to a case: its run's own, else the site's, else
        None (:func:`~adcpdyn.estimators.calibration.file.moving_bed_velocity`, the one lookup)."""
        return moving_bed_velocity(self.data, case_name)[0]

    def to_dict(self) -> Calibration:
        """The validated dict the estimators read (the parsed file)."""
        return self.data


def calibration_dict(calibration) -> Calibration | None:
    """The validated CALIB.json dict the estimators read, from any form a calibration is handed over in
    (:func:`~adcpdyn.estimators.calibration.file.as_calibration`), or None for None.

    Parameters
    ----------
    calibration : None, str, os.PathLike, dict, CalibrationResult or CalibrationRecord
        A CALIB.json path (read and validated; the dict's ``source`` is the path), a parsed
        file or ``CalibrationResult.to_dict()``, a result in memory, or a typed record.

    Raises
    ------
    ValueError
        One line naming the key, for an invalid file or dict; or naming ``calibration``
        for an object of another type.
    """
    return None if calibration is None else as_calibration(calibration)
