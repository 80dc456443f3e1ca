"""The vessel's velocity as a piecewise-linear curve over knots, or a velocity at every ping under
a random-walk prior: the interpolation bases (sparse), the knots, the walk's rows and the
starting levels of its priors from the data."""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.stats import median_abs_deviation

from ..cases.case import Case
from .noise_guess import bt_noise_from_error_velocity


def hat_basis_sparse(times, knots) -> sp.csr_matrix:
    """Piecewise-linear interpolation weights, (len(times), len(knots)), constant beyond the ends:
    each time's two knots only (np.interp's arithmetic), never an (N, K) dense array."""
    knots = np.asarray(knots, dtype=float)
    t = np.clip(np.asarray(times, dtype=float).reshape(-1), knots[0], knots[-1])
    j = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 2)
    a = (1.0 / (knots[j + 1] - knots[j])) * (t - knots[j])
    rows = np.repeat(np.arange(t.size), 2)
    H = sp.csr_matrix((np.column_stack([1.0 - a, a]).ravel(), (rows, np.column_stack([j, j + 1]).ravel())),
                      shape=(t.size, knots.size))
    H.eliminate_zeros()  # a time on a knot touches that knot alone
    return H


def hat_basis(times, knots) -> np.ndarray:
    """:func:`hat_basis_sparse` as a dense array (for a few knots, e.g. the bed's)."""
    return hat_basis_sparse(times, knots).toarray()


def hat_basis_dm(times, knots) -> ca.DM:
    """:func:`hat_basis_sparse` as a CasADi matrix of the same sparsity, so the residual Jacobian
    stays sparse in the knot columns (a dense DM keeps its zeros as structure)."""
    return sparse_dm(hat_basis_sparse(times, knots))


def sparse_dm(H: sp.spmatrix) -> ca.DM:
    """A scipy sparse matrix as a CasADi DM of the same sparsity."""
    H = sp.csc_matrix(H)
    H.sort_indices()
    return ca.DM(ca.Sparsity(H.shape[0], H.shape[1], H.indptr.tolist(), H.indices.tolist()), H.data)


def window_basis_sparse(windows, knots) -> sp.csr_matrix:
    """Weights of the knot velocities in the mean of the piecewise-linear velocity over each window
    [a, b] (rows of ``windows``): exact, since the trapezoid rule is exact on every linear piece
    between the breakpoints (a, the knots inside, b). A GNSS velocity differenced from two fixes is
    that mean, not the velocity at its time stamp."""
    knots = np.asarray(knots, dtype=float)
    windows = np.asarray(windows, dtype=float).reshape(-1, 2)
    rows = []
    for a, b in windows:
        t = np.concatenate([[a], knots[(knots > a) & (knots < b)], [b]])
        H = hat_basis_sparse(t, knots)
        w = np.diff(t) / (2.0 * (b - a))
        rows.append(sp.csr_matrix(np.concatenate([[0.0], w]) + np.concatenate([w, [0.0]])) @ H)
    return sp.vstack(rows, format="csr") if rows else sp.csr_matrix((0, knots.size))


def knot_times(case: Case, interval_s: float | None) -> np.ndarray | None:
    """Navigation knots over the pings' span (None when the vessel is known to stay put).

    Default spacing: five reference intervals (or ping intervals without a reference), at
    least 1/50 of the run. Knots cover the pings only: a reference recorded far outside
    them (a clock off by hours) cannot stretch the problem. A knot with neither a ping nor a
    reference velocity between its neighbours (inside a gap of both) is left out: nothing would
    determine its velocity, and the curve crosses the gap straight between the knots that bound it.
    """
    ref = case.reference
    if ref is not None and ref.stationary:
        return None
    t = case.pings.time_s
    duration = float(t[-1] - t[0])
    if interval_s is None:
        if ref is not None and ref.time_s is not None and ref.time_s.size > 1:
            interval_s = max(5 * float(np.median(np.diff(ref.time_s))), duration / 50)
        else:
            interval_s = max(5 * float(np.median(np.diff(t))), duration / 30)
    n_knots = max(2, int(np.ceil(duration / interval_s)) + 1)
    knots = np.linspace(t[0], t[-1], n_knots)
    data = t
    if ref is not None and ref.time_s is not None and ref.velocity_m_s is not None:
        data = np.sort(np.concatenate([t, ref.time_s[np.all(np.isfinite(ref.velocity_m_s[:, :2]), axis=1)]]))
    # samples in (knot before, knot after) of each knot: the counts between neighbours two apart
    seen = (np.searchsorted(data, np.append(knots[1:], np.inf), "left")
            - np.searchsorted(data, np.insert(knots[:-1], 0, -np.inf), "right"))
    return knots[seen > 0]


