"""Sparse least-squares algebra of a fitted diagnosis model: leverages, leave-fold-out
predictions, marginal covariances and variance components, from the weighted residual
Jacobian J (rows x free unknowns) without ever forming (J^T J)^-1.

A base whose navigation is a velocity per ping (random walk) has thousands of unknowns, each
touching a few rows: J^T J is banded in the velocities plus a few dense columns, so the leverages
come from the band of the velocities' inverse and a Schur complement on the rest (linear in the
pings); solves against one sparse LU serve the few columns of a covariance block, and any matrix
whose band is wide.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.linalg import LinAlgError, cho_solve_banded, cholesky_banded
from scipy.sparse.linalg import splu

CHUNK = 2048  # right-hand sides solved at once (memory: CHUNK x unknowns doubles)
RIDGE = 1e-10  # relative damping of J^T J's diagonal: an unknown no row determines stays put, never NaN
MAX_BAND = 64  # widest band of the velocities' block the selected inversion takes (n p^2 work, against the solves' n^2):
# a reference differenced from two fixes spans every ping of its window (winriver01: 27; 8 sent it to the solves)


def as_sparse(J) -> sp.csr_matrix:
    return J.tocsr() if sp.issparse(J) else sp.csr_matrix(np.asarray(J, dtype=float))


def factor(A: sp.spmatrix, relative_ridge: float = RIDGE):
    """Sparse LU of a normal matrix with a relative ridge on its diagonal."""
    return splu(ridged(A, relative_ridge))


def ridged(A: sp.spmatrix, relative_ridge: float = RIDGE) -> sp.csc_matrix:
    d = np.asarray(A.diagonal()).ravel()
    return sp.csc_matrix(A + sp.diags(relative_ridge * np.maximum(d, 1e-12)))


def leverages(A: sp.spmatrix, J, local: np.ndarray | None = None, lu=None) -> np.ndarray:
    """diag(J A^-1 J^T), A symmetric positive definite (ridge included). With ``local`` (columns
    each row touches a few neighbours of: the velocities per ping) by selected inversion of the
    banded local block and a Schur complement on the rest (:func:`arrow_leverages`, linear in the
    pings); otherwise, or when the band is wide, by solves against a sparse LU (``lu`` when the
    caller has factored A already)."""
    J = as_sparse(J)
    if local is not None and np.any(local):
        h = arrow_leverages(A, J, np.asarray(local, dtype=bool))
        if h is not None:
            return h
    return quadratic_diagonal(lu if lu is not None else splu(sp.csc_matrix(A)), J)


def arrow_leverages(A: sp.spmatrix, J: sp.csr_matrix, local: np.ndarray) -> np.ndarray | None:
    """diag(J A^-1 J^T) for A = [[B, C], [C^T, D]] with B (the ``local`` columns) banded:
    a J_L B^-1 J_L^T a (the band of B^-1 by Takahashi's recurrences on B's banded Cholesky factor)
    plus u S^-1 u^T, u = J_G - J_L B^-1 C, S = D - C^T B^-1 C. None when B's band is wider than
    :data:`MAX_BAND` or B is not positive definite (the caller then solves)."""
    loc, glob = np.flatnonzero(local), np.flatnonzero(~local)
    A = sp.csc_matrix(A)
    Lb = banded_cholesky(A[loc][:, loc])
    if Lb is None:
        return None
    p, n = Lb.shape[0] - 1, loc.size
    zb = band_of_inverse(Lb)
    Z = sp.diags([zb[d, :n - d] for d in range(p + 1)] + [zb[d, :n - d] for d in range(1, p + 1)],
                 list(range(0, -p - 1, -1)) + list(range(1, p + 1)), shape=(n, n), format="csr")
    JL = J[:, loc]
    h = np.asarray(JL.multiply(JL @ Z).sum(axis=1)).ravel()
    if glob.size:
        C = A[loc][:, glob].toarray()
        BC = cho_solve_banded((Lb, True), C)
        S = A[glob][:, glob].toarray() - C.T @ BC
        U = J[:, glob].toarray() - JL @ BC
        h += np.sum((U @ np.linalg.pinv(S, hermitian=True)) * U, axis=1)
    return h


def banded_cholesky(B: sp.spmatrix) -> np.ndarray | None:
    """B's Cholesky factor L in lower banded storage (Lb[d, j] = L[j + d, j]); None when B's band
    is wider than :data:`MAX_BAND` or B is not positive definite."""
    B = sp.coo_matrix(B)
    p = int(np.max(np.abs(B.row - B.col))) if B.nnz else 0
    if p > MAX_BAND:
        return None
    lower = B.row >= B.col
    ab = np.zeros((p + 1, B.shape[0]))
    np.add.at(ab, (B.row[lower] - B.col[lower], B.col[lower]), B.data[lower])
    try:
        return cholesky_banded(ab, lower=True)
    except LinAlgError:
        return None


def band_of_inverse(Lb: np.ndarray) -> np.ndarray:
    """The band of (L L^T)^-1 from L in lower banded storage (Lb[d, j] = L[j + d, j]), same
    storage, by Takahashi's recurrences (L^T Z = L^-1, upper part zero): for j from the last,
    Z[j, i] = (delta_ij / L_jj - sum_k L_kj Z_ki) / L_jj, k = j+1..j+p, i = j+p..j. A narrow band
    (the velocities per ping: p = 3) runs the recurrence as a CasADi ``mapaccum`` (a 2995-ping
    transect's 8985 steps 66 -> 8 ms); a wide one steps in numpy, as the symbolic step grows as p^2
    (p = 64: 4 s to build, three times slower to run)."""
    p, n = Lb.shape[0] - 1, Lb.shape[1]
    if p == 0:
        return 1.0 / Lb**2
    if p <= MAX_SYMBOLIC_BAND:
        return _band_of_inverse_mapaccum(Lb)
    zb = np.zeros_like(Lb)
    grids = {}
    for j in range(n - 1, -1, -1):
        m, Ljj = min(p, n - 1 - j), Lb[0, j]
        if m == 0:
            zb[0, j] = 1.0 / Ljj**2
            continue
        if m not in grids:
            a, b = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
            grids[m] = (np.abs(a - b), np.minimum(a, b))
        dist, low = grids[m]
        w = Lb[1:m + 1, j]
        row = -(w @ zb[dist, j + 1 + low]) / Ljj  # Z[j, j+1..j+m]
        zb[1:m + 1, j] = row
        zb[0, j] = (1.0 / Ljj - w @ row) / Ljj
    return zb


MAX_SYMBOLIC_BAND = 8  # widest band whose recurrence runs as a CasADi mapaccum (p = 16: 0.2 s to build)
TAKAHASHI_STEPS = 1024  # steps per mapaccum call: its outputs hold the p x p window at every step


@functools.lru_cache(maxsize=64)
def _takahashi(p: int, steps: int) -> ca.Function:
    """``steps`` of the recurrence from the last column back: state W = Z[j+1:j+1+p, j+1:j+1+p] (zero beyond
    the matrix), input column j of Lb, output [Z_jj, Z[j, j+1..j+p]]."""
    W, col = ca.SX.sym("W", p, p), ca.SX.sym("L", p + 1)
    w, Ljj = col[1:], col[0]
    row = -ca.mtimes(W, w) / Ljj
    zjj = (1.0 / Ljj - ca.dot(w, row)) / Ljj
    after = ca.blockcat([[zjj, row[:p - 1].T], [row[:p - 1], W[:p - 1, :p - 1]]]) if p > 1 else zjj
    return ca.Function("takahashi_step", [W, col], [after, ca.vertcat(zjj, row)]).mapaccum("takahashi", steps)


def _band_of_inverse_mapaccum(Lb: np.ndarray) -> np.ndarray:
    p, n = Lb.shape[0] - 1, Lb.shape[1]
    L = Lb.copy()
    for d in range(1, p + 1):  # the storage's slots past the matrix's last row take no part
        L[d, max(n - d, 0):] = 0.0
    L = L[:, ::-1]
    W, out = ca.DM.zeros(p, p), np.empty_like(L)
    for a in range(0, n, TAKAHASHI_STEPS):
        m = min(TAKAHASHI_STEPS, n - a)
        windows, columns = _takahashi(p, m)(W, L[:, a:a + m])
        W, out[:, a:a + m] = windows[:, -p:], np.asarray(columns)
    return out[:, ::-1]


def inverse_diagonal(A: sp.spmatrix, lu=None) -> np.ndarray:
    """diag(A^-1), A symmetric positive definite: from the band of the inverse (Takahashi's
    recurrences on A's banded Cholesky factor, linear in its size) when A's band is at most
    :data:`MAX_BAND` wide, as the velocities per ping are; else by solves against a sparse LU
    (``lu`` when the caller has factored A already: as many solves as A has rows)."""
    A = sp.csc_matrix(A)
    Lb = banded_cholesky(A)
    if Lb is not None:
        return band_of_inverse(Lb)[0]
    return quadratic_diagonal(lu if lu is not None else splu(A), sp.identity(A.shape[0], format="csr"))


def quadratic_diagonal(lu, J: sp.csr_matrix) -> np.ndarray:
    """diag(J A^-1 J^T) for the factor ``lu`` of A: each row's leverage."""
    out = np.zeros(J.shape[0])
    for start in range(0, J.shape[0], CHUNK):
        block = J[start:start + CHUNK]
        X = lu.solve(block.T.toarray())  # A^-1 J_block^T
        out[start:start + CHUNK] = np.asarray(block.multiply(X.T).sum(axis=1)).ravel()
    return out


def leave_out_predictions(J, e: np.ndarray, used: np.ndarray, fold_of: np.ndarray, damping: float = 1e-6,
                          local: np.ndarray | None = None) -> np.ndarray:
    """Weighted residuals of each fold predicted with that fold left out, divided by
    sqrt(1 + leverage): one Gauss-Newton step from the full fit (see ``diagnosis.heldout.cv_residuals``).
    ``local``: the columns :func:`leverages` may invert by their band."""
    J = as_sparse(J)
    Ju_all = J[np.flatnonzero(used)]
    A_all = ridged((Ju_all.T @ Ju_all).tocsc(), damping)
    b_all = Ju_all.T @ e[used]
    pred = np.zeros_like(e)
    for k in np.unique(fold_of):
        out = fold_of == k
        Jo = J[np.flatnonzero(out)]
        Ju = J[np.flatnonzero(out & used)]
        A = sp.csc_matrix(A_all - Ju.T @ Ju)
        lu = splu(A)
        step = -lu.solve(b_all - Ju.T @ e[out & used])
        leverage = leverages(A, Jo, local, lu)
        pred[out] = (e[out] + Jo @ step) / np.sqrt(1.0 + np.maximum(leverage, 0.0))
    return pred


def log_det_normal(J) -> float:
    """log det(J^T J) (ridge included) from one sparse LU: the sum of log |U_ii|."""
    J = as_sparse(J)
    if J.shape[1] == 0:
        return 0.0
    return float(np.sum(np.log(np.abs(factor((J.T @ J).tocsc()).U.diagonal()))))


def inverse_columns(J, index) -> np.ndarray:
    """Columns ``index`` of (J^T J)^-1 (unknowns x len(index)), by solves against one sparse LU."""
    J = as_sparse(J)
    index = np.asarray(index, dtype=int)
    E = np.zeros((J.shape[1], index.size))
    E[index, np.arange(index.size)] = 1.0
    return factor((J.T @ J).tocsc()).solve(E) if index.size else E


def marginal_covariance(J, index, s2: float = 1.0) -> np.ndarray:
    """Covariance block s2 (J^T J)^-1 [index, index] of the unknowns ``index`` (columns of J)."""
    index = np.asarray(index, dtype=int)
    if index.size == 0:
        return np.zeros((0, 0))
    C = inverse_columns(J, index)[index]
    return s2 * 0.5 * (C + C.T)


def redundancy(J, row_group: np.ndarray, used: np.ndarray, n_groups: int, local: np.ndarray | None = None) -> np.ndarray:
    """Redundancy of each group of rows, r_g = n_g - sum of its rows' leverages (the degrees of
    freedom its residuals carry: Helmert / Foerstner variance-component estimation)."""
    J = as_sparse(J)
    rows = np.flatnonzero(used)
    Ju = J[rows]
    h = leverages(ridged((Ju.T @ Ju).tocsc()), Ju, local)
    r = np.zeros(n_groups)
    np.add.at(r, row_group[rows], 1.0 - np.clip(h, 0.0, 1.0))
    return r


VCE_RTOL = 0.01  # noise levels settled: none moved by more than this at the last re-estimation


def largest_move(new: dict, old: dict) -> float:
    """The largest relative change of a noise level from ``old`` to ``new`` (same keys)."""
    return max(abs(v / old[k] - 1.0) for k, v in new.items())


SCORING_MAX_UNKNOWNS = 1500  # Fisher scoring forms the inverse normal matrix dense and one product per group (0.1 s
# a step at 900 unknowns, 1.7 s at 2500, where the redundancies' iteration is cheaper even taking three times the steps)
SCORING_MAX_STEP = np.log(4.0)  # the largest change of a log-variance in one scoring step


def scored_levels(J, raw: np.ndarray, row_group: np.ndarray, used: np.ndarray, keys: list, levels: dict,
                  stated: tuple = ("prior",)) -> dict | None:
    """``levels`` after one Fisher-scoring step of the restricted likelihood in the log-variances,
    for the linearised model whose weighted-residual Jacobian ``J`` was taken at ``levels``: with
    M = (J^T J)^-1 and X_g = M J_g^T J_g, the score of group g is (e_g^T e_g / s_g^2 - r_g) / 2
    (r_g = n_g - tr X_g, its redundancy) and the information (delta_gh (n_g - 2 tr X_g) +
    tr X_g X_h) / 2. Its fixed point is :func:`group_levels`' (s_g^2 = e_g^T e_g / r_g), reached in
    a few steps where that iteration crawls because groups trade the same unknowns (the beams', the
    reference's and a walk's levels sharing the velocities: RiverPro's vertical level still 2.5 % a
    round after twelve). Each step is at most ``SCORING_MAX_STEP`` in a log-variance. None above
    ``SCORING_MAX_UNKNOWNS`` (the caller iterates :func:`group_levels` instead); groups as there: a
    group with a redundancy of at most 1 keeps its level (a level heading for zero, as a walk's
    vertical one does where the beams cannot resolve the boat's heave, would halve at every step
    and never settle)."""
    J = as_sparse(J)
    if J.shape[1] > SCORING_MAX_UNKNOWNS:
        return None
    rows = np.flatnonzero(used)
    Ju, g, ru = J[rows], row_group[rows], raw[rows]
    N = ridged((Ju.T @ Ju).tocsc()).toarray()
    try:
        M = np.linalg.inv(N)
    except np.linalg.LinAlgError:
        return None
    groups, X, score, size = [], [], [], []
    for i, key in enumerate(keys):
        m = g == i
        if key[1] in stated or m.sum() <= 3:
            continue
        Jg = Ju[m]
        Xg = np.asarray((Jg.T @ Jg) @ M).T  # M Jg^T Jg (both symmetric), dense
        r = Jg.shape[0] - np.trace(Xg)
        if r <= 1.0:  # under a degree of freedom: the level is not estimable (it heads for zero), held as group_levels holds it
            continue
        groups.append(i)
        X.append(Xg)
        score.append(0.5 * (np.sum(ru[m] ** 2) / levels[key] ** 2 - r))
        size.append(Jg.shape[0])
    info = np.array([[0.5 * ((size[a] - 2 * np.trace(X[a])) * (a == b) + np.sum(X[a] * X[b].T)) for b in range(len(groups))]
                     for a in range(len(groups))])
    try:
        step = np.linalg.solve(info, np.array(score))
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(step)):  # a non-finite residual or Jacobian entry: the caller's plain step decides
        return None
    out = dict(levels)
    for i, d in zip(groups, np.clip(step, -SCORING_MAX_STEP, SCORING_MAX_STEP)):
        out[keys[i]] = float(max(levels[keys[i]] * np.exp(0.5 * d), 1e-6))
    return out


def group_levels(raw: np.ndarray, row_group: np.ndarray, used: np.ndarray, keys: list, r: np.ndarray,
                 levels: dict, stated: tuple = ("prior",)) -> dict:
    """``levels`` with each group's noise level re-estimated as its residuals over its redundancy
    ``r`` (:func:`redundancy`): sqrt(e_g^T e_g / r_g), where the group has more than 3 rows and 1
    degree of freedom; groups whose width is ``stated`` (a prior's), not estimated, keep theirs."""
    out = dict(levels)
    for i, key in enumerate(keys):
        m = (row_group == i) & used
        if key[1] not in stated and m.sum() > 3 and r[i] > 1.0:
            out[key] = float(max(np.sqrt(np.sum(raw[m] ** 2) / r[i]), 1e-6))
    return out
