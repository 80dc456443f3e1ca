"""Qiao et al. 2019's installation-angle calibration, the baseline for installation angles.

Yaw (their Eq. 5): the angle between the reference (GNSS) velocity and the bottom-track
velocity computed with zero installation angles, averaged over moving pings.
Tilt (their Eqs. 6-9): on a flat bottom the slant ranges of a beam pair differ by the
head's tilt in that pair's plane, tan D = (R_long - R_short) / (tan(alpha) (R_1 + R_2)):
in our beam layout pitch about y_t from beams 1-2 and roll about x_t from beams 3-4.
The head's down vector from the ranges and the vessel's from the attitude sensor then
give the installation pitch and roll (with the yaw above), by least squares.
Needs a vessel-frame attitude sensor, a moving vessel with a reference velocity, and
slant ranges. The tangential velocity of the swaying transducer is ignored, as in the
source.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ...cases.case import Case
from ...models.rotations import euler_matrices, euler_matrix
from ..asc import asc, attitude_at

MIN_SPEED_M_S = 0.3


@dataclass(frozen=True)
class QiaoResult:
    installation_ypr_rad: np.ndarray
    installation_ypr_se_rad: np.ndarray
    n_pings_yaw: int
    n_pings_tilt: int


def qiao_calibration(case: Case) -> QiaoResult:
    """Installation yaw from GNSS vs bottom track, pitch and roll from slant ranges."""
    if case.attitude.frame != "vessel":
        raise ValueError("attitude.attrs['frame']: expected 'vessel' for Qiao's calibration (a head sensor sees no installation angles)")
    ref = case.reference
    if ref is None or ref.time_s is None or ref.velocity_m_s is None:
        raise ValueError("/reference: expected a reference velocity (GNSS) for the installation yaw")
    t = case.pings.time_s
    v_bt = asc(case).vessel_velocity_m_s
    v_ref = np.column_stack([np.interp(t, ref.time_s, ref.velocity_m_s[:, j]) for j in range(3)])
    speed = np.hypot(v_ref[:, 0], v_ref[:, 1])
    ok = (speed > MIN_SPEED_M_S) & np.all(np.isfinite(v_bt), axis=1)
    dpsi = np.angle(np.exp(1j * (np.arctan2(v_ref[ok, 1], v_ref[ok, 0]) - np.arctan2(v_bt[ok, 1], v_bt[ok, 0]))))
    yaw = float(np.angle(np.mean(np.exp(1j * dpsi))))
    yaw_se = float(np.std(dpsi) / np.sqrt(max(dpsi.size, 1)))

    pitch = roll = np.nan
    tilt_se = np.full(2, np.inf)
    n_tilt = 0
    R = case.pings.bt_range_m
    if R is not None:
        tan_a = np.tan(case.instrument.beam_angle_rad)
        d12 = np.arctan((R[:, 1] - R[:, 0]) / (tan_a * (R[:, 0] + R[:, 1])))  # head pitch about y_t
        d34 = np.arctan((R[:, 3] - R[:, 2]) / (tan_a * (R[:, 2] + R[:, 3])))  # head roll about x_t
        good = np.isfinite(d12) & np.isfinite(d34)
        n_tilt = int(good.sum())
        # down vector in the head frame, R^T e_z = (-sin th, cos th sin ph, cos th cos ph)
        g_t = np.column_stack([-np.sin(d12), np.cos(d12) * np.sin(d34), np.cos(d12) * np.cos(d34)])[good]
        g_b = euler_matrices(attitude_at(case, t[good]))[:, 2, :]  # Lambda^T e_z: vessel-frame down

        def resid(q):
            Ltb = np.asarray(euler_matrix(yaw, q[0], q[1]))
            return (g_t @ Ltb.T - g_b).ravel()

        sol = least_squares(resid, np.zeros(2))
        pitch, roll = sol.x
        J = sol.jac
        s2 = 2 * sol.cost / max(J.shape[0] - 2, 1)
        tilt_se = np.sqrt(np.diag(np.linalg.pinv(J.T @ J)) * s2)
    return QiaoResult(np.array([yaw, pitch, roll]), np.array([yaw_se, *tilt_se]), int(ok.sum()), n_tilt)