def ping_knots(case: Case) -> np.ndarray | None:
    """A navigation knot at every ping (the random-walk navigation); None when the vessel is known
    to stay put."""
    ref = case.reference
    if ref is not None and ref.stationary:
        return None
    return np.asarray(case.pings.time_s, dtype=float).copy()


def walk_increments(knots: np.ndarray) -> sp.csr_matrix:
    """(K - 1, K): the random-walk prior's rows (V_j+1 - V_j) / sqrt(t_j+1 - t_j) over the K knot
    velocities, each an N(0, q) draw for a walk of intensity sqrt(q)."""
    K, w = knots.size, 1.0 / np.sqrt(np.diff(knots))
    j = np.arange(K - 1)
    return sp.csr_matrix((np.concatenate([-w, w]), (np.concatenate([j, j]), np.concatenate([j, j + 1]))), shape=(K - 1, K))


def janus_velocity_variance(case: Case) -> np.ndarray:
    """(3,) variance of a four-beam velocity (north, east, down axes of the instrument) from the
    beams' noise (error velocity) through the Janus geometry: sigma^2 diag((B^T B)^-1)."""
    b = case.instrument.beam_directions()
    return bt_noise_from_error_velocity(case) ** 2 * np.diag(np.linalg.pinv(b.T @ b))


def random_walk_intensity(case: Case, velocity_m_s: np.ndarray) -> float:
    """Starting level of the random-walk prior, sqrt(q) in m/s/sqrt(s), from the data: the per-ping
    static (ASC) velocities' increments (``velocity_m_s``, (N, 3)), whose variance is q dt + 2 var(v)
    with var(v) from :func:`janus_velocity_variance`; horizontal axes, robust (MAD) spread."""
    v = velocity_m_s[:, :2]
    t = case.pings.time_s
    ok = np.all(np.isfinite(v), axis=1)
    if ok.sum() < 10:
        return 0.05
    dv, dt = np.diff(v[ok], axis=0), np.diff(t[ok])
    z = (dv / np.sqrt(dt)[:, None]).ravel()
    spread2 = median_abs_deviation(z, scale="normal") ** 2
    var_v = float(np.mean(janus_velocity_variance(case)[:2]))
    q = spread2 - 2 * var_v / float(np.median(dt))
    return float(np.sqrt(max(q, 0.01 * spread2, 1e-8)))


def vertical_velocity_level(case: Case, velocity_m_s: np.ndarray) -> float:
    """Starting level of the vertical-velocity prior in m/s: the robust (MAD) spread of the per-ping
    static (ASC) vertical velocities (``velocity_m_s``, (N, 3)) about zero, less the beams' noise
    (:func:`janus_velocity_variance`)."""
    w = velocity_m_s[:, 2]
    w = w[np.isfinite(w)]
    if w.size < 10:
        return 0.02
    spread2 = (1.4826 * np.median(np.abs(w))) ** 2
    var_w = float(janus_velocity_variance(case)[2])
    return float(np.sqrt(max(spread2 - var_w, 0.01 * spread2, 1e-8)))


def slope_basis_sparse(times, knots) -> sp.csr_matrix:
    """Weights of the knot velocities in the interpolant's time derivative at ``times``: central
    differences over half the median knot spacing (the slope of the segment a time falls in, as a
    small shift of the interpolant sees it)."""
    h = 0.5 * float(np.median(np.diff(knots)))
    return sp.csr_matrix((hat_basis_sparse(np.asarray(times) + h, knots) - hat_basis_sparse(np.asarray(times) - h, knots)) / (2 * h))


def navigation_slope(times: np.ndarray, knots: np.ndarray, V):
    """Time derivative of the navigation velocity V (knots x 3) at ``times``
    (:func:`slope_basis_sparse`); linear in V, so it enters the NLP as an expression."""
    return ca.mtimes(sparse_dm(slope_basis_sparse(times, knots)), V)
