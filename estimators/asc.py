"""Attitude static correction (ASC), the conventional baseline (Eqs. 8-9).

Per ping, the beam radial velocities go to the transducer frame by the least-squares
beam-to-instrument transform (Eq. 5 generalised; error velocity as real ADCPs report
it; three-beam solution when one beam is lost), then to the Earth frame with the
attitude at the ping time: Lambda Lambda_tb for a sensor aligned with the vessel, the
sensed Lambda Lambda_tb directly for a sensor inside the head (applying Lambda_tb
again would turn the beams twice, erratum 5). Water velocity per cell from the
Earth-relative radial water velocity bt - water (Eq. 4 in instrument sign).
The tangential velocity of the swaying transducers is ignored: that is the point.
"""

from __future__ import annotations

import numpy as np

from ..cases.case import Case
from ..cases.corrected import Correction, CorrectionProvenance
from ..models.frames import beams_to_earth, sensed_rotation


def attitude_at(case: Case, times) -> np.ndarray:
    """Sensed (yaw, pitch, roll) at times (:meth:`~adcpdyn.cases.case.Attitude.ypr_at`), (n, 3)."""
    return case.attitude.ypr_at(times)


def earth_rotation(case: Case, times, installation_ypr_rad) -> np.ndarray:
    """Transducer-to-Earth rotation at times from the attitude sensor, (n, 3, 3)."""
    return sensed_rotation(attitude_at(case, times), case.attitude.frame, installation_ypr_rad)


def asc(case: Case, installation_ypr_rad=None, water_reference: str = "bt") -> Correction:
    """The attitude static correction of every ping of a case.

    Parameters
    ----------
    case : Case
    installation_ypr_rad : (3,) array, optional
        Installation angles from a calibration; zeros when not given.
    water_reference : str
        ``bt`` (water = Earth transform of bt - w per beam: the bottom-track vessel
        velocity added) or ``gnss`` (water relative to the transducer + the reference
        velocity interpolated to the pings, :mod:`adcpdyn.estimators.water`).
    """
    ypr_tb = np.zeros(3) if installation_ypr_rad is None else np.asarray(installation_ypr_rad, dtype=float)
    if ypr_tb.shape != (3,):
        raise ValueError(f"installation_ypr_rad: expected shape (3,), got {ypr_tb.shape}")
    B = case.instrument.beam_directions()
    R = earth_rotation(case, case.pings.time_s, ypr_tb)
    bt = case.pings.bt_radial_m_s
    v, err, n_good = beams_to_earth(bt, B, R)
    water = relative = None
    provenance = CorrectionProvenance(installation_ypr_rad=ypr_tb)
    if case.water is not None:
        from .water import REFERENCE_NOTES, check_reference, reference_velocity_at, static_relative_water

        check_reference(water_reference, case)
        relative = static_relative_water(case, R)
        if water_reference == "bt":
            rel = bt[:, :, None] - case.water.radial_m_s  # Earth-relative radial water velocity
            N, _, K = rel.shape
            flat = rel.transpose(0, 2, 1).reshape(N * K, 4)
            vw, _, _ = beams_to_earth(flat, B, np.repeat(R, K, axis=0))
            water = vw.reshape(N, K, 3)
        else:
            water = relative + reference_velocity_at(case, case.pings.time_s)[:, None, :]
        note = REFERENCE_NOTES[water_reference]
        if water_reference == "gnss" and np.any(case.reference.point_body_m):
            note += ("; the static correction takes the reference point's velocity for the transducer's (the lever arm "
                     "between them is ignored, as is every rotation)")
        provenance = provenance.replace(water_reference=water_reference, water_reference_note=note)
    return Correction(
        method="asc",
        time_s=case.pings.time_s.copy(),
        vessel_velocity_m_s=v,
        error_velocity_m_s=err,
        beams_used=n_good,
        water_velocity_m_s=water,
        provenance=provenance,
        water_relative_velocity_m_s=relative,
    )
