"""Exact per-ping solve of the two-way Doppler equations (Eq. 70) for all four beams.

Square system per ping: unknowns the vessel velocity V (3) and the error velocity e;
for each beam i

    radial_from_ratio((c + (V + w_Ri) . d_Ri) / (c - (V + w_Ti) . d_Ti), c) + e n_i = v_i

with w the tangential velocities, d the beam directions at transmit and receive, and
n the error-velocity direction (the Janus null vector scaled so that e equals the
instrument's error velocity). Posed symbolically once, solved by ``casadi.rootfinder``
(Newton) for every ping at once through ``map``. Where the closed form's
multiplied-out equations hold exactly this agrees with it; it also keeps the
instrument's nonlinear velocity conversion instead of linearising around it.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..models.doppler import bottom_echo_ratio, radial_from_ratio


NEWTON_STEPS = 3  # from the closed form the error falls ~1e-3 -> 1e-9 -> 1e-21 m/s
NEWTON_RESIDUAL_TOL = 1e-9  # m/s; pings above it go to casadi.rootfinder
THREADS = 2


def doppler_residual(error_direction: np.ndarray, sound_speed: float) -> ca.Function:
    """``g(x (4), p (36)) -> residual (4)`` of one ping (m/s): the unknown first."""
    x = ca.SX.sym("x", 4)
    p = ca.SX.sym("p", 36)
    d_T = ca.reshape(p[0:12], 3, 4).T
    d_R = ca.reshape(p[12:24], 3, 4).T
    w_T, w_R, v = p[24:28], p[28:32], p[32:36]
    V, e = x[:3], x[3]
    u_T = ca.mtimes(d_T, V) + w_T
    u_R = ca.mtimes(d_R, V) + w_R
    model = radial_from_ratio(bottom_echo_ratio(u_T, u_R, sound_speed), sound_speed)  # Eqs. 70, 65
    return ca.Function("doppler_residual", [x, p], [model + e * ca.DM(error_direction) - v], ["x", "p"], ["g"])


def doppler_rootfinder(error_direction: np.ndarray, sound_speed: float, n_pings: int,
                       parallelization: str = "serial") -> ca.Function:
    """``rf(x0 (4, N), p (36, N)) -> x (4, N)``; p per ping = [d_T (12), d_R (12), w_T . d_T (4),
    w_R . d_R (4), measured radial (4)] (see :func:`pack`). Newton with a convergence test."""
    g = doppler_residual(error_direction, sound_speed)
    rf = ca.rootfinder("doppler_rootfinder", "newton", g, {"abstol": 1e-12, "max_iter": 20})
    return rf.map(n_pings, parallelization)


def doppler_newton(error_direction: np.ndarray, sound_speed: float, n_pings: int, steps: int = NEWTON_STEPS,
                   threads: int = THREADS) -> ca.Function:
    """``newton(x0 (4, N), p (36, N)) -> (x (4, N), |residual|_inf (1, N))``: a fixed number of
    Newton steps as one expanded SX expression, mapped over pings on ``threads`` threads.
    Callers check the residual and send pings that did not converge to :func:`doppler_rootfinder`."""
    g = doppler_residual(error_direction, sound_speed)
    x = ca.SX.sym("x", 4)
    p = ca.SX.sym("p", 36)
    jac = ca.Function("doppler_jacobian", [x, p], [ca.jacobian(g(x, p), x)])
    xk = x
    for _ in range(steps):
        xk = xk - ca.solve(jac(xk, p), g(xk, p))
    step = ca.Function("doppler_newton", [x, p], [xk, ca.norm_inf(g(xk, p))], ["x0", "p"], ["x", "residual"])
    return step.map(n_pings, "thread", threads) if threads > 1 else step.map(n_pings)


def pack(d_T, d_R, w_T, w_R, radial) -> np.ndarray:
    """Per-ping parameter columns (36, N) for :func:`doppler_rootfinder`."""
    N = radial.shape[0]
    return np.vstack([d_T.reshape(N, 12).T, d_R.reshape(N, 12).T, w_T.T, w_R.T, radial.T])


def error_direction(e_row: np.ndarray) -> np.ndarray:
    """Direction n with e_row . (e n) = e: radial residuals of pure error velocity e."""
    return e_row / np.dot(e_row, e_row)
