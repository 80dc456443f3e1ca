"""What a recorded file could show of a field error at best: the residuals the error writes
(injected forward on the recorded channels, :mod:`.field_errors`), off everything the base's
unknowns absorb (the per-ping velocities included), against the noise under coloured residuals.
Its smallest detectable size bounds every detector's, the catalog effect's included: an error
under it is one this file cannot show, whatever model is fitted.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from concurrent.futures import ThreadPoolExecutor

from ...models.effects import get_effect
from .base import applicable, base_from, effect_terms
from .config import DiagnosisConfig
from .covariance import hac_of_columns
from .field_errors import FIELD_ERRORS, inject_survey
from .model import Fit, GapModel, free_jacobian
from .profiles import fit_at_delay
from ..statistics.normal_equations import as_sparse, inverse_columns

SEARCH = (1.0 / 16.0, 4.0)  # sizes searched: from the smallest typical one over 16 to the largest times 4
BISECTIONS = 7  # the search spans about 7 octaves: a limit to about 5 %


def signal_statistic(model: GapModel, fit: Fit, case, error: str, size: float, config: DiagnosisConfig,
                     calibration=None) -> tuple | None:
    """(noncentrality, colour inflation) of ``error`` at ``size`` written into ``case`` (a run, or
    a survey's runs: the same error in each, :func:`.field_errors.inject_survey`), on the base
    ``model`` fitted as ``fit``: lambda = d'(I - H)d, d the weighted residuals' change at the fit's
    unknowns, H the hat matrix of its free unknowns (lambda is 2 x the log-likelihood a model that
    reproduced the error exactly would gain, to first order); the inflation is the HAC variance of
    that model's size over its white one. None when the injected case makes a different model
    (another attitude source, other rows)."""
    other = GapModel(base_from(inject_survey(case, error, size, calibration), config, calibration), solver=config.solver)
    if other.names != model.names or other.mask.shape != model.mask.shape:
        return None
    z = fit.x / fit.scale
    same = (other.mask > 0) == (model.mask > 0)
    d = other.weighted_residuals(z, fit.sigma) - model.weighted_residuals(z, fit.sigma)
    d = np.nan_to_num(np.where(same, d, 0.0))
    if not np.any(d):
        return 0.0, 1.0
    J, _ = free_jacobian(fit)
    Ja = sp.hstack([as_sparse(J), sp.csr_matrix(d[:, None])]).tocsr()
    last = Ja.shape[1] - 1
    white = float(inverse_columns(Ja, [last])[last, 0])
    if not white > 0:
        return 0.0, 1.0
    hac = float(hac_of_columns(Ja, [last], model, fit)[0, 0])
    return 1.0 / white, max(hac / white, 1.0)


def selection_bar(model: GapModel, config: DiagnosisConfig, k: int) -> float:
    """The coloured BIC's bar for ``k`` unknowns on ``model``'s observations: k log n + margin
    (in units of 2 x log-likelihood)."""
    return k * np.log(int((model.mask > 0).sum())) + config.bic_margin


def signal_limit(model: GapModel, fit: Fit, case, error: str, config: DiagnosisConfig, calibration=None) -> dict | None:
    """The smallest size of ``error`` whose signature passes the selection's coloured BIC bar
    (lambda / inflation > k log n + margin, k the catalog effect's unknowns), by bisection in log
    size over :data:`SEARCH` around the error's typical sizes: {"size", "beyond": True when not
    even the largest searched size passes, "below": True when the smallest already does}; None
    where the injected case makes another model."""
    typical = FIELD_ERRORS[error][2]
    bar = selection_bar(model, config, len(get_effect(FIELD_ERRORS[error][0]).parameters))

    def passes(size):
        stat = signal_statistic(model, fit, case, error, size, config, calibration)
        return None if stat is None else stat[0] / stat[1] > bar

    lo, hi = min(typical) * SEARCH[0], max(typical) * SEARCH[1]
    top = passes(hi)
    if top is None:
        return None
    if not top:
        return {"size": float(hi), "beyond": True, "below": False}
    if passes(lo):
        return {"size": float(lo), "beyond": False, "below": True}
    for _ in range(BISECTIONS):
        mid = np.sqrt(lo * hi)
        ok = passes(mid)
        if ok is None:
            return None
        lo, hi = (lo, mid) if ok else (mid, hi)
    return {"size": float(hi), "beyond": False, "below": False}


ATTITUDE_DELAY = "attitude_latency.delay_s"
DELAY_STEP_S = 0.25  # the attitude-delay profile's grid: a fraction of any ping interval here (0.5-1.3 s)


def own_delay_profile(model: GapModel, fit: Fit, config: DiagnosisConfig) -> dict | None:
    """The clean file's own attitude-delay profile: the log-likelihood over the base's of an attitude
    latency pinned on a grid over the effect's bounds, each model exact at its delay (the sensor's
    samples taken about t + d, as the diagnosis re-centres them). An injected latency s only shifts
    the time stamps, so the injected file's profile is this one moved by s (checked on RiverPro: to
    within the grid's ripple): where this one rises above the one-unknown bar ((log n + margin) / 2)
    away from zero, a latency is read against that peak, not zero, and no size of it is told on the
    file. {"delays", "gain", "peak_s", "rise", "bar"}; None off the sensor's samples (a motion
    model's attitude is not shifted) or where the effect does not apply."""
    base = model.base
    if not base.sampled or not applicable(base, "attitude_latency")[0]:
        return None
    terms = effect_terms(base, "attitude_latency")  # its refits seed no frequency: no residual peaks needed
    bound = next(p for p in get_effect("attitude_latency").parameters if p.name == "delay_s")
    delays = np.round(np.arange(bound.lower, bound.upper + 1e-9, DELAY_STEP_S), 6)
    base_ll = fit.log_likelihood(model)

    def at(d: float) -> float:
        m, f = fit_at_delay(base, terms, {}, config, "sample_shift_s", ATTITUDE_DELAY, d, fit.values, fit.sigma)
        return float(f.log_likelihood(m) - base_ll)

    with ThreadPoolExecutor(max_workers=2) as pool:  # CasADi lets go of Python's lock
        gain = np.array(list(pool.map(at, delays)))
    best = int(np.argmax(gain))
    zero = int(np.argmin(np.abs(delays)))
    return {"delays": delays.tolist(), "gain": gain.tolist(), "peak_s": float(delays[best]),
            "rise": float(gain[best] - gain[zero]),
            "bar": selection_bar(model, config, 1) / 2}
