"""Sim-to-real gap diagnosis of one case: where the base model misses, which catalog
effect explains it, and how far the held-out gap shrinks once that effect is added.

1. Base fit (:class:`.model.GapModel` without effects), warm-started from the attitude
   pre-fit (or a calibration).
2. Noise levels per channel group: independent where the data allow (attitude from the
   flexible pre-fit, bottom track from the four-beam error velocity), otherwise the
   lowest residual level any fitted model reached.
3. Each catalog effect refitted with the base fit as warm start; scored by the
   likelihood ratio (profiled per-group noise), BIC and the chi-square p-value.
4. The gap: excess chi-square per sample of residuals predicted on held-out time
   blocks (one Gauss-Newton step from the full fit with the block left out), in units of
   the noise levels: 0 when the model is as good as the noise.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from ...cases.case import Case
from ...models.effects import CATALOG, get_effect
from ...models.motion import AttitudeParams, SampledAttitude, evaluate_attitude
from ...solvers.multistart import SolverOptions
from ..attitude_fit import fit_attitude
from ..calibration import ATTITUDES, choose_attitude
from . import where as where_mod
from .model import GROUPS, Fit, GapModel, base_attitude, group_of, initial_noise, residual_peaks

INDEPENDENT_NOISE = ("heading", "pitch", "roll", "bt")
MIN_PINGS = 10  # fewer leave the held-out blocks and the periodograms nothing to work on


@dataclass(frozen=True)
class DiagnosisConfig:
    """Which effects to try and when a difference counts.

    An effect is significant when its BIC improves on the base model's by more than
    ``bic_margin`` AND it removes at least ``min_shrink`` of the held-out gap. A gap is
    significant when its z-score (excess chi-square over its null standard deviation)
    exceeds ``gap_z`` and it exceeds ``min_gap`` (a practical floor: noise levels are
    estimated, so a few percent of excess is not evidence).
    """

    effects: tuple = tuple(CATALOG)
    cv_folds: int = 5
    cv_block_s: float = 2.0
    bic_margin: float = 10.0
    min_shrink: float = 0.25
    gap_z: float = 6.0
    min_gap: float = 0.1
    max_modes: int = 3
    attitude: str = "auto"  # beams' attitude: model | samples | auto (as the calibration chooses)
    solver: SolverOptions = SolverOptions(tol=1e-6, max_iter=200, hessian="gauss-newton", expand=False, mu_init=1e-5)

    def __post_init__(self):
        for name in self.effects:
            get_effect(name)
        if self.attitude not in ATTITUDES:
            raise ValueError(f"attitude: expected one of {list(ATTITUDES)}, got {self.attitude!r}")
        if self.cv_folds < 2:
            raise ValueError(f"cv_folds: expected an integer >= 2, got {self.cv_folds}")
        if not self.cv_block_s > 0:
            raise ValueError(f"cv_block_s: expected a positive duration in s, got {self.cv_block_s}")


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
    significant: bool = False

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclass
class DiagnosisResult:
    """What :func:`diagnose` found. ``verdict`` is an effect name or ``none``."""

    case: str
    verdict: str
    statement: str
    gap_before: float
    gap_after: float
    gap_z_before: float
    gap_z_after: float
    remaining_gap_significant: bool
    where: list
    ranking: list
    noise: dict
    base: dict
    velocity_error_before_m_s: float | None
    velocity_error_after_m_s: float | None
    fits: dict = field(default_factory=dict, repr=False)  # name -> (GapModel, Fit), for figures
    cv_residuals: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        d = {k: v for k, v in dataclasses.asdict(self).items() if k not in ("fits", "cv_residuals")}
        d["ranking"] = [r if isinstance(r, dict) else r.to_dict() for r in self.ranking]
        return d


# ---------------------------------------------------------------------------- numbers
def _group_sigma(model: GapModel, raw: np.ndarray) -> dict:
    out = {}
    for g in model.groups_present:
        m = (model.group_index == GROUPS.index(g)) & (model.mask > 0)
        out[g] = float(np.sqrt(np.mean(raw[m] ** 2))) if m.any() else np.nan
    return out


def _cv_residuals(model: GapModel, fit: Fit, folds: int, block_s: float) -> np.ndarray:
    """Raw residuals of each held-out fold predicted by the fit with that fold left out.

    The run is cut into contiguous time blocks of about ``block_s`` dealt to the folds in
    turn (so a fold is spread over the run and slowly varying unknowns stay
    determined). The leave-fold-out estimate is one Gauss-Newton step from the full fit,
    damped by a millionth of the full-data information so a direction only the fold
    determines stays put. Unknowns pinned or held at a bound are not re-estimated (the
    step would otherwise follow the bound's pull and fit the held-out data).
    """
    J = fit.jacobian
    if getattr(fit, "free", None) is not None:  # a pinned unknown or one at its bound stays put
        J = J[:, fit.free]
    w = model.weights(fit.sigma)
    e = w * fit.raw
    t = model.times
    n_blocks = max(folds, int(round((t.max() - t.min()) / block_s)))
    edges = np.linspace(t.min(), t.max() + 1e-9, n_blocks + 1)
    fold_of = (np.searchsorted(edges, t, side="right") - 1) % folds
    damping = 1e-6 * np.maximum(np.sum(J**2, axis=0), 1e-12)
    pred = np.zeros_like(e)
    for k in range(folds):
        out = fold_of == k
        tr = ~out & (model.mask > 0)
        Jt = J[tr]
        step = -np.linalg.solve(Jt.T @ Jt + np.diag(damping), Jt.T @ e[tr])
        pred[out] = e[out] + J[out] @ step
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(w != 0, pred / np.where(w != 0, w, 1.0), 0.0)


def _gap(model: GapModel, raw: np.ndarray, sigma: dict) -> tuple[float, float]:
    """Excess chi-square per sample and its z-score against the noise levels."""
    m = model.mask > 0
    s = np.array([sigma[GROUPS[g]] for g in model.group_index])
    chi2 = float(np.mean((raw[m] / s[m]) ** 2))
    n = int(m.sum())
    return chi2 - 1.0, (chi2 - 1.0) * np.sqrt(n / 2.0)


def _covariance_se(fit: Fit, model: GapModel) -> np.ndarray:
    """Standard errors of the unknowns from the weighted Jacobian, scaled by the fit."""
    J = fit.jacobian
    m = int((model.mask > 0).sum())
    dof = max(m - J.shape[1], 1)
    s2 = 2.0 * fit.objective / dof
    cov = np.linalg.pinv(J.T @ J, rcond=1e-12) * s2
    return np.sqrt(np.maximum(np.diag(cov), 0.0)) * fit.scale


def _velocity_error(case: Case, model: GapModel, fit: Fit) -> float | None:
    """RMS horizontal error of the per-ping velocity over ground corrected with the fitted model."""
    if case.truth is None or case.truth.vessel_velocity_m_s is None:
        return None
    v = model.corrected_velocity(fit)
    err = v[:, :2] - case.truth.vessel_velocity_m_s[:, :2]
    ok = np.all(np.isfinite(err), axis=1)
    return float(np.sqrt(np.mean(np.sum(err[ok] ** 2, axis=1)))) if ok.any() else None


def _starting_nav(case: Case, att: AttitudeParams | SampledAttitude) -> np.ndarray:
    ref = case.reference
    if ref is None or ref.time_s is None or ref.velocity_m_s is None:
        return np.zeros(4)
    psi = att.heading_at(ref.time_s) if isinstance(att, SampledAttitude) else evaluate_attitude(att, ref.time_s)["ypr"][:, 0]
    v = np.nan_to_num(ref.velocity_m_s)
    fwd = v[:, 0] * np.cos(psi) + v[:, 1] * np.sin(psi)
    side = -v[:, 0] * np.sin(psi) + v[:, 1] * np.cos(psi)
    return np.array([np.median(fwd), np.median(side), 0.0, 0.0])


def applicable(case: Case, name: str, sampled: bool = False) -> tuple[bool, str]:
    e = get_effect(name)
    if sampled and e.acts_on_attitude_model:
        return False, "acts on the motion model's attitude; the beams use the sensor's samples (no motion model follows them)"
    ref = case.reference
    moving = ref is not None and ref.time_s is not None and ref.velocity_m_s is not None
    if e.needs_reference and not moving:
        return False, "needs a moving reference velocity"
    if name == "moving_bed" and not moving:
        return False, "a moving bed is indistinguishable from vessel motion without a reference"
    return True, ""


# ---------------------------------------------------------------------------- main
def fit_base(case: Case, config: DiagnosisConfig, calibration: dict | None = None):
    af = fit_attitude(case, max_modes=config.max_modes)
    att = base_attitude(af)
    if calibration and calibration.get("attitude_model"):
        att = base_attitude(dataclasses.replace(af, params=AttitudeParams.from_dict(calibration["attitude_model"])))
    sigma0 = initial_noise(case, af)
    source, reason = choose_attitude(case, af, config.attitude)
    model = GapModel(case, att, solver=config.solver, sampled=source == "samples")
    model.attitude_reason = reason
    centre = np.zeros(3)
    if calibration and calibration.get("radius_vectors_m") is not None:
        r = np.array(calibration["radius_vectors_m"], dtype=float)  # null (undetermined) -> nan
        if np.all(np.isfinite(r)):
            centre = np.mean(r, axis=0) - np.mean(case.instrument.transducer_positions(), axis=0)
    x0 = model.start(model.x_base(att, centre, _starting_nav(case, model.samples if model.sampled else att)))
    fit = model.solve(x0, sigma0)
    # second pass with the groups' noise levels re-estimated where no independent one exists
    sigma = dict(sigma0)
    rms = _group_sigma(model, fit.raw)
    for g in model.groups_present:
        if g not in INDEPENDENT_NOISE:
            sigma[g] = max(rms[g], 1e-6)
    fit = model.solve(fit.x, sigma)
    return af, att, model, fit, sigma


def diagnose(case: Case, config: DiagnosisConfig = DiagnosisConfig(), calibration: dict | None = None,
             progress=None) -> DiagnosisResult:
    """Diagnose the gap between the base model and one case, blind to its truth."""
    if calibration is not None:
        from ..calibration_file import as_calibration

        calibration = as_calibration(calibration)
    if case.pings.n < MIN_PINGS:
        raise ValueError(f"{case.name}: /pings/time_s: expected at least {MIN_PINGS} pings for the gap diagnosis "
                         f"(residuals held out in time blocks), got {case.pings.n}")
    ypr = case.attitude.ypr()
    if ypr.shape[0] < 3 or np.all(np.ptp(ypr, axis=0) == 0):
        raise ValueError(f"{case.name}: /attitude: heading, pitch and roll never change (no attitude recorded?); "
                         "the gap diagnosis needs a measured attitude")
    af, att, base_model, base, sigma_fit = fit_base(case, config, calibration)
    peaks = residual_peaks(case, base.raw, base_model)
    fits = {"base": (base_model, base)}
    skipped = {}
    for name in config.effects:
        ok, why = applicable(case, name, base_model.sampled)
        if not ok:
            skipped[name] = why
            continue
        e = get_effect(name)
        model = GapModel(case, att, [e], peaks, solver=config.solver, sampled=base_model.sampled)
        starts = [model.start(base.x)] + [model.start(base.x, o) for o in e.extra_starts()]
        best = None
        for x0 in starts:
            f = model.solve(x0, base.sigma)
            if best is None or f.objective < best.objective:
                best = f
        fits[name] = (model, best)
        if progress:
            progress(name)

    # noise levels: independent ones, lowered to the best level any model reached
    noise = dict(sigma_fit)
    for name, (model, f) in fits.items():
        for g, v in _group_sigma(model, f.raw).items():
            noise[g] = min(noise[g], v) if np.isfinite(v) else noise[g]
    noise = {g: max(v, 1e-9) for g, v in noise.items()}

    cv = {name: _cv_residuals(m, f, config.cv_folds, config.cv_block_s) for name, (m, f) in fits.items()}
    gap_before, z_before = _gap(base_model, cv["base"], noise)
    ll0 = base.log_likelihood(base_model)
    n_obs = int((base_model.mask > 0).sum())
    v_before = _velocity_error(case, base_model, base)
    ranking = []
    for name, (model, f) in fits.items():
        if name == "base":
            continue
        k = len(model.effect_index)
        dll = f.log_likelihood(model) - ll0
        dbic = -2.0 * dll + k * np.log(n_obs)
        gap_after, _ = _gap(model, cv[name], noise)
        shrink = (gap_before - gap_after) / gap_before if gap_before > 0 else 0.0
        se = _covariance_se(f, model)
        score = EffectScore(
            effect=name, delta_ll=float(dll), delta_bic=float(dbic),
            p_value=float(stats.chi2.sf(max(2 * dll, 0.0), k)) if k else (1.0 if dll <= 0 else 0.0),
            n_params=k, params=f.effect_values(model),
            params_se={n: float(se[i]) for n, i in zip(model.effect_names, model.effect_index)},
            gap_after=float(gap_after), shrink_fraction=float(shrink),
            velocity_error_m_s=_velocity_error(case, model, f),
            success=f.success, status=f.status, iterations=f.iterations)
        score.significant = bool(score.delta_bic < -config.bic_margin and shrink >= config.min_shrink
                                 and gap_before > config.min_gap)
        ranking.append(score)
    ranking.sort(key=lambda s: (not s.significant, s.delta_bic))
    best = ranking[0] if ranking and ranking[0].significant else None

    where = _where(case, base_model, base, cv["base"], noise, att)
    gap_sig_before = z_before > config.gap_z and gap_before > config.min_gap
    if best is not None:
        gap_after, z_after = _gap(fits[best.effect][0], cv[best.effect], noise)
        remaining = z_after > config.gap_z and gap_after > config.min_gap
        verdict = best.effect
        statement = (f"{best.effect} explains the gap: held-out excess chi2 {gap_before:.3f} -> {gap_after:.3f} "
                     f"(shrink {100 * best.shrink_fraction:.0f}%, delta BIC {best.delta_bic:.1f})")
        if remaining:
            statement += (f"; a significant gap remains after it (excess chi2 {gap_after:.3f}, z = {z_after:.1f}), "
                          f"worst in {where[0]['channel']}: an effect outside the catalog, or more than one")
    else:
        gap_after, z_after, remaining, verdict = gap_before, z_before, gap_sig_before, "none"
        if gap_sig_before:
            statement = (f"no catalog effect is significant, but a significant gap remains (held-out excess chi2 "
                         f"{gap_before:.3f}, z = {z_before:.1f}), worst in {where[0]['channel']} "
                         f"({where[0]['detail']}): an effect outside the catalog")
        else:
            statement = f"no significant gap: the base model fits to the noise (held-out excess chi2 {gap_before:.3f})"
    if base_model.sampled:
        statement = ("beams' attitude from the sensor's samples (" + base_model.attitude_reason + "): the motion model "
                     "itself is the first gap; on the rest of the model: " + statement)
    base_info = {"success": base.success, "status": base.status, "iterations": base.iterations,
                 "attitude_source": "samples" if base_model.sampled else "model",
                 "attitude_source_reason": base_model.attitude_reason,
                 "log_likelihood": float(ll0), "n_observations": n_obs, "skipped_effects": skipped,
                 "unknowns": dict(zip(base.names[: base_model.n_base], map(float, base.x[: base_model.n_base])))}
    return DiagnosisResult(
        case=case.name, verdict=verdict, statement=statement, gap_before=float(gap_before), gap_after=float(gap_after),
        gap_z_before=float(z_before), gap_z_after=float(z_after), remaining_gap_significant=bool(remaining),
        where=where, ranking=[r.to_dict() for r in ranking], noise=noise, base=base_info,
        velocity_error_before_m_s=v_before,
        velocity_error_after_m_s=best.velocity_error_m_s if best is not None else v_before,
        fits=fits, cv_residuals=cv)


def _where(case: Case, model: GapModel, fit: Fit, cv_raw: np.ndarray, noise: dict, att: AttitudeParams) -> list:
    """Ranked channel reports of the base model's held-out residuals."""
    p = att if model.sampled else AttitudeParams.unpack(fit.x[:att.layout.size], att.layout)
    modes = [float(w) for w, _ in p.modes]
    reports = []
    for ch, sl in model.channel_slices().items():
        m = model.mask[sl] > 0
        if m.sum() < 3:
            continue
        t = model.times[sl][m]
        if model.sampled:  # the samples' interpolation and segment slopes (no accelerations)
            local = model.samples.params_at(t)
            now, rate, accel = local[1:4].T, local[4:7].T, None
        else:
            dt = 0.05
            ypr = [evaluate_attitude(p, t + k * dt)["ypr"] for k in (-1, 0, 1)]
            now, rate, accel = ypr[1], (ypr[2] - ypr[0]) / (2 * dt), (ypr[2] - 2 * ypr[1] + ypr[0]) / dt**2
        reg = {"roll rate": rate[:, 2], "pitch rate": rate[:, 1], "yaw rate": rate[:, 0],
               "sin heading": np.sin(now[:, 0]), "cos heading": np.cos(now[:, 0]),
               "roll": now[:, 2], "pitch": now[:, 1], "time": t}
        if accel is not None:
            reg.update({"roll acceleration": accel[:, 2], "pitch acceleration": accel[:, 1]})
        v = model.nav_at(fit.x, t)
        reg["speed"] = np.hypot(v[:, 0], v[:, 1])
        reg["depth"] = np.interp(t, case.pings.time_s, case.environment.depth_at_pings(case.pings.n))
        reports.append(where_mod.channel_report(ch, t, cv_raw[sl][m], noise[group_of(ch)], reg, modes))
    return where_mod.rank(reports)
