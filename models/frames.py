"""The static frame chain of the samples: beam radials -> transducer frame -> Earth (Eqs. 5, 8-9).

On arrays only (no case, no estimator): the beam-to-instrument least squares with the error
velocity real ADCPs report (three beams when one is lost), and the transducer-to-Earth rotation
from sensed Euler angles: Lambda Lambda_tb for a sensor aligned with the vessel, the sensed
Lambda Lambda_tb directly for a sensor inside the head (applying Lambda_tb again would turn the
beams twice, erratum 5). The static correction (:mod:`adcpdyn.estimators.asc`) and the importers
(bottom-track course against GNSS) both use them.
"""

from __future__ import annotations

import numpy as np

from .janus import error_velocity, three_beam_solution
from .rotations import euler_matrices, euler_matrix


def sensed_rotation(ypr_rad: np.ndarray, frame: str, installation_ypr_rad=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Transducer-to-Earth rotation (n, 3, 3) from sensed (yaw, pitch, roll) (n, 3) of a sensor in
    ``frame`` (``vessel``: times Lambda_tb of the installation angles; ``transducer``: as sensed)."""
    R = euler_matrices(np.asarray(ypr_rad, dtype=float))
    if frame == "vessel":
        R = R @ np.asarray(euler_matrix(*np.asarray(installation_ypr_rad, dtype=float)))
    return R


def beams_to_earth(radial: np.ndarray, beam_dirs_t: np.ndarray, R: np.ndarray):
    """Radial velocities (N, 4) -> Earth velocities (N, 3), error velocity (N,), beams used (N,)."""
    v_t, n_good = three_beam_solution(beam_dirs_t, radial)
    err, _ = error_velocity(radial, beam_dirs_t)
    return np.einsum("nij,nj->ni", R, v_t), err, n_good
