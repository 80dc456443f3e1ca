"""A CALIB.json as a typed, read-only record: what every reader of a calibration uses.

A calibration is read once, where it enters (the API, the command line, a batch job), by
:func:`as_record`, from any form it is handed over in (a CALIB.json path, a parsed dict, a
:class:`~adcpdyn.estimators.calibration.result.CalibrationResult`, a record); the corrections,
the diagnosis and the netCDF writer read its typed fields and methods (the bed of a run, the
lever arms in a frame, the installation angles with their fallback, the heading correction),
never the file's keys. Numbers are in SI units, NaN or ``None`` where the file says "not
determined" (``null``), and a method refuses in one line naming the key only when its reader
needs a value the file does not determine.

It is a view of a validated file (:mod:`.file`), not a rebuilt ``CalibrationResult``: the
solver's per-start table, the uncertainty object and the configuration dataclass are not in
a CALIB.json in a form worth rebuilding; the parsed file stays available (:attr:`data`).
Imports run one way: file <- record <- result.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ...cases.case import parse_utc
from ...cases.identity import InstrumentIdentity, Site, site_of
from .file import Calibration, calibration_from_dict, read_calibration, source_prefix

__all__ = ["AppliedCalibration", "CalibrationRecord", "RunRecord", "as_record"]


def _array(value, shape) -> np.ndarray:
    """A float array from JSON (null -> NaN); all NaN when the whole value is null."""
    if value is None:
        return np.full(shape, np.nan)
    return np.array(_nan_for_none(value), dtype=float).reshape(shape)


def _array_if_present(c: dict, key: str, shape) -> np.ndarray | None:
    """:func:`_array` of a key, None when the file does not hold the key."""
    return _array(c[key], shape) if key in c else None


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


def _sin_cos(value) -> tuple | None:
    """(sin, cos) of a compass deviation object, NaN for a component not determined; None without one."""
    if not value:
        return None
    return tuple(np.nan if value.get(k) is None else float(value[k]) for k in ("sin", "cos"))


def _attitude(value):
    """The attitude model of a validated file (its shape checked there), or None."""
    from ...models.motion import AttitudeParams  # CasADi: loaded when a file holds a model

    return AttitudeParams.from_dict(value) if value else None


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
    transducer_depth_offset_se_m: float | None = None
    navigation: str | None = None  # "knots" | "random_walk"; None in files older than it
    attitude_interpolation: str | None = None  # the samples' "spline" | "linear"; None: a model or an older file


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
    radius_vectors_m, radius_vectors_se_m : ndarray (4, 3) or None
        Lever arms in the body (vessel) frame; None when the file has none.
    radius_vectors_head_m, radius_vectors_head_se_m : ndarray (4, 3) or None
        Lever arms in the head frame (a head sensor's calibration); None when the file has none.
    installation_ypr_rad, installation_ypr_se_rad : ndarray (3,)
        Installation yaw, pitch, roll (for a head sensor on a moving run the yaw is the
        heading misalignment, pitch and roll NaN).
    installation_determined : bool
    nominal_installation_ypr_rad : ndarray (3,) or None
        The mounting as configured (``config.nominal_installation_ypr_rad``).
    heading_misalignment_rad, heading_misalignment_se_rad : float or None
        True heading = sensor heading + misalignment (+ compass deviation).
    compass_deviation_rad : tuple (B, C) or None
        B (sin psi - mean_sin) + C (cos psi - mean_cos), NaN for a coefficient not
        determined; ``compass_deviation_centre`` holds (mean_sin, mean_cos).
    magnetic_declination_rad, compass_error_rad : float or None
    moving_bed : str
        ``off``, ``constant`` or ``section`` (``constant`` for a bed velocity without a model,
        ``off`` when the file has no bed).
    moving_bed_velocity_m_s, moving_bed_velocity_se_m_s : ndarray (2,) or None
        The site's bed (north, east), None unless both components are determined; each run's
        own is in ``runs``; :meth:`moving_bed_for` is the one lookup.
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
    source_sha256 : str or None
        That file's SHA-256 when it was read (None when built in memory).
    data : Calibration
        The validated file itself (for display; the readers use the typed fields).
    """

    schema_version: int
    attitude_frame: str
    lever_arms_m: np.ndarray
    lever_arms_se_m: np.ndarray
    radius_vectors_m: np.ndarray | None
    radius_vectors_se_m: np.ndarray | None
    radius_vectors_head_m: np.ndarray | None
    radius_vectors_head_se_m: np.ndarray | None
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
    source_sha256: str | None = None
    own_effects: dict | None = None  # what these runs showed on top of the calibration: held when they are diagnosed

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_json(cls, path) -> "CalibrationRecord":
        """Read, validate (:func:`~adcpdyn.estimators.calibration.file.read_calibration`) and type a CALIB.json.

        Raises
        ------
        ValueError
            One line naming the file and the key (see ``read_calibration``).
        """
        from ...cases.hashing import sha256_of

        return cls.typed(read_calibration(path), sha256_of(path))

    @classmethod
    def from_dict(cls, d) -> "CalibrationRecord":
        """Type a parsed CALIB.json (validated first unless it already is a ``Calibration``:
        :func:`~adcpdyn.estimators.calibration.file.calibration_from_dict`)."""
        return cls.typed(calibration_from_dict(d))

    @classmethod
    def typed(cls, c: Calibration, source_sha256: str | None = None) -> "CalibrationRecord":
        """The record of a validated calibration (``read_calibration`` or ``calibration_from_dict``), with
        the SHA-256 of the file it was read from."""
        frame = c.get("attitude_frame") or "vessel"
        head_key = "radius_vectors_head_m" if frame == "transducer" and "radius_vectors_head_m" in c else "radius_vectors_m"
        head_se = "radius_vectors_head_se_m" if head_key == "radius_vectors_head_m" else "radius_vectors_se_m"
        deviation = c.get("compass_deviation_rad") or {}
        centre = tuple(0.0 if deviation.get(k) is None else float(deviation[k]) for k in ("mean_sin", "mean_cos"))
        bed = c.get("moving_bed")
        bed_model = bed.get("model") if isinstance(bed, dict) else None
        nominal = (c.get("config") or {}).get("nominal_installation_ypr_rad")
        runs = tuple(RunRecord(
            case=str(r["case"]), n_pings=r.get("n_pings"),
            moving_bed_velocity_m_s=_vector_or_none(r.get("moving_bed_velocity_m_s")),
            moving_bed_velocity_se_m_s=_vector_or_none(r.get("moving_bed_velocity_se_m_s")),
            attitude_source=r.get("attitude_source"),
            attitude_model=_attitude(r.get("attitude_model")),
            transducer_depth_offset_m=_float_or_none(r.get("transducer_depth_offset_m")),
            transducer_depth_offset_se_m=_float_or_none(r.get("transducer_depth_offset_se_m")),
            noise_sigma=dict(r.get("noise_sigma") or {}), chi2_per_channel=dict(r.get("chi2_per_channel") or {}),
            navigation=r.get("navigation"), attitude_interpolation=r.get("attitude_interpolation"),
        ) for r in c.get("runs") or [])
        solver = c.get("solver") or {}
        return cls(
            schema_version=int(c.get("schema_version", 1)),
            attitude_frame=frame,
            lever_arms_m=_array(c.get(head_key), (4, 3)),
            lever_arms_se_m=_array(c.get(head_se), (4, 3)),
            radius_vectors_m=_array_if_present(c, "radius_vectors_m", (4, 3)),
            radius_vectors_se_m=_array_if_present(c, "radius_vectors_se_m", (4, 3)),
            radius_vectors_head_m=_array_if_present(c, "radius_vectors_head_m", (4, 3)),
            radius_vectors_head_se_m=_array_if_present(c, "radius_vectors_head_se_m", (4, 3)),
            installation_ypr_rad=_array(c.get("installation_ypr_rad"), (3,)),
            installation_ypr_se_rad=_array(c.get("installation_ypr_se_rad"), (3,)),
            installation_determined=bool(c.get("installation_determined", False)),
            nominal_installation_ypr_rad=None if nominal is None else _array(nominal, (3,)),
            heading_misalignment_rad=_float_or_none(c.get("heading_misalignment_rad")),
            heading_misalignment_se_rad=_float_or_none(c.get("heading_misalignment_se_rad")),
            compass_deviation_rad=_sin_cos(c.get("compass_deviation_rad")), compass_deviation_centre=centre,
            compass_deviation_se_rad=_sin_cos(c.get("compass_deviation_se_rad")),
            magnetic_declination_rad=_float_or_none(c.get("magnetic_declination_rad")),
            compass_error_rad=_float_or_none(c.get("compass_error_rad")),
            moving_bed=str(bed_model) if bed_model else "constant" if c.get("moving_bed_velocity_m_s") else "off",
            moving_bed_velocity_m_s=_vector_or_none(c.get("moving_bed_velocity_m_s")),
            moving_bed_velocity_se_m_s=_vector_or_none(c.get("moving_bed_velocity_se_m_s")),
            attitude_model=_attitude(c.get("attitude_model")),
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
            site=Site.from_dict(c["site"]) if c.get("site") else None, source_sha256=source_sha256,
            own_effects=c.get("own_effects") or None,
        )

    # ------------------------------------------------------------------ what the readers use
    def _refuse(self, text: str) -> ValueError:
        return ValueError(f"{source_prefix(self.source)}{text}")

    def run_for(self, case_name: str) -> RunRecord | None:
        """The run of that case name, or None."""
        return next((r for r in self.runs if r.case == case_name), None)

    def run_of(self, case) -> RunRecord | None:
        """The run of the calibration a case is: by its name, else, for a one-run calibration, a case
        whose pings lie within the calibration's UTC span (the same run written again under another
        name, e.g. with an error injected); None otherwise."""
        own = self.run_for(case.name)
        if own is None and len(self.runs) == 1 and self.spans(case):
            return self.runs[0]
        return own

    def holds(self, case) -> bool:
        """Whether a case is one of the calibration's runs: by name, or its pings within the UTC span
        of the calibration's runs."""
        return self.run_for(case.name) is not None or self.spans(case)

    def spans(self, case) -> bool:
        """Whether a case's pings lie within the UTC span of the calibration's runs (one ping
        interval of slack at each end); False without UTC times on either side."""
        if self.site is None or not (self.site.start_utc and self.site.end_utc) or not case.time_origin_utc:
            return False
        own = site_of([case])
        slack = float(np.median(np.diff(case.pings.time_s))) if case.pings.n > 1 else 0.0
        start, end = ((parse_utc(b) - parse_utc(a)).total_seconds()
                      for a, b in ((self.site.start_utc, own.start_utc), (own.end_utc, self.site.end_utc)))
        return start >= -slack and end >= -slack

    def _own(self, case) -> RunRecord | None:
        """A case's run: :meth:`run_of` for a case, :meth:`run_for` for a case name."""
        return self.run_for(case) if isinstance(case, str) else self.run_of(case)

    def moving_bed_for(self, case) -> tuple[np.ndarray | None, str]:
        """The bed velocity (north, east) under a case's pings (``case``: the case, matched by
        :meth:`run_of`, or its name), and where it came from: the case's own run when both its
        components are determined, else the site's bed when both of its are, else ``(None, "")``.
        The one bed lookup: never a half-determined (NaN) bed."""
        own = self._own(case)
        if own is not None and own.moving_bed_velocity_m_s is not None:
            return own.moving_bed_velocity_m_s, f"run {own.case!r} of the calibration"
        if self.moving_bed_velocity_m_s is None:
            return None, ""
        why = "this case is not one of its runs" if own is None else "this run's own is not determined"
        return self.moving_bed_velocity_m_s, f"the calibration's site bed ({why})"

    def lever_arms_in(self, frame: str, purpose: str = "this calibration cannot correct") -> np.ndarray:
        """The (4, 3) lever arms in an attitude sensor's frame: the head frame for a head sensor
        (``frame="transducer"``), else the body frame; a one-line error naming the key when the
        file has none or any is not determined (null)."""
        key = "radius_vectors_head_m" if frame == "transducer" else "radius_vectors_m"
        arms = self.radius_vectors_head_m if frame == "transducer" else self.radius_vectors_m
        if arms is None:
            raise self._refuse(f"{key}: missing; expected the output of `adcpdyn calibrate` ({purpose})")
        if not np.all(np.isfinite(arms)):
            raise self._refuse(f"{key}: contains undetermined (null) values; {purpose}")
        return arms.copy()

    def installation(self) -> np.ndarray:
        """The installation (yaw, pitch, roll) in radians, or a one-line error when missing or not determined."""
        if not np.all(np.isfinite(self.installation_ypr_rad)):
            raise self._refuse("installation_ypr_rad: missing or not determined; expected 3 angles in radians")
        return self.installation_ypr_rad.copy()

    def installation_or_nominal(self) -> tuple[np.ndarray, bool]:
        """The installation angles to turn the beams by, and whether the calibration determined them:
        the calibrated ones, else the nominal ones of its configuration (the mounting as set up);
        a one-line error when neither is known."""
        if np.all(np.isfinite(self.installation_ypr_rad)):
            return self.installation_ypr_rad.copy(), True
        nominal = self.nominal_installation_ypr_rad
        if nominal is None or not np.all(np.isfinite(nominal)):
            raise self._refuse("installation_ypr_rad is not determined and config.nominal_installation_ypr_rad is "
                               "missing; expected 3 angles in radians")
        return nominal.copy(), False

    def applied_to(self, case, sensor_frame: str, dynamic: bool) -> AppliedCalibration:
        """Everything the correction of one run (``case``: the case, or its name) takes from this
        calibration, resolved at once: the run's bed and depth offset, the heading correction of a
        head sensor, and the installation and lever arms the method needs (``dynamic``: the dynamic
        methods' lever arms and beam rotation; else the static correction's installation angles,
        for a vessel-frame sensor), each refused in one line here when the file does not determine it."""
        head = sensor_frame == "transducer"
        static, determined = (self.installation_or_nominal() if not head and not dynamic else (None, False))
        if dynamic:
            lever = self.lever_arms_in("transducer" if head else "vessel")
            beams = np.zeros(3) if head else self.installation()
        else:
            lever, beams = None, None
        delta = self.heading_misalignment_rad if head else None
        note = ("true heading = recorded heading + heading misalignment (+ compass deviation): the misalignment holds the "
                "magnetic declination, not applied separately" if delta is not None else
                "headings as recorded (vessel-frame attitude: installation angles instead)" if not head else
                "headings as recorded (the calibration has no heading misalignment)")
        own = self._own(case)
        bed, source = self.moving_bed_for(case)
        return AppliedCalibration(
            lever_arms_sensor_m=lever, beam_installation_ypr_rad=beams,
            static_installation_ypr_rad=static, static_installation_determined=determined, heading_misalignment_rad=delta,
            heading_note=note, compass_deviation=self.compass_deviation_applied(),
            compass_deviation_found=self.compass_deviation_rad is not None,
            magnetic_declination_rad=self.magnetic_declination_rad, compass_error_rad=self.compass_error_rad,
            nominal_installation_ypr_rad=self.nominal_installation_ypr_rad, attitude_source=self.attitude_source,
            transducer_depth_offset_m=None if own is None else own.transducer_depth_offset_m, moving_bed_m_s=bed,
            moving_bed_source=source, attitude_interpolation=self.sample_interpolation())

    def sample_interpolation(self) -> str | None:
        """How the calibration's runs joined the sensor's samples (``spline`` or ``linear``) where they
        all agree, None where none recorded it or they differ: a property of the sensor's sampling
        against the boat's motion, so runs corrected or diagnosed with this calibration take it too
        (a diagnosis's injected tilt low-pass must not change the recipe the calibration used)."""
        used = {r.attitude_interpolation for r in self.runs if r.attitude_interpolation is not None}
        return used.pop() if len(used) == 1 else None

    def compass_deviation_applied(self) -> tuple[float, float, float, float]:
        """(B, C, mean_sin, mean_cos) of the one-cycle compass deviation a head sensor's headings are
        corrected by (:func:`~adcpdyn.models.sensors.compass_correction`): a coefficient not
        determined (null) or absent is 0, the others are applied."""
        deviation = self.compass_deviation_rad or (0.0, 0.0)
        return (*(float(v) if np.isfinite(v) else 0.0 for v in deviation), *self.compass_deviation_centre)


