"""The held-out gap, and two models compared row by row.

The gap: excess chi-square per sample of residuals predicted on held-out time blocks (one
Gauss-Newton step from the full fit with the block left out, :func:`cv_residuals`), in units of
the noise levels: 0 when the model is as good as the noise; with several runs also with whole runs
held out. Held out, so that a model is judged by what it predicts, not by how much it can fit.

Two models' residuals compared row by row and summed per time bin (a ping interval): whether one
predicts the held-out data significantly better (:func:`heldout_improvement_z`), and how much
coloured residuals inflate an in-sample likelihood ratio (:func:`colour_factor`).
"""

from __future__ import annotations

import numpy as np

from ..statistics.hac import andrews_lags, newey_west, ping_bins
from ..statistics.normal_equations import leave_out_predictions
from ..measurement_model import PRIOR_GROUPS
from .model import Fit, GapModel, free_jacobian, velocity_columns

FOLD_SEED = 20261125  # the held-out blocks' dealing to folds: shuffled, the same every call


def row_folds(model, folds: int, block_s: float) -> np.ndarray:
    """Fold of every row: each run cut into contiguous blocks of about ``block_s``, dealt to the folds
    in a shuffled balanced order (seeded: the same every call). Dealt round-robin, a channel sampled
    every folds x block_s seconds (a GNSS fix every 10 s with 5 folds of 2-s blocks: winriver01) put
    every one of its rows in one fold, so that fold's model had none of it.

    With a velocity per ping (random walk) the channel groups of one block go to different folds:
    the reference held out is predicted from the beams at the same pings (and the beams from the
    reference), never from the prior bridging a hole in every channel at once."""
    row_run = getattr(model, "row_run", np.zeros(model.times.size, dtype=int))
    fold_of = np.zeros(model.times.size, dtype=int)
    for k in np.unique(row_run):
        rows = row_run == k
        t = model.times[rows]
        n_blocks = max(folds, int(round((t.max() - t.min()) / block_s)))
        edges = np.linspace(t.min(), t.max() + 1e-9, n_blocks + 1)
        deal = np.random.default_rng(FOLD_SEED + int(k)).permutation(n_blocks) % folds
        fold_of[rows] = deal[np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n_blocks - 1)]
    if getattr(model, "random_walk", False):  # each channel group of a block held out in a fold of its own
        groups = list(dict.fromkeys(k[1] for k in model.sigma_keys))
        shift = np.array([groups.index(k[1]) for k in model.sigma_keys])[model.row_sigma]
        fold_of = (fold_of + shift) % folds
    return fold_of


def cv_residuals(model, fit, folds: int, block_s: float, fold_of: np.ndarray | None = None) -> np.ndarray:
    """Raw residuals of each held-out fold predicted by the fit with that fold left out.

    The leave-fold-out estimate is one Gauss-Newton step from the full fit, damped by a
    millionth of the full-data information so a direction only the fold determines stays
    put. Unknowns pinned or held at a bound are not re-estimated (the step would otherwise
    follow the bound's pull and fit the held-out data). ``fold_of`` (rows): default time
    blocks (:func:`row_folds`); whole runs for a run hold-out.

    Each prediction is divided by sqrt(1 + h), h = J_row (J_t^T J_t)^-1 J_row^T its leverage
    (the training fit's uncertainty in units of the noise): a correct model then predicts with
    unit chi-square whatever its number of unknowns (navigation knots, angles), so the gap
    measures misfit, not the model's flexibility.
    """
    J, cols = free_jacobian(fit)  # a pinned unknown or one at its bound stays put
    w = model.weights(fit.sigma)
    e = w * fit.raw
    fold_of = row_folds(model, folds, block_s) if fold_of is None else fold_of
    pred = leave_out_predictions(J, e, model.mask > 0, fold_of, local=velocity_columns(model, cols))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(w != 0, pred / np.where(w != 0, w, 1.0), 0.0)


def _gap_rows(model) -> np.ndarray:
    """Rows the gap is measured on: the data's (a random-walk prior's motion rows are not data)."""
    rows = model.mask > 0
    keys = getattr(model, "sigma_keys", None)
    if keys is not None:
        prior = [i for i, k in enumerate(keys) if k[1] in PRIOR_GROUPS]
        rows = rows & ~np.isin(model.row_sigma, prior)
    return rows


