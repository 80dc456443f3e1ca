"""Standard errors under coloured residuals: a Newey-West sandwich on the Gauss-Newton normal
equations.

With J the Jacobian of the noise-weighted residuals e at the estimate and P the (pseudo-)
inverse of the information J^T J in the determined subspace, white residuals give
cov = P. Real residuals are coloured (lag-1 autocorrelation 0.5-0.97 on every real file:
motion the model does not follow, GNSS filters, bottom-track averaging), and then
cov = P M P with M the long-run covariance of the scores. Each row's score J_row^T e_row is
summed over the rows of one time bin of one run (all channels: attitude, bottom track,
ranges, reference), so correlation across channels at the same time is kept; M is the
Bartlett-weighted (Newey-West) sum of the bins' autocovariances within each run, runs
independent of each other. The bandwidth follows Andrews (1991)'s AR(1) plug-in.
Only the columns Q of interest (the shared unknowns) are carried: (P M P)_QQ = G^T G
with G the influence of each bin on them, so the cost is bins x |Q|^2 x lags.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_RHO = 0.97  # AR(1) coefficient cap in the bandwidth rule (a unit root has no long-run variance)


@dataclass
class Sandwich:
    """Long-run covariance of the unknowns Q, and how it was formed."""

    cov: np.ndarray  # (q, q)
    lags: list  # bandwidth per run
    rho: list  # AR(1) coefficient of the influence series per run (the largest over Q)
    bins: list  # number of time bins per run


def andrews_lags(series: np.ndarray) -> tuple[int, float]:
    """Bartlett bandwidth from AR(1) fits of each standardised column (Andrews 1991, Eq. 6.4),
    and the largest |rho|."""
    T = series.shape[0]
    if T < 4:
        return 0, 0.0
    x = series - series.mean(axis=0)
    sd = x.std(axis=0)
    x = x[:, sd > 1e-12 * max(sd.max(initial=0.0), 1e-300)]
    if x.shape[1] == 0:
        return 0, 0.0
    x = x / x.std(axis=0)
    rho = np.clip(np.sum(x[1:] * x[:-1], axis=0) / np.sum(x[:-1] ** 2, axis=0), -MAX_RHO, MAX_RHO)
    s2 = 1 - rho**2  # innovation variance of a unit-variance AR(1)
    num = np.sum(4 * rho**2 * s2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2))
    den = np.sum(s2**2 / (1 - rho) ** 4)
    alpha = num / den if den > 0 else 0.0
    lags = int(np.ceil(1.1447 * (alpha * T) ** (1 / 3)))
    return min(lags, T - 1), float(np.max(np.abs(rho)))


def newey_west(series: np.ndarray, lags: int) -> np.ndarray:
    """sum_t g_t g_t^T + sum_{l=1..L} (1 - l / (L + 1)) (Gamma_l + Gamma_l^T)."""
    M = series.T @ series
    for lag in range(1, lags + 1):
        gamma = series[lag:].T @ series[:-lag]
        M += (1 - lag / (lags + 1)) * (gamma + gamma.T)
    return M


def ping_bins(cases) -> dict:
    """The time bins of :func:`sandwich` and of per-bin series: each run's median ping interval (s),
    keyed by the run's index in ``cases``."""
    return {k: float(np.median(np.diff(case.pings.time_s))) for k, case in enumerate(cases)}


def sandwich(J, e: np.ndarray, P_q: np.ndarray, row_run: np.ndarray, row_time: np.ndarray,
             bin_s: dict, known: np.ndarray | None = None) -> Sandwich:
    """HAC covariance of the unknowns Q.

    Parameters
    ----------
    J : (m, n) array or scipy sparse
        Jacobian of the weighted residuals w.r.t. the scaled unknowns.
    e : (m,) weighted residuals at the estimate.
    P_q : (n, q) columns Q of the white covariance P (its pseudo-inverse part).
    row_run, row_time : (m,) run index and time of each residual row.
    bin_s : {run: bin width in seconds} (e.g. the run's median ping interval).
    known : (m,) bool, optional
        Rows whose information is known rather than sampled (a prior's pseudo-residuals):
        they add their expected meat (J_k P_q)^T (J_k P_q), not their one realisation.
    """
    e = np.asarray(e, dtype=float).ravel()
    JP = np.asarray(J @ P_q)
    q = P_q.shape[1]
    cov = np.zeros((q, q))
    known = np.zeros(e.size, dtype=bool) if known is None else np.asarray(known, dtype=bool)
    if known.any():
        cov += JP[known].T @ JP[known]
    influence = JP  # (m, q): each row's pull on the unknowns Q, in place (10^5 pings: 200 MB a copy)
    influence *= e[:, None]
    lags, rhos, counts = [], [], []
    for run in np.unique(row_run[~known]):
        rows = np.flatnonzero(row_run == run)
        t = row_time[rows]
        width = float(bin_s[int(run)])
        b = np.floor((t - t.min()) / width).astype(int)
        pull = influence[rows[0]:rows[-1] + 1] if rows[-1] - rows[0] + 1 == rows.size else influence[rows]  # a view if contiguous
        series = np.stack([np.bincount(b, weights=pull[:, j], minlength=b.max() + 1) for j in range(q)], axis=1) \
            if q else np.zeros((b.max() + 1, 0))  # per-bin sums (np.add.at took 0.3 s at 10^5 pings)
        series = series[np.bincount(b, minlength=b.max() + 1) > 0]
        L, rho = andrews_lags(series)
        cov += newey_west(series, L)
        lags.append(L), rhos.append(rho), counts.append(series.shape[0])
    return Sandwich(cov, lags, rhos, counts)


def at_least_white(cov: np.ndarray, white_var: np.ndarray) -> np.ndarray:
    """A HAC covariance with each variance raised to at least the white one (``white_var``), its
    correlations kept: coloured residuals never make an unknown better determined than white ones
    would. An unknown without HAC information (variance 0) is left as it is."""
    d = np.diag(cov)
    ratio = np.sqrt(np.where(d > 0, np.maximum(1.0, white_var / np.where(d > 0, d, 1.0)), 1.0))
    return ratio[:, None] * cov * ratio[None, :]
