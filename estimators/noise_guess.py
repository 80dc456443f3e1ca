"""Noise levels to start from, measured without the model: the bottom track's error velocity,
the reference's first differences, the attitude pre-fit's residuals (the fit re-estimates them)."""

from __future__ import annotations

import numpy as np
from scipy.stats import median_abs_deviation

from ..cases.case import Case
from ..models.janus import error_velocity
from .attitude_fit import AttitudeFit


def bt_noise_from_error_velocity(case: Case) -> float:
    """Beam noise from the error velocity (immune to rigid motion): robust MAD estimate."""
    err, norm = error_velocity(case.pings.bt_radial_m_s, case.instrument.beam_directions())
    err = err[np.isfinite(err)]
    if err.size < 5:
        return 0.01
    return float(max(median_abs_deviation(err, scale="normal") / norm, 1e-4))


def reference_noise_from_differences(time_s, velocity_m_s) -> float:
    """Reference velocity noise from first differences (white noise: sd(diff) = sqrt 2 sigma),
    robust MAD over the horizontal axes; an upper bound when the vessel accelerates."""
    v = np.asarray(velocity_m_s, dtype=float)[:, :2]
    d = np.diff(v, axis=0)
    d = d[np.all(np.isfinite(d), axis=1)].ravel()
    if d.size < 10:
        return 0.02
    return float(max(median_abs_deviation(d, scale="normal") / np.sqrt(2), 1e-3))


def range_noise_from_differences(slant_range_m) -> float:
    """Slant-range noise from each beam's ping-to-ping first differences (robust MAD over sqrt 2,
    the median over the beams): the bed's own relief between pings counts as noise, so an upper
    bound on a rough bed; 2 cm without enough ranges."""
    d = np.diff(np.asarray(slant_range_m, dtype=float), axis=0)
    per_beam = [median_abs_deviation(c, scale="normal") / np.sqrt(2)
                for c in (col[np.isfinite(col)] for col in d.T) if c.size >= 10]
    return float(max(np.median(per_beam), 1e-3)) if per_beam else 0.02


def initial_noise(case: Case, fit: AttitudeFit | None, with_attitude: bool) -> dict:
    """Independent noise levels to start from: attitude pre-fit residuals, the bottom track's
    error velocity, the reference's and the slant ranges' first differences."""
    ranges = case.pings.bt_range_m
    s = {"bt": bt_noise_from_error_velocity(case),
         "range": 0.02 if ranges is None else range_noise_from_differences(ranges)}
    if with_attitude and fit is not None:
        s.update(heading=max(fit.sigmas[0], 1e-4), pitch=max(fit.sigmas[1], 1e-4), roll=max(fit.sigmas[2], 1e-4))
    ref = case.reference
    if ref is not None and ref.time_s is not None and ref.velocity_m_s is not None:
        s["reference"] = reference_noise_from_differences(ref.time_s, ref.velocity_m_s)
    return s
