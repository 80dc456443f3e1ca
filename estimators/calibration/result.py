"""What a calibration returns: estimates with standard errors, the solver's own account, what
is not determined and why, per run; and its CALIB.json form (schema version 3).

Version 2 adds to version 1 (whose keys it keeps): ``schema_version``,
``moving_bed_velocity_m_s`` / ``_se_m_s`` (north, east; null when not estimated or not
determined), ``moving_bed`` (model, section knots), ``compass_deviation_rad`` / ``_se_rad``
({"sin": B, "cos": C}), ``magnetic_declination_rad``, ``compass_error_rad`` (misalignment
minus declination), ``standard_errors`` (method, lags, per-quantity inflation over white
noise, residual lag-1 autocorrelation per run and channel), ``confounded`` (pairs the data
cannot separate, in words) and ``runs`` (one entry per case). Version 3 adds whose it is:
``instrument`` (make, model, serial number, frequency, beam angle, beams, sensor frame) and
``site`` (the runs' mean position and UTC span), null where the runs do not say.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

import numpy as np

from ...cases.identity import InstrumentIdentity, Site
from ...models.motion import AttitudeParams
from ...solvers.multistart import MultistartResult
from ..statistics.uncertainty import Uncertainty

SCHEMA_VERSION = 3


def jsonable(obj):
    """Numbers and arrays as JSON values; NaN and infinities as null."""
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    return obj


def determined(values, se):
    """A number the data do not fix is not an estimate: null where its SE is not finite."""
    return np.where(np.isfinite(se), values, np.nan).tolist()


@dataclass
class RunResult:
    """One run of a (joint) calibration: the bed velocity that applies to it and its diagnostics."""

    case: str
    n_pings: int
    moving_bed_velocity_m_s: np.ndarray | None  # (2,) north, east (mean over its pings for a section bed)
    moving_bed_velocity_se_m_s: np.ndarray | None
    noise_sigma: dict
    chi2_per_channel: dict
    residual_lag1: dict
    attitude_source: str
    attitude_source_reason: str
    timing: str
    heading_deg: tuple  # circular mean and circular standard deviation of the sensor's heading
    attitude: AttitudeParams | None = None  # this run's motion model (the pre-fit when the beams used the samples)
    transducer_depth_offset_m: float | None = None  # what the slant ranges add to the case's transducer depth
    transducer_depth_offset_se_m: float | None = None
    velocity_knots_s: np.ndarray | None = None
    velocity_knots_m_s: np.ndarray | None = None
    navigation: str | None = None  # the run's vessel velocity: "knots" or "random_walk"
    attitude_interpolation: str | None = None  # the samples' ("spline" or "linear"); None with a motion model

    def to_dict(self) -> dict:
        bed, se = self.moving_bed_velocity_m_s, self.moving_bed_velocity_se_m_s
        out = {
            "case": self.case,
            "n_pings": self.n_pings,
            "moving_bed_velocity_m_s": None if bed is None else determined(bed, se),
            "moving_bed_velocity_se_m_s": None if se is None else se,
            "noise_sigma": self.noise_sigma,
            "chi2_per_channel": self.chi2_per_channel,
            "residual_lag1": self.residual_lag1,
            "attitude_source": self.attitude_source,
            "attitude_source_reason": self.attitude_source_reason,
            "timing": self.timing,
            "navigation": self.navigation,
            "attitude_interpolation": self.attitude_interpolation,
            "heading_deg": {"mean": self.heading_deg[0], "circular_sd": self.heading_deg[1]},
            "transducer_depth_offset_m": (self.transducer_depth_offset_m if self.transducer_depth_offset_se_m is not None
                                          and np.isfinite(self.transducer_depth_offset_se_m) else None),
            "transducer_depth_offset_se_m": self.transducer_depth_offset_se_m,
        }
        if self.velocity_knots_s is not None:
            out["velocity_model"] = {"knot_times_s": self.velocity_knots_s, "knot_velocities_m_s": self.velocity_knots_m_s}
        if self.attitude is not None:
            out["attitude_model"] = self.attitude.to_dict()
        return jsonable(out)


@dataclass
class CalibrationResult:
    """Estimates with standard errors, the solver's own account, and what is not determined.

    Shared unknowns (lever arms, installation angles or heading misalignment, compass
    deviation, moving bed) are top-level; ``runs`` holds each run's own. For one run the
    top-level ``noise_sigma``/``chi2_per_channel``/``velocity_knots_*`` are that run's.
    """

    radius_vectors_m: np.ndarray
    radius_vectors_se_m: np.ndarray
    installation_ypr_rad: np.ndarray
    installation_ypr_se_rad: np.ndarray
    installation_determined: bool
    attitude: AttitudeParams
    attitude_frame: str
    lever_arms_sensor_m: np.ndarray  # lever arms in the sensor frame (head frame for a head sensor)
    lever_arms_sensor_se_m: np.ndarray
    lever_arms_cov_m2: np.ndarray  # (12, 12) covariance of the sensor-frame lever arms (observable part)
    objective: float
    max_constraint_violation: float
    formulation: str
    timing: str
    noise_sigma: dict
    chi2_per_channel: dict
    multistart: MultistartResult
    uncertainty: Uncertainty
    x_names: list
    x: np.ndarray
    x_se: np.ndarray
    config: object
    velocity_knots_s: np.ndarray | None = None
    velocity_knots_m_s: np.ndarray | None = None
    # head sensor on a moving run: true heading = sensor heading + this (compass error, declination), found against the reference
    heading_misalignment_rad: float = float("nan")
    heading_misalignment_se_rad: float = float("inf")
    warnings: list = field(default_factory=list)
    jacobian: str = "symbolic"  # how the residual Jacobian was formed: symbolic or assembled per row
    # where the NLP's graph came from: "built" for this problem (and kept), "kept" (taken from a problem of the same
    # graph on other numbers: :mod:`..model_cache`), "assembled" (the numbers constants of a per-row Jacobian)
    graph: str = "built"
    attitude_source: str = "model"  # the beams' attitude: the fitted model or the sensor's samples
    attitude_source_reason: str = ""
    moving_bed: str = "off"  # off, constant or section
    moving_bed_velocity_m_s: np.ndarray | None = None  # (2,) north, east: the constant bed or the section's mean
    moving_bed_velocity_se_m_s: np.ndarray | None = None
    moving_bed_knots_m_s: np.ndarray | None = None  # (n, 2) section bed at positions linspace(0, 1, n)
    moving_bed_knots_se_m_s: np.ndarray | None = None
    compass_deviation_rad: np.ndarray | None = None  # (B, C): B (sin psi - mean_sin) + C (cos psi - mean_cos)
    compass_deviation_se_rad: np.ndarray | None = None
    compass_deviation_centre: tuple = (0.0, 0.0)  # (mean_sin, mean_cos) of the headings the deviation was fitted on
    magnetic_declination_rad: float | None = None
    magnetic_declination_note: str = ""
    standard_errors: dict = field(default_factory=dict)
    confounded: list = field(default_factory=list)
    runs: list = field(default_factory=list)
    # where it came from, for CALIB.json's ``provenance``: {"cases": [{"name", "path", "sha256"}, ...], ...}
    provenance: dict = field(default_factory=dict)
    instrument: InstrumentIdentity | None = None  # whose calibration it is (schema 3)
    site: Site | None = None  # the runs' mean position and UTC span
    moving_bed_test: dict | None = None  # --moving-bed auto: the bed's speed, SE, threshold and the decision
    # what the runs show on top of the calibration ({"effects", "unknowns", "navigation", "statement"}), None if not
    # diagnosed: held by a later diagnosis of these runs (estimators.diagnosis.own_effects)
    own_effects: dict | None = None

    @property
    def success(self) -> bool:
        return bool(self.multistart.success)

    @property
    def compass_error_rad(self) -> float | None:
        """Heading misalignment minus magnetic declination: what the compass itself gets wrong."""
        if self.magnetic_declination_rad is None or not np.isfinite(self.heading_misalignment_se_rad):
            return None
        return float(np.angle(np.exp(1j * (self.heading_misalignment_rad - self.magnetic_declination_rad))))

    def run_for(self, case_name: str) -> RunResult | None:
        return next((r for r in self.runs if r.case == case_name), None)

    def to_dict(self) -> dict:
        ms = self.multistart
        out = {
            "schema_version": SCHEMA_VERSION,
            "radius_vectors_m": determined(self.radius_vectors_m, self.radius_vectors_se_m),
            "radius_vectors_se_m": self.radius_vectors_se_m.tolist(),
            "installation_ypr_rad": determined(self.installation_ypr_rad, self.installation_ypr_se_rad),
            "installation_ypr_assumed_rad": self.installation_ypr_rad.tolist(),
            "installation_ypr_se_rad": self.installation_ypr_se_rad.tolist(),
            "installation_determined": self.installation_determined,
            "heading_misalignment_rad": (self.heading_misalignment_rad
                                         if np.isfinite(self.heading_misalignment_se_rad) else None),
            "heading_misalignment_se_rad": self.heading_misalignment_se_rad,
            "magnetic_declination_rad": self.magnetic_declination_rad,
            "magnetic_declination_note": self.magnetic_declination_note,
            "compass_error_rad": self.compass_error_rad,
            "compass_deviation_rad": None if self.compass_deviation_rad is None else
            {**dict(zip(("sin", "cos"), determined(self.compass_deviation_rad, self.compass_deviation_se_rad))),
             "mean_sin": self.compass_deviation_centre[0], "mean_cos": self.compass_deviation_centre[1]},
            "compass_deviation_se_rad": None if self.compass_deviation_se_rad is None else
            dict(zip(("sin", "cos"), self.compass_deviation_se_rad.tolist())),
            "moving_bed": {"model": self.moving_bed},
            "moving_bed_velocity_m_s": None if self.moving_bed_velocity_m_s is None else
            determined(self.moving_bed_velocity_m_s, self.moving_bed_velocity_se_m_s),
            "moving_bed_velocity_se_m_s": self.moving_bed_velocity_se_m_s,
            "attitude_frame": self.attitude_frame,
            "attitude_model": self.attitude.to_dict(),
            "attitude_source": self.attitude_source,
            "attitude_source_reason": self.attitude_source_reason,
            "objective": self.objective,
            "max_constraint_violation": self.max_constraint_violation,
            "formulation": self.formulation,
            "timing": self.timing,
            "noise_sigma": self.noise_sigma,
            "chi2_per_channel": self.chi2_per_channel,
            "standard_errors": self.standard_errors,
            "confounded": self.confounded,
            "solver": {
                "success": ms.success,
                "status": ms.status,
                "message": ms.message,
                "iterations": ms.iterations,
                "time_s": ms.time_s,
                "n_groups": ms.n_groups,
                "jacobian": self.jacobian,
                "graph": self.graph,
                "fraction_at_best": ms.fraction_at_best,
                "best_start": ms.best_start,
                "options": asdict(self.config.solver),
            },
            "starts": [s.to_dict() for s in ms.starts],
            "unobservable": self.uncertainty.unobservable,
            "parameters": {n: {"value": float(v) if np.isfinite(s) else None, "se": float(s)}
                           for n, v, s in zip(self.x_names, self.x, self.x_se)},
            "warnings": self.warnings,
            "config": {k: v for k, v in asdict(self.config).items() if k != "solver"},
            "runs": [r.to_dict() for r in self.runs],
            "provenance": provenance_block(self),
            "instrument": None if self.instrument is None else self.instrument.to_dict(),
            "site": None if self.site is None else self.site.to_dict(),
            "moving_bed_test": self.moving_bed_test,
            "own_effects": self.own_effects,
        }
        if self.moving_bed == "section":
            out["moving_bed"].update({"section_positions": np.linspace(0, 1, len(self.moving_bed_knots_m_s)).tolist(),
                                      "velocity_m_s": determined(self.moving_bed_knots_m_s, self.moving_bed_knots_se_m_s),
                                      "velocity_se_m_s": self.moving_bed_knots_se_m_s})
        if self.attitude_frame == "transducer" and np.isfinite(self.heading_misalignment_se_rad):
            # A head sensor's installation yaw against the reference is its heading misalignment: the
            # angle from the bottom-track course to the GNSS course (Qiao et al.'s Eq. 5 yaw); the
            # installation pitch and roll stay undetermined.
            out["installation_ypr_rad"][0] = self.heading_misalignment_rad
            out["installation_ypr_se_rad"][0] = self.heading_misalignment_se_rad
            out["installation_yaw_is"] = "heading_misalignment (head sensor: course of bottom track -> course of the reference)"
        if self.attitude_frame == "transducer":
            out["radius_vectors_head_m"] = determined(self.lever_arms_sensor_m, self.lever_arms_sensor_se_m)
            out["radius_vectors_head_se_m"] = self.lever_arms_sensor_se_m.tolist()
        if self.velocity_knots_s is not None:
            out["velocity_model"] = {"knot_times_s": self.velocity_knots_s.tolist(),
                                     "knot_velocities_m_s": self.velocity_knots_m_s.tolist()}
        return jsonable(out)

    def to_json(self, path) -> None:
        """Write CALIB.json atomically, its ``provenance`` stamped with the UTC time of writing."""
        import datetime as dt

        from ...cases.atomic import atomic_path

        d = self.to_dict()
        d["provenance"]["written_utc"] = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        with atomic_path(path) as tmp:
            with open(tmp, "w") as fh:
                json.dump(d, fh, indent=2)

    @classmethod
    def from_json(cls, path):
        """Read a CALIB.json back as a typed, read-only record.

        Returns a :class:`~adcpdyn.estimators.calibration.record.CalibrationRecord`, not a
        ``CalibrationResult``: a CALIB.json holds the estimates, their standard errors, the
        attitude model and source, the noise levels, each run's bed and the provenance (all
        typed on the record), but not the solver's objects (multistart, uncertainty,
        configuration dataclass) a full result carries, so none is rebuilt. The record is
        accepted wherever a calibration is (``adcpdyn.correct``, ``adcpdyn.diagnose``, ...).

        Raises
        ------
        ValueError
            One line naming the file and the key (an unreadable or invalid file).
        """
        from .record import CalibrationRecord

        return CalibrationRecord.from_json(path)


def provenance_block(result) -> dict:
    """CALIB.json's ``provenance``: the adcpdyn version and what the result says it came from."""
    from ...cases.hashing import adcpdyn_version

    cases = result.provenance.get("cases") or [{"name": r.case} for r in result.runs]
    return jsonable({"adcpdyn_version": adcpdyn_version(), **result.provenance, "cases": cases})