@dataclass(frozen=True, eq=False)
class AppliedCalibration:
    """What a calibration gives the correction of one run, resolved once where the correction
    starts (:meth:`CalibrationRecord.applied_to`): the correction reads these fields and never goes
    back to the record. Angles in radians, lengths in metres, velocities in m/s.

    Attributes
    ----------
    lever_arms_sensor_m : ndarray (4, 3) or None
        Lever arms in the sensor's frame (dynamic methods; None for the static correction).
    beam_installation_ypr_rad : ndarray (3,) or None
        Rotation of the beams into the sensor's frame (zero for a head sensor; dynamic methods).
    static_installation_ypr_rad : ndarray (3,) or None
        The static correction's installation angles (vessel-frame sensor; None otherwise), and
        ``static_installation_determined``: calibrated (True) or the configured mounting (False).
    heading_misalignment_rad : float or None
        Applied to a head sensor's heading readings; None for a vessel-frame sensor or when the
        calibration has none (``heading_note`` says which).
    compass_deviation : tuple
        (B, C, mean_sin, mean_cos) applied with the misalignment (undetermined coefficients 0).
    compass_deviation_found : bool
        Whether the calibration has a compass deviation (for the provenance).
    magnetic_declination_rad, compass_error_rad : float or None
    nominal_installation_ypr_rad : ndarray (3,) or None
    attitude_source : str
        ``model`` or ``samples``: what the calibration's beams used.
    transducer_depth_offset_m : float or None
        The run's depth offset found from the slant ranges (None or 0: none).
    moving_bed_m_s : ndarray (2,) or None
        The bed under the run (:meth:`CalibrationRecord.moving_bed_for`) and ``moving_bed_source``.
    attitude_interpolation : str or None
        How the calibration's runs joined the attitude samples (:meth:`CalibrationRecord.sample_interpolation`).
    """

    lever_arms_sensor_m: np.ndarray | None
    beam_installation_ypr_rad: np.ndarray | None
    static_installation_ypr_rad: np.ndarray | None
    static_installation_determined: bool
    heading_misalignment_rad: float | None
    heading_note: str
    compass_deviation: tuple
    compass_deviation_found: bool
    magnetic_declination_rad: float | None
    compass_error_rad: float | None
    nominal_installation_ypr_rad: np.ndarray | None
    attitude_source: str
    transducer_depth_offset_m: float | None
    moving_bed_m_s: np.ndarray | None
    moving_bed_source: str
    attitude_interpolation: str | None = None


def as_record(calibration) -> CalibrationRecord | None:
    """The one conversion of a calibration where it enters (API, command line, batch job): a
    record as it is, a CALIB.json path read and validated, a parsed dict or
    ``CalibrationResult.to_dict()`` (any object with ``to_dict()``) validated; None for None.

    Parameters
    ----------
    calibration : None, str, os.PathLike, dict, CalibrationResult or CalibrationRecord

    Raises
    ------
    ValueError
        One line naming the file and the key, for an invalid file or dict; or naming
        ``calibration`` for an object of another type.
    """
    if calibration is None or isinstance(calibration, CalibrationRecord):
        return calibration
    if isinstance(calibration, (str, os.PathLike)):
        return CalibrationRecord.from_json(calibration)
    if not isinstance(calibration, dict) and callable(getattr(calibration, "to_dict", None)):
        calibration = calibration.to_dict()
    if not isinstance(calibration, dict):
        raise ValueError(f"calibration: expected a CALIB.json path, a dict, a CalibrationResult or a CalibrationRecord, "
                         f"got {type(calibration).__name__}")
    return CalibrationRecord.from_dict(calibration)
