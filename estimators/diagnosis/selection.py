"""Scoring and choosing catalog effects in the forward selection.

Every applicable effect refitted on top of the current model is scored (:func:`score_effect`:
likelihood ratio, BIC and its coloured-residual version, the held-out gap's shrink, standard
errors and detection limits). Of the significant ones (:func:`significant`: BIC better by
``bic_margin`` and at least ``min_shrink`` of the held-out gap removed; on a random-walk base the
coloured BIC, and a smaller share or a paired held-out improvement) the one that shrinks the
held-out gap most comes first (:func:`preference`: one that contains another as a special case
only when its extra unknowns are significant). One stopped at a bound of its plausible range is
never significant (:func:`at_bounds`). An effect whose parameters share most of their variance
with a base unknown (or with an effect already chosen) cannot be told from it in these data
(:func:`confounding`): the report says which instead of claiming it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from ...models.effects import effect_of, get_effect
from .base import velocity_error
from .config import DiagnosisConfig
from .covariance import covariance, detection_limits, hac_standard_errors, standard_errors
from .heldout import colour_factor, heldout_gap, heldout_improvement_z
from .model import BOUND_TOL, Fit, GapModel


@dataclass
class EffectScore:
    effect: str
    delta_ll: float
    delta_bic: float
    p_value: float
    n_params: int
    params: dict
    params_se: dict
    gap_after: float
    shrink_fraction: float
    velocity_error_m_s: float | None
    success: bool
    status: str
    iterations: int
    colour_factor: float = 1.0  # long-run over white variance of the per-bin likelihood gains (>= 1)
    delta_bic_hac: float = 0.0  # -2 delta_ll / colour_factor + k log n: the BIC change under coloured residuals (negative: better)
    significant: bool = False
    confounded_with: list = field(default_factory=list)
    confounded_share: float = 0.0
    round: int = 1
    at_bound: list = field(default_factory=list)  # unknowns stopped at a bound of their range: not determined there
    detection_limit: dict = field(default_factory=dict)  # per unknown: the smallest size this file's selection takes
    heldout_z: float = float("nan")  # held-out gap change over its HAC standard error (random-walk base)
    ping: dict = field(default_factory=dict)  # random-walk base: the held-out evidence on ping-scale blocks
    # (gap_before, gap_after, shrink_fraction, heldout_z) where the long blocks show none (:func:`needs_ping_evidence`)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _shrink(ref_gap: float, gap_after: float) -> float:
    return (ref_gap - gap_after) / ref_gap if ref_gap > 0 else 0.0


def score_effect(name, model, fit, ref_model, ref_fit, ref_gap, cv, ref_cv, noise, n_obs, config, round_) -> EffectScore:
    """The effect's model (``model``, ``fit``, held-out residuals ``cv``) against the current one
    (``ref_*``): likelihood ratio, BICs, the held-out gap's shrink and paired z, SEs, detection limits."""
    k = len(model.effect_index) - len(ref_model.effect_index)
    dll = fit.log_likelihood(model) - ref_fit.log_likelihood(ref_model)
    dbic = -2.0 * dll + k * np.log(n_obs)
    gap_after, _ = heldout_gap(model, cv, noise)
    shrink = _shrink(ref_gap, gap_after)
    mine = [n for n in model.effect_names if effect_of(n) == name]
    idx = [model.names.index(n) for n in mine]
    values = {n: float(fit.x[i]) for n, i in zip(mine, idx)}
    colour = colour_factor(model, fit, ref_model, ref_fit, noise)
    # a profile's curvature counts white residuals: its SE widened by the same colour factor as the BIC
    white = standard_errors(fit, model, idx)
    hac = hac_standard_errors(fit, model, idx)
    limits = detection_limits(mine, np.maximum(hac, white), k, n_obs, config.bic_margin)
    # a free unknown's SE under coloured residuals (never below the white one, as the colour factor is at least 1)
    profiled = {n: v * np.sqrt(colour) for n, v in fit.profile_se.items() if n in mine}
    se = {**{n: float(max(h, w)) if w > 0 else 0.0 for n, h, w in zip(mine, hac, white)}, **profiled}
    finite = [n for n in profiled if np.isfinite(profiled[n])]
    limits.update(detection_limits(finite, [profiled[n] for n in finite], k, n_obs, config.bic_margin))
    return EffectScore(
        colour_factor=colour, delta_bic_hac=float(-2.0 * dll / colour + k * np.log(n_obs)),
        effect=name, delta_ll=float(dll), delta_bic=float(dbic),
        # an effect without unknowns is not nested in the model it replaces: no likelihood-ratio test, the BIC compares
        p_value=float(stats.chi2.sf(max(2 * dll, 0.0), k)) if k else float("nan"),
        at_bound=at_bounds(name, values, {n: float(model.scale[i]) for n, i in zip(mine, idx)}), n_params=k, params=values,
        params_se={n: float(e) for n, e in se.items()}, detection_limit=limits, gap_after=float(gap_after),
        shrink_fraction=float(shrink), velocity_error_m_s=velocity_error(model, fit), success=fit.success,
        status=fit.status, iterations=fit.iterations, round=round_,
        heldout_z=heldout_improvement_z(model, cv, ref_model, ref_cv, noise))


