"""How the four lever arms r_1..r_4 enter the calibration NLP.

* ``paper``: twelve coordinates, the paper's three Janus conditions (Eq. 64, an image
  in the source; read from its prose) relaxed by epsilon: the midpoints of the
  diagonal pairs 1-2 and 3-4 coincide, the diagonals are perpendicular, and they are
  of equal length.
* ``exact``: twelve coordinates with the same conditions as exact equalities and tied
  to the installation angles and the known transducer radius: r_2 - r_1 =
  Lambda_st (T_2t - T_1t) (diagonal 1->2 along Lambda_st x_t, length 2 tr),
  r_3 - r_4 = Lambda_st (T_3t - T_4t), and the midpoints coincide.
* ``minimal``: r_i = Lambda_st T_it + P (Eqs. 14, 20); unknowns P only (with the angles).
* ``free``: twelve independent coordinates, no constraints.

Lever arms are in the sensor frame (see :mod:`adcpdyn.models.measurement`).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

FORMULATIONS = ("paper", "exact", "minimal", "free")
AXES = ("x", "y", "z")


@dataclass(frozen=True)
class LeverBlock:
    """Decision variables of a formulation, the lever arms they imply and their constraints."""

    x: ca.MX  # this block's decision variables (unscaled)
    names: list
    r: ca.MX  # (4, 3) lever arms in the sensor frame
    g: ca.MX  # constraints
    lbg: np.ndarray
    ubg: np.ndarray
    g_names: list

    def initial(self, centre, Lst: np.ndarray, pos_t: np.ndarray) -> np.ndarray:
        """Values of this block for a Janus head centred at ``centre`` with rotation Lst."""
        r = pos_t @ Lst.T + np.asarray(centre, dtype=float)
        if len(self.names) == 3:
            return np.asarray(centre, dtype=float)
        return r.reshape(-1)


def lever_block(formulation: str, Lst: ca.MX, pos_t: np.ndarray, epsilon_rel: float = 0.05) -> LeverBlock:
    """Build the lever-arm block of a formulation.

    Parameters
    ----------
    formulation : str
        One of ``FORMULATIONS``.
    Lst : casadi.MX
        (3, 3) transducer-to-sensor-frame rotation (a function of the installation angles).
    pos_t : (4, 3) array
        Transducer positions in the transducer frame (T_it).
    epsilon_rel : float
        ``paper`` only: the relaxation as a fraction of the squared diagonal (2 tr)^2.
    """
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation: expected one of {list(FORMULATIONS)}, got {formulation!r}")
    T = ca.DM(pos_t)
    if formulation == "minimal":
        P = ca.MX.sym("P", 3)
        r = ca.mtimes(T, Lst.T) + ca.repmat(P.T, 4, 1)
        return LeverBlock(P, [f"P_{a}" for a in AXES], r, ca.MX(0, 1), np.zeros(0), np.zeros(0), [])
    flat = ca.MX.sym("r", 12)
    r = ca.reshape(flat, 3, 4).T  # row i = r_{i+1}
    names = [f"r{i + 1}_{a}" for i in range(4) for a in AXES]
    if formulation == "free":
        return LeverBlock(flat, names, r, ca.MX(0, 1), np.zeros(0), np.zeros(0), [])
    m12 = (r[0, :] + r[1, :]) / 2
    m34 = (r[2, :] + r[3, :]) / 2
    d12 = r[1, :] - r[0, :]
    d43 = r[2, :] - r[3, :]
    if formulation == "exact":
        mid_t = (T[0, :] + T[1, :]) / 2 - (T[2, :] + T[3, :]) / 2
        g = ca.vertcat(
            (m12 - m34 - ca.mtimes(mid_t, Lst.T)).T,
            (d12 - ca.mtimes(T[1, :] - T[0, :], Lst.T)).T,
            (d43 - ca.mtimes(T[2, :] - T[3, :], Lst.T)).T,
        )
        g_names = [f"midpoint_{a}" for a in AXES] + [f"diagonal12_{a}" for a in AXES] + [f"diagonal43_{a}" for a in AXES]
        return LeverBlock(flat, names, r, g, np.zeros(9), np.zeros(9), g_names)
    diag2 = float(np.sum((pos_t[1] - pos_t[0]) ** 2))
    eps = epsilon_rel * diag2
    g = ca.vertcat(ca.sumsqr(m12 - m34), ca.dot(d12, d43), ca.sumsqr(d12) - ca.sumsqr(d43))
    return LeverBlock(flat, names, r, g, np.array([0.0, -eps, -eps]), np.array([eps / 4, eps, eps]),
                      ["midpoints_coincide", "diagonals_perpendicular", "diagonals_equal"])
