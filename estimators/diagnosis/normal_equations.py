"""Sparse least-squares algebra of a fitted diagnosis model: leverages, leave-fold-out
predictions, marginal covariances and variance components, from the weighted residual
Jacobian J (rows x free unknowns) without ever forming (J^T J)^-1.

A base whose navigation is a velocity per ping (random walk) has thousands of unknowns, each
touching a few rows: J^T J is sparse (block-tridiagonal in the velocities plus a few dense
columns), so one sparse LU factor and solves against the rows needed replace the dense inverse.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

CHUNK = 2048  # right-hand sides solved at once (memory: CHUNK x unknowns doubles)
RIDGE = 1e-10  # relative damping of J^T J's diagonal: an unknown no row determines stays put, never NaN


def as_sparse(J) -> sp.csr_matrix:
    return J.tocsr() if sp.issparse(J) else sp.csr_matrix(np.asarray(J, dtype=float))


def factor(A: sp.spmatrix, relative_ridge: float = RIDGE):
    """Sparse LU of a normal matrix with a relative ridge on its diagonal."""
    d = np.asarray(A.diagonal()).ravel()
    A = A + sp.diags(relative_ridge * np.maximum(d, 1e-12))
    return splu(sp.csc_matrix(A))


def quadratic_diagonal(lu, J: sp.csr_matrix) -> np.ndarray:
    """diag(J A^-1 J^T) for the factor ``lu`` of A: each row's leverage."""
    out = np.zeros(J.shape[0])
    for start in range(0, J.shape[0], CHUNK):
        block = J[start:start + CHUNK]
        X = lu.solve(block.T.toarray())  # A^-1 J_block^T
        out[start:start + CHUNK] = np.asarray(block.multiply(X.T).sum(axis=1)).ravel()
    return out


def leave_out_predictions(J, e: np.ndarray, used: np.ndarray, fold_of: np.ndarray, damping: float = 1e-6) -> np.ndarray:
    """Weighted residuals of each fold predicted with that fold left out, divided by
    sqrt(1 + leverage): one Gauss-Newton step from the full fit (see ``_cv_residuals``)."""
    J = as_sparse(J)
    Ju_all = J[np.flatnonzero(used)]
    A_all = (Ju_all.T @ Ju_all).tocsc()
    A_all = A_all + sp.diags(damping * np.maximum(np.asarray(A_all.diagonal()).ravel(), 1e-12))
    b_all = Ju_all.T @ e[used]
    pred = np.zeros_like(e)
    for k in np.unique(fold_of):
        out = fold_of == k
        Jo = J[np.flatnonzero(out)]
        Ju = J[np.flatnonzero(out & used)]
        lu = factor(A_all - Ju.T @ Ju, 0.0)
        step = -lu.solve(b_all - Ju.T @ e[out & used])
        leverage = quadratic_diagonal(lu, Jo)
        pred[out] = (e[out] + Jo @ step) / np.sqrt(1.0 + np.maximum(leverage, 0.0))
    return pred


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


def redundancy(J, row_group: np.ndarray, used: np.ndarray, n_groups: int) -> np.ndarray:
    """Redundancy of each group of rows, r_g = n_g - sum of its rows' leverages (the degrees of
    freedom its residuals carry: Helmert / Foerstner variance-component estimation)."""
    J = as_sparse(J)
    rows = np.flatnonzero(used)
    Ju = J[rows]
    h = quadratic_diagonal(factor((Ju.T @ Ju).tocsc()), Ju)
    r = np.zeros(n_groups)
    np.add.at(r, row_group[rows], 1.0 - np.clip(h, 0.0, 1.0))
    return r
