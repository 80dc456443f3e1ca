"""One correction method applied to one case, with the calibration's numbers checked."""

from __future__ import annotations

import dataclasses

import numpy as np

from ...cases.case import Case
from ..calibration.record import AppliedCalibration, CalibrationRecord

CORRECTION_METHODS = ("asc", "adc", "paper_literal", "rootfinder", "oracle")


def with_calibrated_depth(case: Case, applied: AppliedCalibration | None) -> tuple[Case, str]:
    """The case with the transducer depth its own calibration found from the slant ranges (the
    case's run of the calibration), and a note; unchanged without one."""
    offset = None if applied is None else applied.transducer_depth_offset_m
    if offset is None or not np.isfinite(offset) or offset == 0:
        return case, ""
    env = case.environment
    depth = env.transducer_depth_m + offset
    note = (f"transducer depth {env.transducer_depth_m:.3f} m -> {depth:.3f} m (offset {offset:+.3f} m the "
            "calibration found from the slant ranges)")
    return case.replace(environment=dataclasses.replace(env, transducer_depth_m=depth)), note


def with_moving_bed(result, bed: np.ndarray, source: str):
    """Bottom track measures the vessel over a moving bed: add the bed back to the vessel velocity
    and to water velocities referenced to it (not to those referenced to the GNSS, already over
    ground), and say so in its provenance."""
    offset = np.array([bed[0], bed[1], 0.0])
    water = result.water_velocity_m_s
    if water is not None and result.provenance.water_reference in (None, "bt"):
        water = water + offset
    provenance = result.provenance.replace(
        moving_bed_velocity_m_s=offset[:2],
        moving_bed_note=f"bed velocity from {source} added to the bottom-track vessel velocity (and to the water "
                        "velocities referenced to it): velocities are over ground")
    return dataclasses.replace(result, vessel_velocity_m_s=result.vessel_velocity_m_s + offset, water_velocity_m_s=water,
                               provenance=provenance)


def correct_case(case: Case, method: str, calibration: CalibrationRecord | None = None, timing: str = "deep",
                 reference: str = "bt"):
    """``asc`` (installation angles from the calibration for vessel-frame sensors; for a head
    sensor, its heading misalignment) or a dynamic method of
    :func:`~adcpdyn.estimators.correction.adc.dynamic_correction` with its ``timing``; then the moving bed
    the calibration found under this case added back (:meth:`CalibrationRecord.moving_bed_for`).
    Water cells are referenced to the bottom track or to the GNSS (``reference``: ``bt`` | ``gnss``,
    :mod:`adcpdyn.estimators.water`); what was applied (headings, bed, transducer depth) is in the
    result's ``provenance``.

    ``calibration``: the typed record (:func:`~adcpdyn.estimators.calibration.record.as_record`
    reads every other form once, where it enters), or None. What this run takes from it is
    resolved once, here (:meth:`~adcpdyn.estimators.calibration.record.CalibrationRecord.applied_to`)."""
    from ..water import check_reference

    check_reference(reference)
    if method not in CORRECTION_METHODS:
        raise ValueError(f"--method: expected one of {list(CORRECTION_METHODS)}, got {method!r}")
    applied = None if calibration is None or method == "oracle" else \
        calibration.applied_to(case, case.attitude.frame, dynamic=method != "asc")
    entered = float(case.environment.transducer_depth_m)
    case, depth_note = with_calibrated_depth(case, applied)
    result = _correct(case, method, applied, timing, reference)
    result = result.with_provenance(**heading_corrections_applied(applied), transducer_depth_entered_m=entered)
    if depth_note:
        result = result.with_provenance(transducer_depth_note=depth_note,
                                        transducer_depth_calibrated_m=float(case.environment.transducer_depth_m))
    if method == "oracle":
        bed, source = _true_bed(case)
    else:
        bed, source = (None, "") if applied is None else (applied.moving_bed_m_s, applied.moving_bed_source)
    return result if bed is None else with_moving_bed(result, bed, source)  # no bed: the provenance says none applied


def heading_corrections_applied(applied: AppliedCalibration | None) -> dict:
    """What a correction did to the headings, as :class:`~adcpdyn.cases.corrected.CorrectionProvenance`
    fields: the heading misalignment and compass deviation applied to a head sensor's readings (the
    misalignment holds the magnetic declination, which is not applied again), with the calibration's
    declination and compass error for the record."""
    if applied is None:
        return {"heading_misalignment_applied_rad": None, "heading_correction_note": "headings as recorded (no calibration)",
                "magnetic_declination_rad": None}
    if applied.heading_misalignment_rad is None:
        return {"heading_misalignment_applied_rad": None, "heading_correction_note": applied.heading_note,
                "magnetic_declination_rad": applied.magnetic_declination_rad}
    return {
        "heading_misalignment_applied_rad": applied.heading_misalignment_rad,
        "compass_deviation_applied_rad": applied.compass_deviation if applied.compass_deviation_found else None,
        "magnetic_declination_rad": applied.magnetic_declination_rad,
        "compass_error_rad": applied.compass_error_rad,
        "heading_correction_note": applied.heading_note,
    }


def _true_bed(case: Case) -> tuple[np.ndarray | None, str]:
    """The oracle's bed: the one the simulator moved (``/truth`` effects), if any."""
    effects = [] if case.truth is None else case.truth.effects
    beds = [e["params"] for e in effects if e.get("name") == "moving_bed"]
    if not beds:
        return None, ""
    return np.array([beds[0]["velocity_north_m_s"], beds[0]["velocity_east_m_s"]]), "/truth (the simulated bed)"


def _correct(case: Case, method: str, applied: AppliedCalibration | None, timing: str, reference: str = "bt"):
    from .adc import dynamic_correction, with_heading_misalignment
    from ..asc import asc

    if method == "asc":
        ypr, note = None, None
        if applied is not None and applied.static_installation_ypr_rad is not None:
            ypr = applied.static_installation_ypr_rad
            if not applied.static_installation_determined:
                note = (f"installation angles not determined by the calibration: its nominal angles "
                        f"{np.round(np.rad2deg(ypr), 3).tolist()} deg are used, as a static correction with the "
                        "configured alignment would; the Earth velocities carry the unknown installation error")
        result = asc(with_heading_misalignment(case, applied), ypr, water_reference=reference)
        if note:
            result = result.with_provenance(installation_note=note)
    else:
        result = dynamic_correction(case, method, applied, timing=timing, water_reference=reference)
    if not np.any(result.beams_used >= 3):
        raise ValueError(f"{case.name}: /pings/bt_radial_m_s: expected pings with at least 3 valid beams (a velocity "
                         f"needs 3), got none of {case.pings.n}")
    return result
