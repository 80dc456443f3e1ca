"""Whether the bed moves, decided by the data: the calibration's bed velocity tested for
significance with its standard errors, and against QRev's practical threshold (a bed slower
than 1 % of the mean flow or than 0.012 m/s is not corrected for).

``--moving-bed auto`` fits a constant bed first and keeps it only when the test says it moves;
otherwise the calibration is solved again without it, so a ship over a fixed seabed keeps its
precision. A bed the runs cannot tell from a heading error (one course) is ``undetermined``:
dropped too, with a warning that a moving one would then sit in the heading.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

MIN_SPEED_M_S = 0.012  # QRev's moving-bed threshold (loop and stationary tests)
FLOW_SHARE = 0.01  # ... and 1 % of the mean water speed
SIGNIFICANCE = 0.01  # chi-square (2 dof) test of the bed velocity against zero


def mean_flow_speed(cases) -> float | None:
    """Mean horizontal water speed over the runs' valid cells (static correction, bottom-track
    referenced), or None without a water profile."""
    from ..asc import asc

    speeds = []
    for case in cases:
        if case.water is None:
            continue
        w = asc(case).water_velocity_m_s
        if w is not None:
            s = np.hypot(w[..., 0], w[..., 1])
            speeds.append(s[np.isfinite(s)])
    speeds = np.concatenate(speeds) if speeds else np.zeros(0)
    return float(np.mean(speeds)) if speeds.size else None


def moving_bed_test(velocity_m_s, se_m_s, confounded: bool, flow_m_s: float | None) -> dict:
    """The decision on a fitted constant bed (north, east) with its standard errors: ``moving``
    (significant at ``SIGNIFICANCE`` and above the practical threshold), ``undetermined`` (not
    determined, or not separable from a heading error) or ``fixed``; with the figures behind it."""
    threshold = max(MIN_SPEED_M_S, FLOW_SHARE * flow_m_s) if flow_m_s else MIN_SPEED_M_S
    out = {"speed_m_s": None, "speed_se_m_s": None, "chi2": None, "p_value": None, "threshold_m_s": threshold,
           "mean_flow_m_s": flow_m_s, "percent_of_flow": None}
    v = None if velocity_m_s is None else np.asarray(velocity_m_s, dtype=float)
    se = None if se_m_s is None else np.asarray(se_m_s, dtype=float)
    if v is None or se is None or not np.all(np.isfinite(se)) or not np.all(se > 0):
        return {**out, "decision": "undetermined", "reason": "the runs do not determine the bed velocity"}
    speed = float(np.hypot(*v))
    speed_se = float(np.hypot(v[0] * se[0], v[1] * se[1]) / speed) if speed > 0 else float(np.max(se))
    chi2 = float(np.sum((v / se) ** 2))
    p = float(stats.chi2.sf(chi2, 2))
    out.update(speed_m_s=speed, speed_se_m_s=speed_se, chi2=chi2, p_value=p,
               percent_of_flow=100 * speed / flow_m_s if flow_m_s else None)
    share = f" ({out['percent_of_flow']:.1f} % of the mean flow {flow_m_s:.2f} m/s)" if flow_m_s else ""
    rule = (f"the larger of {MIN_SPEED_M_S} m/s and {100 * FLOW_SHARE:g} % of the mean flow" if flow_m_s else
            f"{MIN_SPEED_M_S} m/s; no water profile gives the mean flow")
    if p < SIGNIFICANCE and speed > threshold:
        return {**out, "decision": "moving", "reason": f"{speed:.3f} +- {speed_se:.3f} m/s{share}: significant "
                                                       f"(p = {p:.1g}) and above the threshold {threshold:.3f} m/s ({rule})"}
    if confounded:
        return {**out, "decision": "undetermined", "reason": "the bed and a constant heading error turn the bottom track "
                                                             "alike on these courses"}
    why = (f"not significant (p = {p:.2g})" if p >= SIGNIFICANCE else
           f"below the threshold {threshold:.3f} m/s ({rule})")
    return {**out, "decision": "fixed", "reason": f"{speed:.3f} +- {speed_se:.3f} m/s{share}: {why}"}