def ping_evidence(model, cv, ref_model, ref_cv, noise) -> dict:
    """The held-out evidence on ping-scale blocks (``cv``, ``ref_cv``: the two models' held-out
    residuals there), for :attr:`EffectScore.ping`."""
    before, after = heldout_gap(ref_model, ref_cv, noise)[0], heldout_gap(model, cv, noise)[0]
    return {"gap_before": float(before), "gap_after": float(after), "shrink_fraction": float(_shrink(before, after)),
            "heldout_z": float(heldout_improvement_z(model, cv, ref_model, ref_cv, noise))}


def _held_out(config: DiagnosisConfig, shrink: float, before: float, after: float, z: float) -> bool:
    """Out-of-sample evidence on a random-walk base: a share of a gap there is, or a paired
    improvement that is also a practical one."""
    return bool((shrink >= config.min_shrink_walk and before > config.min_gap)
                or (z > config.heldout_z_walk and before - after >= config.min_gain_walk))


def _in_sample(s: EffectScore, config: DiagnosisConfig) -> bool:
    """The in-sample half of significance: the (coloured) BIC better by the margin, no unknown at a bound."""
    return bool(not s.at_bound and s.delta_bic_hac < -config.bic_margin)


def needs_ping_evidence(s: EffectScore, ref_gap: float, config: DiagnosisConfig) -> bool:
    """Whether the ping-scale blocks can still decide (random-walk base): the in-sample test passes
    and the long blocks show nothing; otherwise they are not computed."""
    return _in_sample(s, config) and not _held_out(config, s.shrink_fraction, ref_gap, s.gap_after, s.heldout_z)


def at_bounds(effect: str, values: dict, scales: dict | None = None) -> list:
    """The effect's unknowns (full names) whose estimate sits on a bound of the effect's range: the
    data pushed them there, so their value and its standard error say nothing. "On" as the fit
    holds an unknown by its bound (:meth:`GapModel.solve`'s ``free``): within ``BOUND_TOL`` of the range, or
    of the unknown's scale (``scales``, full name -> scale) where that is larger; an interior-point
    solver stops a hair inside a bound it presses on."""
    ranges = {q.name: (q.lower, q.upper) for q in get_effect(effect).parameters}
    out = []
    for name, v in values.items():
        lo, hi = ranges.get(name.rsplit(".", 1)[-1], (-np.inf, np.inf))
        width = hi - lo if np.isfinite(hi - lo) else max(1.0, abs(v))
        tol = BOUND_TOL * max(width, (scales or {}).get(name, 0.0))
        if min(abs(v - lo), abs(v - hi)) <= tol:
            out.append(name)
    return out


