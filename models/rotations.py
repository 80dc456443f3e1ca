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
    return ca.mtimes([rot_z(yaw), rot_y(pitch), rot_x(roll)])


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
