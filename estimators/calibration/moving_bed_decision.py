"""Whether the bed moves, decided by the data: the calibration's bed velocity tested for
significance with its standard errors, against QRev's practical threshold (a bed slower
than 1 % of the mean flow or than 0.012 m/s is not corrected for), and against the flow's
direction (a bed moves with the near-bed flow: QRev's loop test rejects a closure error that
does not point upstream).

``--moving-bed auto`` fits a constant bed first and keeps it only when the test says it moves;
otherwise the calibration is solved again without it, so a ship over a fixed seabed keeps its
precision. A bed the runs cannot tell from a heading error (one course) is ``undetermined``, and
one that would move against the flow is ``against_flow`` (on one course a heading error of either
sign looks like a bed, upstream or downstream): both dropped too, with a warning that a moving one
would then sit in the heading.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

MIN_SPEED_M_S = 0.012  # QRev's moving-bed threshold (loop and stationary tests)
FLOW_SHARE = 0.01  # ... and 1 % of the mean water speed
SIGNIFICANCE = 0.01  # chi-square (2 dof) test of the bed velocity against zero
MAX_FROM_FLOW_RAD = np.deg2rad(45.0)  # QRev's loop test: the closure error within 135-225 deg of the flow
DIRECTION_Z = 2.0  # ... by more than this many standard errors of the bed's direction


def mean_flow(cases, installation_ypr_rad=None, heading_correction_rad: float = 0.0) -> dict | None:
    """The runs' flow over their valid cells (static correction, bottom-track referenced), in the
    true Earth frame: ``speed_m_s`` the mean horizontal water speed, ``direction_rad`` the direction
    of the mean water velocity (QRev's flow direction, clockwise from north); None without a water
    profile. ``installation_ypr_rad`` turns a vessel-frame sensor's beams (a head sensor's turn with
    the head: the static correction takes them for a vessel frame only), ``heading_correction_rad``
    (a head sensor's heading misalignment) turns every sensed heading into a true one."""
    from ..asc import asc

    speeds, vectors = [], []
    for case in cases:
        if case.water is None:
            continue
        w = asc(case, installation_ypr_rad).water_velocity_m_s
        if w is None:
            continue
        horizontal = w[..., :2].reshape(-1, 2)
        horizontal = horizontal[np.isfinite(horizontal).all(axis=1)]
        speeds.append(np.hypot(horizontal[:, 0], horizontal[:, 1]))
        vectors.append(horizontal)
    speeds = np.concatenate(speeds) if speeds else np.zeros(0)
    if not speeds.size:
        return None
    north, east = np.concatenate(vectors).mean(axis=0)
    return {"speed_m_s": float(np.mean(speeds)), "direction_rad": float(np.arctan2(east, north) + heading_correction_rad)}


def _degrees(angle_rad: float) -> float:
    """An angle in degrees within [0, 360)."""
    return float(np.rad2deg(angle_rad) % 360.0)


def bed_direction(velocity_m_s, se_m_s, flow: dict | None) -> dict:
    """A bed velocity (north, east) with its SEs against the flow (:func:`mean_flow`): its direction
    and that direction's SE (deg, clockwise from north), the flow's, the bed's angle from it
    (``from_flow_deg``, -180..180) and ``against_flow``: more than 45 deg off the flow by over
    ``DIRECTION_Z`` standard errors of its direction (QRev's loop test, made aware of the bed's
    uncertainty). Figures are None where the speed is zero or no flow is known."""
    v, se = np.asarray(velocity_m_s, dtype=float), np.asarray(se_m_s, dtype=float)
    speed = float(np.hypot(*v))
    out = {"direction_deg": None, "direction_se_deg": None,
           "flow_direction_deg": _degrees(flow["direction_rad"]) if flow else None, "from_flow_deg": None,
           "against_flow": False}
    if speed <= 0:
        return out
    direction = float(np.arctan2(v[1], v[0]))
    direction_se = float(np.hypot(v[1] * se[0], v[0] * se[1]) / speed ** 2)
    out.update(direction_deg=_degrees(direction), direction_se_deg=float(np.rad2deg(direction_se)))
    if flow:
        off = float(np.angle(np.exp(1j * (direction - flow["direction_rad"]))))
        out.update(from_flow_deg=float(np.rad2deg(off)),
                   against_flow=bool(abs(off) - DIRECTION_Z * direction_se > MAX_FROM_FLOW_RAD))
    return out


def moving_bed_test(velocity_m_s, se_m_s, confounded: bool, flow: dict | None) -> dict:
    """The decision on a fitted constant bed (north, east) with its standard errors, given the
    runs' flow (:func:`mean_flow`): ``moving`` (significant at ``SIGNIFICANCE``, above the practical
    threshold and not against the flow), ``against_flow`` (significant, but more than 45 deg off the
    flow's direction by over ``DIRECTION_Z`` of its standard errors), ``undetermined`` (not
    determined, or not separable from a heading error) or ``fixed``; with the figures behind it."""
    flow_m_s = flow["speed_m_s"] if flow else None
    threshold = max(MIN_SPEED_M_S, FLOW_SHARE * flow_m_s) if flow_m_s else MIN_SPEED_M_S
    out = {"speed_m_s": None, "speed_se_m_s": None, "chi2": None, "p_value": None, "threshold_m_s": threshold,
           "mean_flow_m_s": flow_m_s, "percent_of_flow": None,
           **{k: v for k, v in bed_direction((0.0, 0.0), (0.0, 0.0), flow).items() if k != "against_flow"}}
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
    direction = bed_direction(v, se, flow)
    against = direction.pop("against_flow")
    out.update(direction)
    share = f" ({out['percent_of_flow']:.1f} % of the mean flow {flow_m_s:.2f} m/s)" if flow_m_s else ""
    rule = (f"the larger of {MIN_SPEED_M_S} m/s and {100 * FLOW_SHARE:g} % of the mean flow" if flow_m_s else
            f"{MIN_SPEED_M_S} m/s; no water profile gives the mean flow")
    figures = f"{speed:.3f} +- {speed_se:.3f} m/s{share}"
    if p < SIGNIFICANCE and speed > threshold:
        if against:
            return {**out, "decision": "against_flow", "reason": (
                f"{figures}, significant (p = {p:.1g}), but towards {out['direction_deg']:.0f} +- "
                f"{out['direction_se_deg']:.0f} deg, {abs(out['from_flow_deg']):.0f} deg from the flow's "
                f"{out['flow_direction_deg']:.0f} deg: a bed moves with the near-bed flow (QRev's loop test "
                f"rejects a closure error more than {np.rad2deg(MAX_FROM_FLOW_RAD):.0f} deg from upstream), so what "
                "it carried is a heading error on these courses or a bias of the bottom track")}
        return {**out, "decision": "moving", "reason": f"{figures}: significant (p = {p:.1g}) and above the threshold "
                                                       f"{threshold:.3f} m/s ({rule})"}
    if confounded:
        return {**out, "decision": "undetermined", "reason": "the bed and a constant heading error turn the bottom track "
                                                             "alike on these courses"}
    why = (f"not significant (p = {p:.2g})" if p >= SIGNIFICANCE else
           f"below the threshold {threshold:.3f} m/s ({rule})")
    return {**out, "decision": "fixed", "reason": f"{figures}: {why}"}
