"""Water profiles in the Earth frame: relative to the transducer, or referenced to the
bottom track or to the GNSS.

The instrument measures the water relative to the transducer. The static correction turns
each cell's radials -w into the Earth frame with the ping's attitude (the water velocity
relative to the transducer, the instrument's own Earth-frame water velocity); referenced to
the bottom track it turns bt - w (the bottom-track vessel velocity added, beam by beam); and
referenced to the GNSS it adds the GNSS velocity interpolated to the pings. The dynamic
corrections solve each cell with a vessel velocity: the bottom track's, or the centre of
rotation's from the GNSS (the antenna's velocity less its tangential velocity
dLambda/dt p), see :func:`~adcpdyn.estimators.correction.adc.dynamic_correction`.
"""

from __future__ import annotations

import numpy as np

from ..cases.case import Case
from ..models.frames import beams_to_earth

WATER_REFERENCES = ("bt", "gnss")

REFERENCE_NOTES = {
    "bt": "water velocities referenced to the bottom track: the corrected vessel velocity over the bed (plus the "
          "calibration's moving bed when it found one) added to the water velocity relative to the transducer",
    "gnss": "water velocities referenced to the GNSS: the reference velocity interpolated linearly to each ping "
            "(never extrapolated: NaN outside the reference's span) added to the water velocity relative to the "
            "transducer",
}


def check_reference(reference: str, case: Case | None = None) -> str:
    """``bt`` or ``gnss``; ``gnss`` needs a moving reference with samples in the case.

    Raises
    ------
    ValueError
        One line naming ``--reference`` (or the case's ``/reference``).
    """
    if reference not in WATER_REFERENCES:
        raise ValueError(f"--reference: expected one of {list(WATER_REFERENCES)}, got {reference!r}")
    if reference == "gnss" and case is not None:
        ref = case.reference
        if ref is None or (not ref.stationary and (ref.time_s is None or ref.velocity_m_s is None)):
            raise ValueError(f"{case.name}: /reference: --reference gnss needs the case's reference velocity "
                             "(GNSS), got none")
    return reference


def reference_velocity_at(case: Case, times) -> np.ndarray:
    """The reference point's Earth velocity (NED) at ``times``, (n, 3)
    (:func:`adcpdyn.cases.coverage.reference_at`: per component, never extrapolated beyond one
    sample interval; zeros for a stationary reference); a one-line error without one."""
    from ..cases.coverage import reference_at

    out = reference_at(case, times)
    if out is None:
        missing = "/reference: none in this case" if case.reference is None else "/reference/velocity_m_s: expected samples, got none"
        raise ValueError(f"{case.name}: {missing}")
    return out


def static_relative_water(case: Case, rotation: np.ndarray) -> np.ndarray:
    """Earth water velocity relative to the transducer from the static transform, (N, K, 3) NED.

    ``rotation`` (N, 3, 3) is the ping's transducer-to-Earth matrix (as the static
    correction's): each cell's radials -w (water approaching the transducer is positive,
    so -w is the water's velocity along the outward beam) solved by least squares, three
    beams when one is lost.
    """
    w = case.water.radial_m_s
    N, _, K = w.shape
    flat = (-w).transpose(0, 2, 1).reshape(N * K, 4)
    v, _, _ = beams_to_earth(flat, case.instrument.beam_directions(), np.repeat(rotation, K, axis=0))
    return v.reshape(N, K, 3)


def reference_point_in_sensor_frame(case: Case, nominal_installation_ypr_rad=None, oracle: bool = False) -> np.ndarray:
    """The reference's body point in the frame of the attitude the corrections use.

    Vessel-frame attitude (and the oracle's true attitude): the body point itself. A
    sensor in the head: turned into the head frame by the calibration's nominal
    installation angles (``nominal_installation_ypr_rad``, (3,), as the calibration's
    measurement model does); zeros stay zeros.
    """
    from ..models.rotations import euler_matrix

    p = np.asarray(case.reference.point_body_m, dtype=float)
    if oracle or case.attitude.frame == "vessel" or not np.any(p):
        return p
    nominal = nominal_installation_ypr_rad
    if nominal is None or not np.all(np.isfinite(nominal)):
        raise ValueError("calibration: config.nominal_installation_ypr_rad: needed to put the reference point "
                         f"{p.tolist()} m into the head sensor's frame for --reference gnss, got none")
    return np.asarray(euler_matrix(*np.asarray(nominal, dtype=float))).T @ p


def centre_velocity_from_reference(case: Case, attitude, point_sensor_m) -> np.ndarray:
    """Velocity of the centre of rotation G at the pings from the reference: v_ref - dLambda/dt p, (N, 3).

    ``attitude`` is the attitude model (or samples) the dynamic correction uses, in the
    sensor frame; ``point_sensor_m`` the reference point in that frame
    (:func:`reference_point_in_sensor_frame`).
    """
    from ..models.motion import SampledAttitude, evaluate_attitude

    t = case.pings.time_s
    v = reference_velocity_at(case, t)
    p = np.asarray(point_sensor_m, dtype=float)
    if not np.any(p):
        return v
    anchor = t if isinstance(attitude, SampledAttitude) else None
    dlam = evaluate_attitude(attitude, t, anchor)["dLambda_dt"]
    return v - np.einsum("nij,j->ni", dlam, p)
