"""Janus four-beam geometry and beam-to-instrument transforms (Eqs. 5, 13-18, 25-29).

Transducer frame P x_t y_t z_t: transducers 1, 2 at (-tr, 0, 0), (+tr, 0, 0), 3, 4 at
(0, +tr, 0), (0, -tr, 0); z_t out of the face. Beam i's outward unit vector, beam
angle alpha from z_t: b1 = (-sin a, 0, cos a), b2 = (sin a, 0, cos a),
b3 = (0, sin a, cos a), b4 = (0, -sin a, cos a).

Radial velocities follow the instrument convention (positive when the target
approaches), so a transducer moving with v over a still bottom measures b_i . v and
the least-squares inverse maps radial velocities back to v.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def janus_beam_directions(beam_angle_rad):
    """Outward unit beam vectors b_i in the transducer frame, rows of a (4, 3) (Eqs. 25-29)."""
    s, c = ca.sin(beam_angle_rad), ca.cos(beam_angle_rad)
    return ca.vertcat(
        ca.horzcat(-s, 0, c),
        ca.horzcat(s, 0, c),
        ca.horzcat(0, s, c),
        ca.horzcat(0, -s, c),
    )


def janus_transducer_positions(transducer_radius_m):
    """Transducer centres T_it relative to P in the transducer frame, (4, 3) (Eqs. 13, 16-18)."""
    tr = transducer_radius_m
    return ca.vertcat(
        ca.horzcat(-tr, 0, 0),
        ca.horzcat(tr, 0, 0),
        ca.horzcat(0, tr, 0),
        ca.horzcat(0, -tr, 0),
    )


def beam_to_instrument_janus(beam_angle_rad):
    """The paper's Eq. 5 with beta = 0 for the layout above: (3, 4), v_t = M @ radial.

    Row 1 (x_t) uses beams 1, 2; row 2 (y_t) beams 3, 4; row 3 (z_t) all four.
    """
    s, c = ca.sin(beam_angle_rad), ca.cos(beam_angle_rad)
    a, d = 1 / (2 * s), 1 / (4 * c)
    return ca.vertcat(
        ca.horzcat(-a, a, 0, 0),
        ca.horzcat(0, 0, a, -a),
        ca.horzcat(d, d, d, d),
    )


def beam_to_instrument(beam_dirs):
    """General least-squares beam-to-instrument transform for any four beam vectors.

    Parameters
    ----------
    beam_dirs : (4, 3) array
        Outward unit beam vectors, one per row, in the transducer frame.

    Returns
    -------
    M : (3, 4) ndarray
        Velocity v = M @ radial, the least-squares solution of beam_dirs @ v = radial.
    e : (4,) ndarray
        Error-velocity row: err = e @ radial, zero for any rigid velocity field. For the
        Janus layout it equals RDI's (r1 + r2 - r3 - r4) / (2 sqrt(2) sin a).
    """
    B = np.asarray(beam_dirs, dtype=float)
    if B.shape != (4, 3):
        raise ValueError(f"beam_dirs: expected shape (4, 3), got {B.shape}")
    M = np.linalg.pinv(B)
    # The left null space of B (B^T n = 0) is what no rigid velocity can produce.
    u, _, _ = np.linalg.svd(B)
    n = u[:, 3]
    if n @ np.array([1.0, 1.0, -1.0, -1.0]) < 0:
        n = -n
    horizontal = np.mean(np.hypot(B[:, 0], B[:, 1]))
    return M, n / (np.sqrt(2.0) * horizontal)


def error_velocity(radial, beam_dirs) -> tuple[np.ndarray, float]:
    """RDI's error velocity of each ping (N,) from its radials (N, 4) (:func:`beam_to_instrument`'s
    error row e; NaN unless all four beams are valid), and |e|: independent beam noise sigma gives
    an error velocity of SD sigma |e|."""
    radial = np.asarray(radial, dtype=float)
    _, e = beam_to_instrument(beam_dirs)
    four = np.all(np.isfinite(radial), axis=1)
    return np.where(four, np.nan_to_num(radial) @ e, np.nan), float(np.linalg.norm(e))


def three_beam_solution(beam_dirs, radial):
    """Velocity from three beams when one is lost (NaN), per row; NaN if two or more are lost.

    Parameters
    ----------
    beam_dirs : (4, 3) array
    radial : (N, 4) array

    Returns
    -------
    v : (N, 3) ndarray
    n_good : (N,) int ndarray, number of valid beams used
    """
    B = np.asarray(beam_dirs, dtype=float)
    radial = np.asarray(radial, dtype=float)
    good = np.isfinite(radial)
    n_good = good.sum(axis=1)
    v = np.full((radial.shape[0], 3), np.nan)
    M4, _ = beam_to_instrument(B)
    full = n_good == 4
    v[full] = radial[full] @ M4.T
    for lost in range(4):
        rows = (n_good == 3) & ~good[:, lost]
        if rows.any():
            keep = [j for j in range(4) if j != lost]
            v[rows] = radial[rows][:, keep] @ np.linalg.inv(B[keep]).T
    return v, n_good