def significant(s: EffectScore, ref_gap: float, config: DiagnosisConfig, walk: bool) -> bool:
    """Whether an effect is significant against the current model (held-out gap ``ref_gap``): its
    BIC better by the margin (the coloured one on a random-walk base), and out of sample a share of
    the held-out gap removed, on a random-walk base alternatively a paired held-out improvement.
    On a random walk the held-out evidence may come from the long blocks or the ping-scale ones
    (``s.ping``). Never with an unknown stopped at a bound of the effect's plausible range (``at_bound``): the
    data want it beyond anything the effect can be, so it stands in for something else (a 5.7-deg
    beam-angle error fitting a bed's slant ranges on a real transect without GNSS)."""
    if not _in_sample(s, config):
        return False
    if walk:
        at_ping = bool(s.ping) and _held_out(config, s.ping["shrink_fraction"], s.ping["gap_before"],
                                             s.ping["gap_after"], s.ping["heldout_z"])
        return _held_out(config, s.shrink_fraction, ref_gap, s.gap_after, s.heldout_z) or at_ping
    return bool(s.shrink_fraction >= config.min_shrink and ref_gap > config.min_gap)


SHRINK_TIE = 0.01  # held-out shrinks this close predict alike: the BIC decides between them


def preference(scores: list, gain, bic_margin: float) -> list:
    """The scores in order of preference: the significant ones first, the one that predicts the
    held-out data best (largest shrink) ahead, since two effects the BIC both accepts are told apart
    by what they predict, not by in-sample fit under residuals whose colour is only estimated;
    an effect that contains a significant other as a special case (``Effect.nests``) goes behind
    it unless its extra unknowns are significant themselves (BIC better than the other's by
    ``bic_margin``). Shrinks within ``SHRINK_TIE`` of the largest are a tie, which the better BIC
    breaks (the same prediction, fewer or better-spent unknowns). The rest follow by BIC gain."""
    significant = sorted((s for s in scores if s.significant), key=lambda s: -s.shrink_fraction)
    if significant:
        tied = [s for s in significant if s.shrink_fraction >= significant[0].shrink_fraction - SHRINK_TIE]
        best = min(tied, key=gain)
        significant.remove(best)
        significant.insert(0, best)
    for big in list(significant):
        for name in get_effect(big.effect).nests:
            small = next((s for s in significant if s.effect == name), None)
            if small is not None and gain(big) - gain(small) > -bic_margin:
                i, j = significant.index(big), significant.index(small)
                if j > i:
                    significant.insert(i, significant.pop(j))
    return significant + sorted((s for s in scores if not s.significant), key=gain)


def confounding(model: GapModel, fit: Fit, effect_names: list, against: list, threshold: float) -> tuple[list, float]:
    """Unknowns in ``against`` that share more than ``threshold`` of the effect parameters' variance."""
    idx_e = [model.names.index(n) for n in effect_names]
    idx_b = [model.names.index(n) for n in against if n in model.names]
    free = fit.free if fit.free is not None else np.ones(len(model.names), dtype=bool)
    idx_e = [i for i in idx_e if free[i]]
    idx_b = [i for i in idx_b if free[i]]
    if not idx_e or not idx_b:
        return [], 0.0
    C = covariance(fit, model, idx_e + idx_b)
    ne = len(idx_e)
    Cb = C[ne:, ne:]
    worst, names = 0.0, []
    for i in range(ne):
        if C[i, i] <= 0:
            continue
        c = C[i, ne:]
        share = float(c @ np.linalg.pinv(Cb) @ c / C[i, i])
        if share > worst:
            worst = share
            F = np.abs(c) / np.sqrt(np.maximum(np.diag(Cb) * C[i, i], 1e-300))
            names = [model.names[idx_b[j]] for j in np.argsort(F)[::-1] if F[j] > 0.3][:3]
    return (names if worst > threshold else []), worst
