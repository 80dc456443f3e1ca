"""Field errors injected into a recorded run, on its recorded channels (attitude samples,
reference, radials), written independently of the fitted model: the check that a diagnosis
finds what a field crew meets is then not the model testing itself.

Each error is named after the catalog effect that should explain it; sizes are the field's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...cases.case import Case

FIELD_ERRORS = {  # name -> (catalog effect, unit, typical sizes)
    "compass_offset_deg": ("compass_offset", "deg", (2.0, 4.0)),
    "attitude_latency_s": ("attitude_latency", "s", (0.3, 1.0)),
    "reference_latency_s": ("reference_latency", "s", (0.5, 2.0)),
    "moving_bed_m_s": ("moving_bed", "m/s", (0.1, 0.3)),
    "sound_speed_relative": ("sound_speed_error", "", (0.02, 0.04)),
}


def inject(case: Case, error: str, size: float) -> Case:
    """``case`` with one field error of ``size`` (units of :data:`FIELD_ERRORS`) written into what
    the instruments recorded.

    - compass_offset_deg: every heading sample turned by ``size`` (true = read - size);
    - attitude_latency_s: attitude samples stamped ``size`` late (the sample stamped t holds t - size);
    - reference_latency_s: reference velocities stamped ``size`` late;
    - moving_bed_m_s: a bed moving at ``size`` across the mean course (to its left): the bottom
      track sees v - u, so the reference, which sees v, gets + u;
    - sound_speed_relative: radials and slant ranges scaled by 1 + size (the instrument's sound
      speed off by that fraction).
    """
    if error not in FIELD_ERRORS:
        raise ValueError(f"error: expected one of {sorted(FIELD_ERRORS)}, got {error!r}")
    att, ref = case.attitude, case.reference
    if error == "compass_offset_deg":
        return case.replace(attitude=dataclasses.replace(att, heading_rad=att.heading_rad + np.radians(size)))
    if error == "attitude_latency_s":
        return case.replace(attitude=dataclasses.replace(att, time_s=att.time_s + size))
    if error == "sound_speed_relative":
        p = case.pings
        rng = None if p.bt_range_m is None else p.bt_range_m * (1 + size)
        return case.replace(pings=dataclasses.replace(p, bt_radial_m_s=p.bt_radial_m_s * (1 + size), bt_range_m=rng))
    if ref is None or ref.stationary or ref.velocity_m_s is None:
        raise ValueError(f"error: {error} needs a moving reference velocity; {case.name} has none")
    if error == "reference_latency_s":
        return case.replace(reference=dataclasses.replace(ref, time_s=ref.time_s + size))
    v = ref.velocity_m_s
    course = np.arctan2(np.nanmean(v[:, 1]), np.nanmean(v[:, 0]))
    u = size * np.array([np.cos(course - np.pi / 2), np.sin(course - np.pi / 2), 0.0])
    return case.replace(reference=dataclasses.replace(ref, velocity_m_s=v + u))
