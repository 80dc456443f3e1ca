"""Sim-to-real gap diagnosis of one run or of several runs of one boat: where the base model
misses, which catalog effects explain it, and how far the held-out gap shrinks.

The orchestrator (:func:`diagnose`), blind to the runs' truth:

1. Base fit and noise levels (:mod:`.base`): the calibration's measurement model with its platform
   quantities pinned, or what the runs determine; noise levels independent where the data allow,
   otherwise the lowest residual level any fitted model of the first round reached.
2. Forward selection: every applicable catalog effect is refitted on top of the current model
   (warm start; delays and velocity scales settled by :mod:`.profiles`), scored against it and the
   most preferred significant one joins the model (:mod:`.selection`); the next round tries the
   rest. ``given`` effects (a file's own) are fitted first and stay in every model.
3. Confounding: an effect whose parameters share most of their variance with a base unknown (or
   with an effect already chosen) cannot be told from it in these data: the report says which
   and why (:mod:`.statement`) instead of claiming it.
4. The gap (:mod:`.heldout`): excess chi-square per sample of residuals predicted on held-out time
   blocks, in units of the noise levels, before and after the chosen effects; with several runs
   also with whole runs held out; where it lies per channel (:mod:`.where`).
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ...cases.case import Case, check_distinct_names
from ...models.effects import effect_of
from ...models.motion import AttitudeParams, evaluate_attitude
from ..calibration.record import CalibrationRecord
from . import where as where_mod
from .base import (applicable, effect_terms, fit_base, group_sigma, noise_from_data, pinned_effect_parameters,
                   variance_components, velocity_error)
from .config import DiagnosisConfig, holding
from .covariance import coloured_covariance
from .heldout import cv_residuals, heldout_gap
from ..measurement_model import PRIOR_GROUPS
from .model import Fit, GapModel, residual_peaks
from .profiles import REFERENCE_DELAY, delay_profile, fixed_points, marginal_profile
from .selection import (EffectScore, confounding, needs_ping_evidence, ping_evidence, preference, score_effect,
                        significant)
from .statement import base_flow, calibration_base_note, compass_or_bed, confounding_reason, not_the_base, reading_of

MIN_PINGS = 10  # fewer leave the held-out blocks and the periodograms nothing to work on
PLATFORM = ("installation_", "heading_misalignment", "compass_deviation_", "P_")
VELOCITY_SCALES = ("sound_speed_error.relative_error", "beam_angle_error.error_rad")  # unknowns scaling the beams' velocities
ALTERNATIVE_SHARE = 0.8  # a significant effect removing this share of the chosen one's shrink is named beside it


@dataclass
class DiagnosisResult:
    """What :func:`diagnose` found. ``verdict`` is an effect name, several joined by ``+``
    (forward selection), or ``none``."""

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
    selected: list = field(default_factory=list)
    given: dict = field(default_factory=dict)  # the given effects' unknowns: {name: {"value", "se"}}
    given_covariance: dict = field(default_factory=dict)  # {"names": [...], "matrix": [[...]]} of the given unknowns
    confounded: list = field(default_factory=list)
    alternatives: list = field(default_factory=list)  # per chosen effect: the others of its round nearly as good
    look_alike: list = field(default_factory=list)  # a compass error chosen on one run while a bed is significant too, or vice versa
    runs: list = field(default_factory=list)
    run_holdout: dict = field(default_factory=dict)
    fits: dict = field(default_factory=dict, repr=False)  # name -> (GapModel, Fit), for figures
    cv_residuals: dict = field(default_factory=dict, repr=False)
    noise_levels: dict = field(default_factory=dict, repr=False)  # noise keyed by (run, group), as the models use it

    def to_dict(self) -> dict:
        d = {k: v for k, v in dataclasses.asdict(self).items() if k not in ("fits", "cv_residuals", "noise_levels")}
        d["ranking"] = [r if isinstance(r, dict) else r.to_dict() for r in self.ranking]
        return d


def _key_name(model: GapModel, key) -> str:
    return key[1] if model.n_runs == 1 else f"{model.base.runs[key[0]].case.name}/{key[1]}"


def diagnose(cases, config: DiagnosisConfig = DiagnosisConfig(), calibration: CalibrationRecord | None = None,
             progress=None) -> DiagnosisResult:
    """Diagnose the gap between the base model and one case (or several runs of one boat), blind
    to its truth; with a calibration (the typed record), its platform quantities are pinned."""
    cases = [cases] if isinstance(cases, Case) else list(cases)
    check_distinct_names(cases)
    for case in cases:
        if case.pings.n < MIN_PINGS:
            raise ValueError(f"{case.name}: /pings/time_s: expected at least {MIN_PINGS} pings for the gap diagnosis "
                             f"(residuals held out in time blocks), got {case.pings.n}")
        ypr = case.attitude.ypr()
        if ypr.shape[0] < 3 or np.all(np.nan_to_num(np.ptp(ypr, axis=0)) == 0):
            raise ValueError(f"{case.name}: /attitude: heading, pitch and roll never change (no attitude recorded?); "
                             "the gap diagnosis needs a measured attitude")
    base, base_model, base_fit, sigma_fit = fit_base(cases, config, calibration)
    own = calibration_own_effects(calibration, cases, config, base)
    if own:  # what these runs showed when calibrated: held there, the question is what changed since
        config = holding(config, own)
    peaks = residual_peaks(base_model, base_fit)
    flow = base_flow(cases, base_model, base_fit)  # what a named bed's direction is read against
    fits = {"base": (base_model, base_fit)}
    # the given effects held at the runs' own values, each also a candidate: that it moved from there
    own_values = {n: (float(v), np.nan if se is None else float(se)) for n, v, se in config.given_values}
    base.held = {n: v for n, (v, _) in own_values.items()}
    skipped, candidates = {}, [n for n in config.given if own_values]
    for name in config.effects:
        if name in config.given:
            continue
        ok, why = applicable(base, name)
        if ok:
            candidates.append(name)
        else:
            skipped[name] = why
    for name in config.given:
        ok, why = applicable(base, name)
        if not ok:
            raise ValueError(f"given: {name} cannot be fitted on this base ({why})")
    against = [n for n in base_model.names if n.startswith(PLATFORM)]

    profile_hints = {}  # a velocity scale's maximum and SE from its last profile

    def refit(selected_terms, name, start_fit, moved=False):
        """``name`` refitted on top of ``selected_terms``; ``moved``: a held given effect freed from its values
        (its terms already among them), started also from its fresh start."""
        terms = list(selected_terms) if moved else selected_terms + effect_terms(base, name)
        at = released(base, name) if moved else base  # the base this refit's models are built on
        values = start_fit.values
        held_delay = any(n.endswith(REFERENCE_DELAY) for n in at.held)  # the runs' own, where it is held
        if base_model.random_walk and any(t.effect.name == "reference_latency" for t in terms) and not held_delay:
            return delay_profile(at, terms, peaks, config, values, start_fit.sigma, profile=name == "reference_latency")
        model = GapModel(at, terms, peaks, solver=config.solver)
        pinned = pinned_effect_parameters(model, at)
        if base_model.random_walk:  # unknowns that scale the velocities: by the marginal likelihood, held where it put them
            scaled = [n for n in model.names if n.endswith(VELOCITY_SCALES)]
            mine = [n for n in scaled if effect_of(n) == name]
            pinned.update({n: float(values[n]) for n in scaled if n not in mine and n in values})
            if len(mine) == 1 and mine[0] not in at.held:  # started about an earlier round's maximum, where there is one
                model, fit = marginal_profile(model, mine[0], values, start_fit.sigma, pinned, config, terms, peaks,
                                               profile_hints.get(mine[0]))
                if np.isfinite(fit.profile_se[mine[0]]):
                    profile_hints[mine[0]] = (float(fit.x[model.names.index(mine[0])]), fit.profile_se[mine[0]])
                return model, fit
        extra = [o for t in effect_terms(at, name) for o in t.effect.extra_starts()]
        starts = [model.start(values)] + [model.start(values, _renamed(model, o)) for o in extra]
        if moved:
            starts.append(model.start({k: v for k, v in values.items() if not (k in model.effect_names and effect_of(k) == name)}))
        best = None
        for x0 in starts:
            f = model.solve(x0, start_fit.sigma, fixed=pinned)
            if best is None or f.objective < best.objective:
                best = f
        return fixed_points(at, terms, peaks, config, model, best, pinned)

    # round 1: every candidate against the base (the ranking); later rounds: on top of the chosen ones
    noise = dict(sigma_fit)
    n_obs = int((base_model.mask > 0).sum())
    selected_terms, selected, confounded, ranking, alternatives, look_alike = [], [], [], [], [], []
    chosen = []  # the score of each selected effect in the round that chose it
    current_name, current = "base", (base_model, base_fit)
    walk = base_model.random_walk  # a velocity per ping: long held-out blocks, a smaller shrink share or a paired gain
    block_s = config.block_s(walk)
    cv_ping = {}  # on a random walk, the ping-scale blocks' held-out residuals, where an effect needs them

    def held_out(model, f) -> np.ndarray:
        return cv_residuals(model, f, config.cv_folds, block_s)

    def at_ping_scale(label) -> np.ndarray:
        if label not in cv_ping:
            cv_ping[label] = cv_residuals(*fits[label], config.cv_folds, config.cv_block_s)
        return cv_ping[label]

    cv = {"base": held_out(base_model, base_fit)}
    given, given_covariance = {}, {}
    if config.given:  # the run's own effects first: every candidate is then judged on top of them
        for name in config.given:
            current = refit(selected_terms, name, current[1])
            selected_terms += effect_terms(base, name)
        if current[0].random_walk:  # the noise levels of the model the candidates are judged against: its own
            gm, gf = current
            # a reference delay and the velocity scales where their marginal profiles put them: the joint refit would
            # pull them back (winriver01's own sound speed 0.0223 refitted, 0.0284 at its marginal maximum)
            at_profile = {n: float(gf.x[gm.names.index(n)]) for n in gm.names if n.endswith((REFERENCE_DELAY, *VELOCITY_SCALES))}
            profile_se = gf.profile_se
            gf, noise, _, _ = noise_from_data(gm, gf, fixed={**pinned_effect_parameters(gm, base), **at_profile})
            gf.profile_se = profile_se
            current = (gm, gf)
        current_name = "given:" + "+".join(config.given)
        fits[current_name] = current
        cv[current_name] = held_out(*current)
        gm, gf = current
        if own_values:  # held where the runs' own values put them: their standard errors are those values'
            given = {n: {"value": v, "se": se} for n, (v, se) in own_values.items()}
        else:
            idx = [gm.names.index(n) for n in gm.effect_names]
            cov = coloured_covariance(gf, gm, idx)
            given = {n: {"value": float(gf.x[i]), "se": float(gf.profile_se.get(n, np.sqrt(cov[j, j])))}
                     for j, (n, i) in enumerate(zip(gm.effect_names, idx))}
            # how the given unknowns co-vary (a compass deviation's A, B, C on one course): what a shift of them is judged by
            given_covariance = {"names": list(gm.effect_names), "matrix": cov.tolist()}
    start_name = current_name  # what the chosen effects are judged against: the base, or the base with the given
    path = []  # the model after each selected effect, in order

    def gain(s: EffectScore) -> float:  # the BIC change that decides: the coloured-residual one
        return s.delta_bic_hac

    first_gain = {}
    for round_ in range(1, config.max_effects + 1):
        tried = {}
        # later rounds retry only the effects that improved on the base alone (a BIC gain in round 1)
        todo = [name for name in candidates if name not in selected and (round_ == 1 or first_gain.get(name, 0.0) < 0)]
        labels = {name: name if round_ == 1 else "+".join(selected + [name]) for name in todo}

        def one(name, terms=tuple(selected_terms), start=current[1]):
            model, f = refit(list(terms), name, start, moved=name in config.given)
            residuals = held_out(model, f)
            if progress:
                progress(labels[name])
            return model, f, residuals

        # the candidates' refits are independent: threads (CasADi computes without the GIL); the reference delay's
        # profile (a dozen refits) first, so the pool packs the single refits around it instead of after it
        with ThreadPoolExecutor(max_workers=max(1, min(config.workers, len(todo)))) as pool:
            futures = {name: pool.submit(one, name) for name in sorted(todo, key=lambda n: n != "reference_latency")}
            done = [futures[name].result() for name in todo]
        for name, (model, f, residuals) in zip(todo, done):
            tried[name] = (labels[name], model, f)
            fits[labels[name]] = (model, f)
            cv[labels[name]] = residuals
        if round_ == 1:  # noise levels: independent ones, lowered to the best level any model reached
            for model, f in [v[1:] for v in tried.values()] + [fits[start_name]]:
                levels = variance_components(model, f) if model.random_walk else group_sigma(model, f.raw)
                for key, value in levels.items():
                    if key[1] not in PRIOR_GROUPS:  # the walk's intensity is the base's, not a floor
                        noise[key] = min(noise[key], value) if np.isfinite(value) else noise[key]
            noise = {k: max(v, 1e-9) for k, v in noise.items()}
        ref_gap, _ = heldout_gap(current[0], cv[current_name], noise)
        scores = []
        for name, (label, model, f) in tried.items():
            s = score_effect(name, model, f, current[0], current[1], ref_gap, cv[label], cv[current_name], noise, n_obs,
                             config, round_)
            if walk and needs_ping_evidence(s, ref_gap, config):  # a latency or heave may show at the ping scale only
                s.ping = ping_evidence(model, at_ping_scale(label), current[0], at_ping_scale(current_name), noise)
            mine = [n for n in model.effect_names if effect_of(n) == name]
            others = against + [n for n in model.effect_names if n not in mine]
            s.confounded_with, s.confounded_share = confounding(model, f, mine, others, config.confounded_share)
            s.significant = significant(s, ref_gap, config, walk)
            scores.append(s)
        scores = preference(scores, gain, config.bic_margin)
        ranking += scores
        if round_ == 1:
            first_gain = {sc.effect: gain(sc) for sc in scores}
        # an effect the base's unknowns (or a chosen effect) largely stand in for: said in words, whether or not
        # the rest of its signature still carries it
        for sc in scores:
            if sc.confounded_with and gain(sc) < -config.bic_margin and sc.effect not in [c["effect"] for c in confounded]:
                confounded.append({"effect": sc.effect, "with": sc.confounded_with, "shared_variance": sc.confounded_share,
                                   "chosen": sc.significant,
                                   "statement": confounding_reason(sc.effect, sc.confounded_with, base)})
        best = next((s for s in scores if s.significant), None)
        if best is None:
            break
        close = [s for s in scores if s is not best and s.significant
                 and s.shrink_fraction >= ALTERNATIVE_SHARE * best.shrink_fraction]
        if close:
            alternatives.append({"chosen": best.effect, "round": round_, "shrink": best.shrink_fraction,
                                 "delta_bic": best.delta_bic, "gap_after": best.gap_after,
                                 "alternatives": [{"effect": s.effect, "shrink": s.shrink_fraction, "delta_bic": s.delta_bic,
                                                   "gap_after": s.gap_after, **reading_of(s, cases, flow)} for s in close]})
        one_course = compass_or_bed(best.effect, [s.effect for s in scores if s.significant], base)
        if one_course and not look_alike:  # said once: a later round's pair is the same question
            look_alike.append(one_course)
        selected.append(best.effect)
        chosen.append(best)
        if best.effect in config.given:  # moved from the runs' own values: free from here on
            base = released(base, best.effect)
        else:
            selected_terms += effect_terms(base, best.effect)
        current_name = tried[best.effect][0]
        current = fits[current_name]
        path.append(current_name)

    start_model, start_fit = fits[start_name]
    gap_before, z_before = heldout_gap(start_model, cv[start_name], noise)
    where = _where(start_model, start_fit, cv[start_name], noise)
    v_before = velocity_error(start_model, start_fit)
    if selected:
        gap_after, z_after = heldout_gap(current[0], cv[current_name], noise)
        remaining = z_after > config.gap_z and gap_after > config.min_gap
        verdict = "+".join(selected)
        # each step's held-out gap from the model after it, as the gap before and after are measured
        steps = [gap_before] + [heldout_gap(fits[name][0], cv[name], noise)[0] for name in path]
        statement = (f"{' then '.join(selected)} explain{'s' if len(selected) == 1 else ''} the gap: held-out excess chi2 "
                     f"{gap_before:.3f} -> {gap_after:.3f} ("
                     + "; ".join(f"{s.effect}: {a:.3f} -> {b:.3f}, delta BIC {s.delta_bic:.1f}"
                                 for s, a, b in zip(chosen, steps, steps[1:])) + ")")
        if remaining:
            after = _where(*current, cv[current_name], noise)  # where what is left lies, not where the base's gap did
            statement += (f"; a significant gap remains after {'it' if len(selected) == 1 else 'them'} (excess chi2 "
                          f"{gap_after:.3f}, z = {z_after:.1f}), worst in {after[0]['channel']} ({after[0]['detail']}): "
                          "an effect outside the catalog, or more than the catalog's"
                          + not_the_base(current[0]))
        v_after = velocity_error(*current)
    else:
        gap_after, z_after, verdict = gap_before, z_before, "none"
        remaining = z_before > config.gap_z and gap_before > config.min_gap
        if remaining:
            statement = (f"no catalog effect is significant, but a significant gap remains (held-out excess chi2 "
                         f"{gap_before:.3f}, z = {z_before:.1f}), worst in {where[0]['channel']} "
                         f"({where[0]['detail']}): an effect outside the catalog"
                         + not_the_base(start_model))
        else:
            statement = f"no significant gap: the base model fits to the noise (held-out excess chi2 {gap_before:.3f})"
        v_after = v_before
    for c in confounded:
        if c["effect"] in selected:
            statement += (f"; {c['effect']} shares {100 * c['shared_variance']:.0f}% of its variance with "
                          f"{', '.join(c['with'])}: its value carries that ({c['statement']})")
        else:
            statement += f"; {c['effect']} improves the fit but cannot be separated here: {c['statement']}"
    for a in alternatives:
        statement += (f"; {' and '.join(x['effect'] for x in a['alternatives'])} explain"
                      f"{'s' if len(a['alternatives']) == 1 else ''} nearly as much as {a['chosen']} ("
                      + "held-out gap after " + ", ".join(f"{x['gap_after']:.3f}" for x in a["alternatives"])
                      + f" vs {a['gap_after']:.3f}): these data hardly tell them apart, so read "
                      f"{a['chosen']} as the likeliest of them, not as proven"
                      + "".join(f" ({x['effect']}: {x['reading']['text']})" for x in a["alternatives"] if "reading" in x))
    statement += "".join("; " + a["statement"] for a in look_alike)
    for sc in chosen:
        statement += "".join(f"; {sc.effect}: {r['text']}" for r in reading_of(sc, cases, flow).values())
    if given:
        whose = "what these runs showed when calibrated (held there), " if own else "the run's own "
        statement = ("on top of " + whose + ", ".join(f"{n} = {v['value']:.4g} +- {v['se']:.2g}" for n, v in given.items())
                     + ": " + statement)
    if base.sampled:
        reasons = "; ".join(dict.fromkeys(f"{r.attitude_reason}; {r.samples.reason}" for r in base.runs
                                          if r.attitude_source == "samples"))
        statement = ("beams' attitude from the sensor's samples (" + reasons + "): effects on the sensor are undone on "
                     "the samples; " + statement)
    other_base = calibration_base_note(calibration, base, chosen)
    if other_base:
        statement += "; " + other_base
    if base.notes:
        statement += " [base: " + "; ".join(base.notes) + "]"
    run_holdout = {}
    if len(cases) > 1 and selected:
        runs_fold = base_model.row_run.copy()
        for label, (m, f) in (("base", (base_model, base_fit)), (current_name, current)):
            rv = cv_residuals(m, f, config.cv_folds, block_s, fold_of=runs_fold)
            run_holdout[label] = heldout_gap(m, rv, noise)[0]
    base_info = {"success": base_fit.success, "status": base_fit.status, "iterations": base_fit.iterations,
                 "attitude_source": ", ".join(dict.fromkeys("samples" if r.attitude_source == "samples" else "model"
                                                            for r in base.runs)),
                 "attitude_source_reason": "; ".join(dict.fromkeys(r.attitude_reason for r in base.runs)),
                 "calibration": base.pins.source or None, "pinned": base.pins.values, "notes": base.notes,
                 "noise_levels_moved": base.noise_moved,
                 "navigation": ", ".join(dict.fromkeys(r.navigation for r in base.runs)),
                 "calibration_on_another_base": other_base or None,
                 "log_likelihood": float(base_fit.log_likelihood(base_model)), "n_observations": n_obs,
                 "skipped_effects": skipped,
                 "unknowns": {n: float(base_fit.x[i]) for i, n in enumerate(base_model.names)
                              if not n.split("/")[-1].startswith(("V", "mode", "roll_", "pitch_", "yaw_"))}}
    return DiagnosisResult(
        case=", ".join(c.name for c in cases), verdict=verdict, statement=statement, gap_before=float(gap_before),
        gap_after=float(gap_after), gap_z_before=float(z_before), gap_z_after=float(z_after),
        remaining_gap_significant=bool(remaining), where=where,
        ranking=[{**r.to_dict(), **reading_of(r, cases, flow)} for r in ranking],
        noise={_key_name(base_model, k): v for k, v in noise.items()}, base=base_info,
        velocity_error_before_m_s=v_before, velocity_error_after_m_s=v_after, selected=selected, given=given,
        given_covariance=given_covariance,
        confounded=confounded,
        alternatives=alternatives, look_alike=look_alike,
        runs=[c.name for c in cases], run_holdout=run_holdout, fits=fits, cv_residuals=cv, noise_levels=noise)


def calibration_own_effects(calibration, cases, config: DiagnosisConfig, base) -> dict | None:
    """The calibration's own effects (CALIB.json ``own_effects``) where they apply: these runs are its
    own, none are given, ``config.hold_own_effects``, and this base's navigation is the one they were
    found on. None otherwise."""
    own = getattr(calibration, "own_effects", None)
    if not own or not own["effects"] or config.given or not config.hold_own_effects:
        return None
    navigation = ", ".join(dict.fromkeys(r.navigation for r in base.runs))
    if navigation != own["navigation"] or not all(calibration.holds(c) for c in cases):
        return None
    return own


def released(base, name: str):
    """``base`` with the held unknowns of effect ``name`` freed (the effect moved from the runs' own values)."""
    return dataclasses.replace(base, held={k: v for k, v in base.held.items() if effect_of(k) != name})


def _renamed(model: GapModel, overrides: dict) -> dict:
    """An effect's extra start ({"effect.param": v}) on this model's names (per-run ones prefixed)."""
    out = {}
    for key, value in overrides.items():
        for n in model.names:
            if n == key or n.endswith("/" + key):
                out[n] = value
    return out


def _where(model: GapModel, fit: Fit, cv_raw: np.ndarray, noise: dict) -> list:
    """Ranked channel reports of the base model's held-out residuals."""
    reports = []
    sl = model.channel_slices()
    for (name, _), key_index in zip(model.channels, _channel_keys(model)):
        s = sl[name]
        m = model.mask[s] > 0
        if m.sum() < 3:
            continue
        k = model.sigma_keys[key_index][0]
        run = model.base.runs[k]
        t = model.times[s][m]
        if run.attitude_source == "samples":  # the samples' interpolation and segment slopes (no accelerations)
            local = run.samples.params_at(t)
            now, rate, accel = local[1:4].T, local[4:7].T, None
            modes = [float(w) for w, _ in run.fit.params.modes]
        else:
            idx = model.model.unknowns.index(f"attitude{k}")
            p = AttitudeParams.unpack(fit.x[idx], run.fit.params.layout)
            modes = [float(w) for w, _ in p.modes]
            dt = 0.05
            ypr = [evaluate_attitude(p, t + j * dt)["ypr"] for j in (-1, 0, 1)]
            now, rate, accel = ypr[1], (ypr[2] - ypr[0]) / (2 * dt), (ypr[2] - 2 * ypr[1] + ypr[0]) / dt**2
        reg = {"roll rate": rate[:, 2], "pitch rate": rate[:, 1], "yaw rate": rate[:, 0],
               "sin heading": np.sin(now[:, 0]), "cos heading": np.cos(now[:, 0]),
               "roll": now[:, 2], "pitch": now[:, 1], "time": t}
        if accel is not None:
            reg.update({"roll acceleration": accel[:, 2], "pitch acceleration": accel[:, 1]})
        v = model.nav_at(fit.x, t, k)
        reg["speed"] = np.hypot(v[:, 0], v[:, 1])
        reg["depth"] = np.interp(t, run.case.pings.time_s, run.case.environment.depth_at_pings(run.case.pings.n))
        reports.append(where_mod.channel_report(name, t, cv_raw[s][m], noise[model.sigma_keys[key_index]], reg, modes))
    return where_mod.rank(reports)


def _channel_keys(model: GapModel) -> list:
    """Index of each channel's (run, group) noise key."""
    sl = model.channel_slices()
    return [int(model.row_sigma[sl[name].start]) for name, _ in model.channels]