def heldout_gap(model: GapModel, raw: np.ndarray, sigma: dict) -> tuple[float, float]:
    """Excess chi-square per sample and its z-score against the noise levels.

    With a velocity per ping (random walk) the velocity follows the beams, and what they and the
    reference disagree on shows in the reference's few rows: the excess is then the mean of the
    channel groups' excesses (each group one vote, however many rows it has), its z against that
    mean's null sd sqrt(sum_g 2 / n_g) / G."""
    m = _gap_rows(model)
    s = np.array([sigma[k] for k in model.sigma_keys])[model.row_sigma]
    z2 = (raw / s) ** 2
    if not getattr(model, "random_walk", False):
        chi2 = float(np.mean(z2[m]))
        return chi2 - 1.0, (chi2 - 1.0) * np.sqrt(int(m.sum()) / 2.0)
    group_names = np.array([k[1] for k in model.sigma_keys])[model.row_sigma]
    excess, var = [], 0.0
    for g in dict.fromkeys(group_names[m]):
        rows = m & (group_names == g)
        excess.append(float(np.mean(z2[rows])) - 1.0)
        var += 2.0 / rows.sum()
    gap = float(np.mean(excess))
    return gap, gap / (np.sqrt(var) / len(excess))


def colour_factor(model: GapModel, fit: Fit, ref_model: GapModel, ref_fit: Fit, noise: dict) -> float:
    """How much coloured residuals inflate the likelihood ratio of an effect: each data row's
    contribution to 2 delta_ll, (e_ref / s)^2 - (e / s)^2, summed per time bin (a ping interval)
    of each run, and the Newey-West long-run variance of that series over its white variance
    (centred; Bartlett lags by Andrews' AR(1) plug-in; at least 1). A real file's slow wander makes
    neighbouring bins' gains agree, and 2 delta_ll / factor is then the white-equivalent statistic."""
    bins = _paired_bins(model, fit.raw, ref_model, ref_fit.raw, noise)
    if bins is None:
        return 1.0
    long_run = white = 0.0
    for series in bins:
        series = (series - series.mean())[:, None]
        lags, _ = andrews_lags(series)
        long_run += float(newey_west(series, lags)[0, 0])
        white += float(series[:, 0] @ series[:, 0])
    return max(long_run / white, 1.0) if white > 0 else 1.0


def _paired_bins(model: GapModel, raw: np.ndarray, ref_model: GapModel, ref_raw: np.ndarray, noise: dict,
                 weights: bool = False) -> list | None:
    """Per run, the series over time bins (a ping interval) of each data row's (e_ref / s)^2 - (e / s)^2,
    the reference model's residuals ``ref_raw`` against the model's ``raw`` at the common noise levels;
    with ``weights`` each row counts 1 / (groups x its group's rows), as :func:`heldout_gap` averages them
    (the bins then sum to the gap's change). None when the two models' data rows differ."""
    rows, rows_ref = _gap_rows(model), _gap_rows(ref_model)
    if rows.sum() != rows_ref.sum():
        return None
    s_ref = np.array([noise[k] for k in ref_model.sigma_keys])[ref_model.row_sigma[rows_ref]]
    s = np.array([noise[k] for k in model.sigma_keys])[model.row_sigma[rows]]
    d = (ref_raw[rows_ref] / s_ref) ** 2 - (raw[rows] / s) ** 2
    if weights:
        group = np.array([k[1] for k in model.sigma_keys])[model.row_sigma[rows]]
        names, count = np.unique(group, return_counts=True)
        d = d / (names.size * count[np.searchsorted(names, group)])
    run, t = model.row_run[rows], model.times[rows]
    widths = ping_bins([r.case for r in model.base.runs])
    out = []
    for r in np.unique(run):
        m = run == r
        b = np.floor((t[m] - t[m].min()) / widths[int(r)]).astype(int)
        out.append(np.bincount(b, weights=d[m])[np.bincount(b) > 0])
    return out


SAME_PREDICTION_RTOL = 1e-9  # held-out predictions this close to the reference's are the reference's


def heldout_improvement_z(model: GapModel, cv: np.ndarray, ref_model: GapModel, ref_cv: np.ndarray, noise: dict) -> float:
    """How significantly the model predicts the held-out data better than the reference model: the
    change of the held-out gap (:func:`heldout_gap`'s group-averaged excess) over its standard error, from
    the per-bin series of the paired row differences with a Newey-West long-run variance (real
    residuals are coloured). A paired test: it asks whether the effect predicts better, not how
    much of a gap that may hold other structure it removes (the shrink share)."""
    if not getattr(model, "random_walk", False):
        return float("nan")
    if cv.shape == ref_cv.shape and np.allclose(cv, ref_cv, rtol=SAME_PREDICTION_RTOL, atol=0.0):
        return 0.0  # the same predictions (an effect estimated at zero): no change, not the z of their rounding
    bins = _paired_bins(model, cv, ref_model, ref_cv, noise, weights=True)
    if bins is None:
        return float("nan")
    change = var = 0.0
    for series in bins:
        change += float(series.sum())
        c = (series - series.mean())[:, None]
        lags, _ = andrews_lags(c)
        var += float(newey_west(c, lags)[0, 0])  # the long-run variance of the bins' sum
    return change / np.sqrt(var) if var > 0 else float("nan")
