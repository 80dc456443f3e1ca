"""One correction method applied to one case, with the calibration's numbers checked."""

from __future__ import annotations

import numpy as np

from ..cases.case import Case

CORRECTION_METHODS = ("asc", "adc", "paper_literal", "rootfinder", "oracle")


def installation_from(calibration: dict) -> np.ndarray:
    """Installation angles of a CALIB.json, or a one-line error naming the field."""
    from .calibration_file import installation_angles

    return installation_angles(calibration)


def assumed_installation(calibration: dict) -> np.ndarray:
    """The nominal installation angles of the calibration's configuration (the mounting as set up)."""
    from .calibration_file import nominal_installation

    return nominal_installation(calibration)


def correct_case(case: Case, method: str, calibration: dict | None, timing: str = "deep"):
    """``asc`` (installation angles from the calibration for vessel-frame sensors; for a head
    sensor, its heading misalignment) or a dynamic method of
    :func:`~adcpdyn.estimators.adc.dynamic_correction` with its ``timing``."""
    from .adc import dynamic_correction, with_heading_misalignment
    from .asc import asc

    from .calibration_file import as_calibration

    if method not in CORRECTION_METHODS:
        raise ValueError(f"--method: expected one of {list(CORRECTION_METHODS)}, got {method!r}")
    if calibration is not None:
        calibration = as_calibration(calibration)
    if method == "asc":
        ypr, note = None, None
        if calibration is not None and case.attitude.frame == "vessel":
            try:
                ypr = installation_from(calibration)
            except ValueError:
                ypr = assumed_installation(calibration)
                note = (f"installation angles not determined by the calibration: its nominal angles "
                        f"{np.round(np.rad2deg(ypr), 3).tolist()} deg are used, as a static correction with the "
                        "configured alignment would; the Earth velocities carry the unknown installation error")
        result = asc(with_heading_misalignment(case, calibration), ypr)
        if note:
            result.attrs["installation_note"] = note
    else:
        result = dynamic_correction(case, method, calibration, timing=timing)
    if not np.any(result.beams_used >= 3):
        raise ValueError(f"{case.name}: /pings/bt_radial_m_s: expected pings with at least 3 valid beams (a velocity "
                         f"needs 3), got none of {case.pings.n}")
    return result
