"""One correction method applied to one case, with the calibration's numbers checked."""

from __future__ import annotations

import numpy as np

from ..cases.case import Case

CORRECTION_METHODS = ("asc", "adc", "paper_literal", "rootfinder", "oracle")


def installation_from(calibration: dict) -> np.ndarray:
    """Installation angles of a CALIB.json, or a one-line error naming the field."""
    value = calibration.get("installation_ypr_rad")
    if value is None or any(v is None for v in value):
        raise ValueError("calibration: installation_ypr_rad: missing or not determined; expected 3 angles in radians")
    return np.asarray(value, dtype=float)


def correct_case(case: Case, method: str, calibration: dict | None, timing: str = "deep"):
    """``asc`` (installation angles from the calibration for vessel-frame sensors; for a head
    sensor, its heading misalignment) or a dynamic method of
    :func:`~adcpdyn.estimators.adc.dynamic_correction` with its ``timing``."""
    from .adc import dynamic_correction, with_heading_misalignment
    from .asc import asc

    if method not in CORRECTION_METHODS:
        raise ValueError(f"--method: expected one of {list(CORRECTION_METHODS)}, got {method!r}")
    if method == "asc":
        ypr = None
        if calibration is not None and case.attitude.frame == "vessel":
            ypr = installation_from(calibration)
        return asc(with_heading_misalignment(case, calibration), ypr)
    return dynamic_correction(case, method, calibration, timing=timing)
