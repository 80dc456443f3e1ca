"""Frames and rotations (paper Eqs. 6-7).

Earth frame: x north, y east, z down (NED). Body frame: x bow, y starboard, z down.
Euler angles are yaw psi, pitch theta, roll phi, in radians, composed as
R = Rz(psi) Ry(theta) Rx(phi); R maps vectors of the rotated frame into the parent
frame (Lambda: body -> Earth, Lambda_tb: transducer -> body). Positive roll lowers
starboard, positive pitch raises the bow, heading is clockwise from north.

Every function accepts CasADi SX/MX/DM (or floats) and returns CasADi expressions,
so the same code builds NLPs and evaluates numbers.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def rot_x(phi):
    """Rotation about x by phi (roll)."""
    c, s = ca.cos(phi), ca.sin(phi)
    return ca.vertcat(
        ca.horzcat(1, 0, 0),
        ca.horzcat(0, c, -s),
        ca.horzcat(0, s, c),
    )


def rot_y(theta):
    """Rotation about y by theta (pitch)."""
    c, s = ca.cos(theta), ca.sin(theta)
    return ca.vertcat(
        ca.horzcat(c, 0, s),
        ca.horzcat(0, 1, 0),
        ca.horzcat(-s, 0, c),
    )


def rot_z(psi):
    """Rotation about z by psi (yaw)."""
    c, s = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(
        ca.horzcat(c, -s, 0),
        ca.horzcat(s, c, 0),
        ca.horzcat(0, 0, 1),
    )


def euler_matrix(yaw, pitch, roll):
    """R = Rz(yaw) Ry(pitch) Rx(roll): Lambda(t) (Eq. 7) and Lambda_tb (Eq. 6)."""
    return _euler_matrix(ca.cos(yaw), ca.sin(yaw), ca.cos(pitch), ca.sin(pitch), ca.cos(roll), ca.sin(roll))


def _euler_matrix(cy, sy, cp, sp, cr, sr):
    # Rz Ry Rx multiplied out
    return ca.vertcat(
        ca.horzcat(cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        ca.horzcat(sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        ca.horzcat(-sp, cp * sr, cp * cr),
    )


def euler_matrix_and_rate(ypr, ypr_rate):
    """Lambda = Rz Ry Rx (:func:`euler_matrix`) and its time derivative dLambda/dt = Lambda
    skew(w_b) for Euler angles changing at ``ypr_rate`` (rad/s), with w_b the body-frame angular
    velocity (rad/s, x bow, y starboard, z down). The identity is exact (Lambda orthonormal), and costs a third
    of differentiating Lambda's nine products (the per-ping models evaluate it nine times a
    ping); one set of sines and cosines serves both. Returns (Lambda, dLambda_dt, w_b)."""
    cy, sy = ca.cos(ypr[0]), ca.sin(ypr[0])
    cp, sp = ca.cos(ypr[1]), ca.sin(ypr[1])
    cr, sr = ca.cos(ypr[2]), ca.sin(ypr[2])
    Lam = _euler_matrix(cy, sy, cp, sp, cr, sr)
    w_b = _body_rates(cp, sp, cr, sr, ypr_rate)
    return Lam, ca.mtimes(Lam, skew(w_b)), w_b


def _body_rates(cp, sp, cr, sr, rate):
    # Rx^T Ry^T (0, 0, yaw') + Rx^T (0, pitch', 0) + (roll', 0, 0)
    return ca.vertcat(rate[2] - sp * rate[0], cr * rate[1] + sr * cp * rate[0], cr * cp * rate[0] - sr * rate[1])


def matrix_euler(R):
    """Inverse of :func:`euler_matrix`: (yaw, pitch, roll) of a rotation matrix.

    Yaw and roll in (-pi, pi], pitch in [-pi/2, pi/2]; singular at pitch = +-pi/2,
    which a vessel never reaches.
    """
    yaw = ca.atan2(R[1, 0], R[0, 0])
    pitch = -ca.asin(ca.fmin(ca.fmax(R[2, 0], -1), 1))
    roll = ca.atan2(R[2, 1], R[2, 2])
    return ca.vertcat(yaw, pitch, roll)


def skew(w):
    """Cross-product matrix: skew(w) @ v = w x v."""
    return ca.vertcat(
        ca.horzcat(0, -w[2], w[1]),
        ca.horzcat(w[2], 0, -w[0]),
        ca.horzcat(-w[1], w[0], 0),
    )


def unskew(W):
    """Vector w of a (numerically) skew-symmetric matrix W = skew(w)."""
    return ca.vertcat(W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]) / 2


def euler_matrices(ypr):
    """Numeric R = Rz Ry Rx for many angle triples: (n, 3) -> (n, 3, 3), via :func:`euler_matrix`."""
    import numpy as np

    ypr = np.atleast_2d(np.asarray(ypr, dtype=float))
    n = ypr.shape[0]
    a = ca.SX.sym("ypr", 3)
    fun = ca.Function("euler", [a], [euler_matrix(a[0], a[1], a[2])]).map(n)
    return np.asarray(fun(ypr.T)).reshape(3, n, 3).transpose(1, 0, 2)


def course_difference_rad(a, b) -> np.ndarray:
    """Horizontal course of velocities ``a`` minus that of ``b`` (rows of north, east, ...), wrapped to (-pi, pi]."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.angle(np.exp(1j * (np.arctan2(a[:, 1], a[:, 0]) - np.arctan2(b[:, 1], b[:, 0]))))
