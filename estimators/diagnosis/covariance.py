"""Covariances and standard errors of a fit's unknowns, and the detection limits they give.

White (:func:`covariance`: scaled by the fit's chi-square) to tell an effect from the unknowns it
shares its variance with; under coloured residuals (:func:`coloured_covariance`: the Newey-West
sandwich over time bins of a ping interval, each variance at least the white one) for what an
estimate is reported with, since a real file's residuals wander slowly and white errors would
claim more than its data hold; and the smallest size of an unknown the selection would take
(:func:`detection_limits`).
"""

from __future__ import annotations

import numpy as np

from ..statistics.hac import at_least_white, ping_bins, sandwich
from ..statistics.normal_equations import as_sparse, inverse_columns, marginal_covariance
from ..measurement_model import PRIOR_GROUPS
from .model import Fit, GapModel, free_jacobian


def covariance(fit: Fit, model: GapModel, index) -> np.ndarray:
    """Covariance of the scaled unknowns ``index`` (a pinned one or one at its bound: zero),
    scaled by the fit's chi-square."""
    index = np.asarray(index, dtype=int)
    J, cols = free_jacobian(fit)
    dof = max(int((model.mask > 0).sum()) - cols.size, 1)
    s2 = 2.0 * fit.objective / dof
    position = {c: j for j, c in enumerate(cols)}
    inside = [j for j, i in enumerate(index) if i in position]
    C = np.zeros((index.size, index.size))
    if inside:
        sub = marginal_covariance(J, [position[index[j]] for j in inside], s2)
        C[np.ix_(inside, inside)] = sub
    return C


def standard_errors(fit: Fit, model: GapModel, index) -> np.ndarray:
    """Standard errors of the unknowns ``index`` in their own units (:func:`covariance`'s diagonal)."""
    return np.sqrt(np.maximum(np.diag(covariance(fit, model, index)), 0)) * fit.scale[index]


def _hac_covariance(fit: Fit, model: GapModel, index) -> np.ndarray:
    """Covariance of the unknowns ``index`` (own units) under coloured residuals: the Newey-West
    sandwich (:func:`..statistics.hac.sandwich`) over time bins of a ping interval, the priors'
    rows counted by their expected information. An unknown held at a bound is freed for it: its
    variance is then what the data would give it near there (a detection limit's scale)."""
    index = np.asarray(index, dtype=int)
    if index.size == 0:
        return np.zeros((0, 0))
    J = as_sparse(fit.jacobian)
    free = np.ones(J.shape[1], dtype=bool) if fit.free is None else fit.free.astype(bool).copy()
    free[index] = True
    cols = np.flatnonzero(free)
    scale = fit.scale[index]
    return hac_of_columns(J[:, cols], np.searchsorted(cols, index), model, fit) * np.outer(scale, scale)


def hac_of_columns(J, q, model: GapModel, fit: Fit) -> np.ndarray:
    """The HAC covariance of columns ``q`` of the weighted-residual Jacobian ``J`` (the model's rows,
    any columns: the fit's free unknowns, or those and a signature), at the fit's residuals."""
    P_q = inverse_columns(J, q)
    used = model.mask > 0
    e = np.where(used, model.weights(fit.sigma) * fit.raw, 0.0)
    prior = np.isin(model.row_sigma, [i for i, k in enumerate(model.sigma_keys) if k[1] in PRIOR_GROUPS])
    rows = used | prior
    return sandwich(as_sparse(J)[np.flatnonzero(rows)], e[rows], P_q, model.row_run[rows], model.times[rows],
                    ping_bins([r.case for r in model.base.runs]), known=prior[rows]).cov


def hac_standard_errors(fit: Fit, model: GapModel, index) -> np.ndarray:
    """Standard errors of the unknowns ``index`` (own units) under coloured residuals (:func:`_hac_covariance`)."""
    return np.sqrt(np.maximum(np.diag(_hac_covariance(fit, model, index)), 0.0))


def coloured_covariance(fit: Fit, model: GapModel, index) -> np.ndarray:
    """Covariance of the unknowns ``index`` (own units) an estimate is reported with: the HAC one's
    correlations, each variance at least the white one (coloured residuals never make an unknown
    better determined than white ones would)."""
    hac = _hac_covariance(fit, model, index)
    white = standard_errors(fit, model, index)
    out = at_least_white(hac, white ** 2)
    missing = ~(np.diag(hac) > 0)  # no HAC information (a pinned unknown): the white variance alone
    out[missing, :] = out[:, missing] = 0.0
    out[missing, missing] = white[missing] ** 2
    return out


def detection_limits(names: list, se_hac: np.ndarray, n_params: int, n_obs: int, bic_margin: float) -> dict:
    """Smallest size of each unknown the selection would take: an effect joins when
    z^2 > k log n + margin under coloured residuals (its coloured BIC gain beyond the margin), so
    the limit is its HAC standard error times sqrt(k log n + margin)."""
    factor = np.sqrt(n_params * np.log(n_obs) + bic_margin)
    return {n: float(s * factor) for n, s in zip(names, se_hac)}
