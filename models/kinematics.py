"""Transducer kinematics (Eqs. 10-33), frame-consistent.

Conventions: r is a (4, 3) array whose rows are the radius vectors r_i of the
transducers in the body frame, from the centre of rotation G (Eq. 30); beam
vectors are rows too. Lambda maps body to Earth, Lambda_tb transducer to body.

The paper's Eq. 31 writes the tangential velocity as Omega r with Omega an
Earth-frame tensor and r a body-frame vector. The consistent form is
dLambda/dt r = Omega Lambda r (the paper's own Eqs. 22/24); ``paper_literal``
functions keep the printed form for comparison only
(``docs/notes-on-the-paper.md``, erratum 1).
"""

from __future__ import annotations

import casadi as ca

from .rotations import euler_matrix


def radius_vectors(installation_ypr, centre_body_m, transducer_pos_t):
    """r_i = Lambda_tb T_it + P_b (Eqs. 14, 20, 30), rows (4, 3)."""
    Ltb = euler_matrix(installation_ypr[0], installation_ypr[1], installation_ypr[2])
    P_b = ca.reshape(centre_body_m, 1, 3)
    return ca.mtimes(transducer_pos_t, Ltb.T) + ca.repmat(P_b, 4, 1)


def beam_directions_earth(Lam, Ltb, beam_dirs_t):
    """d_i = Lambda Lambda_tb b_i (Eqs. 26-29), rows (4, 3)."""
    return ca.mtimes(beam_dirs_t, ca.mtimes(Lam, Ltb).T)


def angular_velocity_tensor(Lam, dLam):
    """Omega = dLambda/dt Lambda^T (Eq. 32), Earth frame, skew-symmetric."""
    return ca.mtimes(dLam, Lam.T)


def tangential_velocity_earth(Lam, omega, r):
    """Earth-frame tangential velocity dLambda/dt r_i = omega x Lambda r_i of each transducer, rows
    (4, 3) (Eqs. 22, 24), with omega the Earth-frame angular velocity (the axial vector of Omega,
    Eq. 32): the cross product costs half of dLambda/dt's nine entries, and Lambda r_i is the
    transducers' position anyway."""
    rot = ca.mtimes(r, Lam.T)
    return ca.cross(ca.repmat(ca.reshape(omega, 1, 3), rot.shape[0], 1), rot, 2)


def tangential_velocity_paper_literal(Omega, r):
    """Omega r_i exactly as printed in Eqs. 31, 51, 79-81 (mixes frames; for comparison only)."""
    return ca.mtimes(r, Omega.T)


def transducer_velocity_earth(Lam, omega, r, vessel_velocity):
    """V_Ti = dLambda/dt r_i + V_a (Eq. 24), rows (4, 3); omega as :func:`tangential_velocity_earth`."""
    return tangential_velocity_earth(Lam, omega, r) + ca.repmat(ca.reshape(vessel_velocity, 1, 3), 4, 1)


def transducer_positions_earth(Lam, r, centre_of_rotation):
    """T_i = Lambda r_i + G (Eqs. 15, 19), rows (4, 3)."""
    return ca.mtimes(r, Lam.T) + ca.repmat(ca.reshape(centre_of_rotation, 1, 3), 4, 1)


def centre_of_rotation_depth(transducer_depth_m, r):
    """Depth of G below the surface (positive down): the transducer centre's depth when level
    (H_O) less the mean vertical lever arm, H_O - mean_i r_iz (Eq. 66 with a level vessel).
    Works on numbers (r an array) and on CasADi expressions."""
    if isinstance(r, (ca.SX, ca.MX, ca.DM)):
        return transducer_depth_m - ca.sum1(r[:, 2]) / 4
    import numpy as np

    return float(transducer_depth_m) - float(np.mean(np.asarray(r, dtype=float)[:, 2]))


def transducer_state_function(attitude_fun: ca.Function) -> ca.Function:
    """Per-time kinematics from an attitude model, as one CasADi Function.

    ``state(t, p, r, installation_ypr, beam_dirs_t) -> (Lambda, dLambda_dt, d, v_tan, rot)``
    with d the Earth beam directions (4, 3), v_tan the Earth tangential velocities
    dLambda/dt r_i (4, 3) and rot the Earth positions Lambda r_i relative to G (4, 3).
    Map it over pings with ``.map(n)``.
    """
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", attitude_fun.size_in(1))
    r = ca.SX.sym("r", 4, 3)
    ypr_tb = ca.SX.sym("installation_ypr", 3)
    b_t = ca.SX.sym("beam_dirs_t", 4, 3)
    _, Lam, dLam, _, omega = attitude_fun(t, p)
    Ltb = euler_matrix(ypr_tb[0], ypr_tb[1], ypr_tb[2])
    return ca.Function(
        "transducer_state",
        [t, p, r, ypr_tb, b_t],
        [Lam, dLam, beam_directions_earth(Lam, Ltb, b_t), tangential_velocity_earth(Lam, omega, r), ca.mtimes(r, Lam.T)],
        ["t", "p", "r", "installation_ypr", "beam_dirs_t"],
        ["Lambda", "dLambda_dt", "d", "v_tan", "rot"],
    )
