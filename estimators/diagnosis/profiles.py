"""Fits whose delay or velocity scale is settled outside the NLP's joint minimum.

Delays (attitude latency, tilt low-pass, reference latency) are re-centred and the fit repeated
to a fixed point (:func:`fixed_points`), so no expansion reaches far. On a velocity per ping
(random walk) the joint fit the NLP minimises is biased for unknowns that trade against the
velocities (a reference delay drawn to the pings' knots, a sound speed or beam angle that shrinks
the velocity path): they are read from the likelihood marginal over the velocities instead, by
profiles whose curvature gives their standard errors (:func:`delay_profile`,
:func:`marginal_profile`).
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .base import pinned_effect_parameters
from .config import DiagnosisConfig
from .model import Fit, GapModel

LATENCY_ITERATIONS = 3
SAMPLE_FIXED_POINTS = {"attitude_latency.delay_s": "sample_shift_s", "tilt_lowpass.tau_s": "sample_tilt_lead_s"}
REFERENCE_FIXED_POINTS = {"reference_latency.delay_s": "reference_shift_s"}


def fixed_points(base, terms, peaks, config, model, fit, pinned):
    """Delays re-centred and the fit repeated to a fixed point, so no expansion reaches far.
    On the sensor's samples each row's segment is taken about t + the current attitude latency,
    its tilts low-pass-inverted with the current tau (angle and rate from the spline:
    x = y + tau y', x' = y' + tau y''); the reference rows take the navigation at t - the current
    reference latency. Without such an effect the fit is returned as it is."""
    points = {**(SAMPLE_FIXED_POINTS if base.sampled else {}), **REFERENCE_FIXED_POINTS}
    names = {field: n for key, field in points.items() for n in model.names if n.endswith(key)}
    if all(n in pinned for n in names.values()):  # a delay held (a profile's) is where its model is exact already
        return model, fit
    for _ in range(LATENCY_ITERATIONS if names else 0):
        values = {field: float(fit.x[model.names.index(n)]) for field, n in names.items()}
        if set(values) == {"reference_shift_s"}:  # the reference rows alone move: the rest of the NLP is kept
            model = model.at_reference_shift(values["reference_shift_s"])
        else:
            model = GapModel(base.at_delays(**values), terms, peaks, solver=config.solver)
        new = model.solve(model.start(fit.values), fit.sigma, fixed=pinned)
        moved = max(abs(float(new.x[model.names.index(n)]) - values[field]) for field, n in names.items())
        fit = new
        if moved < 1e-3:
            break
    return model, fit


def held_at_delay(model: GapModel, key: str, d: float) -> dict:
    """The unknowns a model exact at delay ``d`` holds: the unknown ending in ``key`` at ``d``, and the
    effect unknowns the base already carries (:func:`.base.pinned_effect_parameters`)."""
    return {**pinned_effect_parameters(model, model.base), next(n for n in model.names if n.endswith(key)): float(d)}


def fit_at_delay(base, terms, peaks, config, field: str, key: str, d: float, x: dict, sigma: dict):
    """(model, fit) exact at delay ``d``: every run's ``field`` (``reference_shift_s``, ``sample_shift_s``)
    set to it, the unknown ending in ``key`` pinned there, the fit started from ``x``."""
    model = GapModel(base.at_delays(**{field: d}), terms, peaks, solver=config.solver)
    return model, model.solve(model.start(x), sigma, fixed=held_at_delay(model, key, d))


REFERENCE_DELAY_SPAN_S = 3.0  # the reference delays a random-walk base's profile searches, +- (s)
REFERENCE_DELAY = "reference_latency.delay_s"


def delay_profile(base, terms, peaks, config, values: dict, sigma: dict, profile: bool):
    """A reference delay on a velocity per ping, by the likelihood marginal over the velocities: each
    model is exact at its delay (the reference rows taken at t - d, the delay pinned there), since the
    joint fit the NLP minimises prefers the reference samples on the pings' knots (0.38 s on clean
    winriver02, where the marginal is highest at 0). With ``profile``: a grid of one ping interval
    over +- :data:`REFERENCE_DELAY_SPAN_S`, then half and a quarter of one about the best, then the
    vertex of a parabola through the whole-interval points within two intervals of it
    (:func:`envelope_parabola`), whose curvature gives the standard error (``Fit.profile_se``; NaN at
    the span's edge or where the parabola does not curve down). The marginal profile keeps a ripple
    at the ping interval where the reference samples sit on the pings (RiverPro: +-30 in
    log-likelihood; a piecewise-linear path has no bridge variance between its knots): the estimate
    is then drawn to the delays that keep them there. Without
    ``profile``: held where ``values`` (the chosen model's) put it."""

    d0 = next(v for n, v in values.items() if n.endswith(REFERENCE_DELAY)) if not profile else 0.0
    built = GapModel(base.at_delays(reference_shift_s=d0), terms, peaks, solver=config.solver)  # every other delay
    # rebuilds its reference rows only, with its own solver (the profile's two sides solve at once)

    def at(d: float, x: dict):
        model = built if d == d0 else built.at_reference_shift(d)
        return model, model.solve(model.start(x), sigma, fixed=held_at_delay(model, REFERENCE_DELAY, d))

    def settled(model: GapModel, fit: Fit, d: float):  # the attitude's delays, if any, to their fixed point
        return fixed_points(model.base, terms, peaks, config, model, fit, held_at_delay(model, REFERENCE_DELAY, d))

    if not profile:
        return settled(*at(d0, values), d0)
    step = min(float(np.median(np.diff(r.knots))) for r in base.runs if r.knots is not None)
    tried, marginal, kept = {}, {}, {}  # each delay's fit and marginal; the model of the best delay only
    lock = threading.Lock()

    def visit(d: float, x: dict) -> None:
        model, fit = at(d, x)
        with lock:
            tried[d], marginal[d] = fit, fit.log_likelihood(model)
            if not kept or marginal[d] > marginal[next(iter(kept))]:  # one expanded problem held, not one per delay
                kept.clear()
                kept[d] = model

    def side(delays: list) -> None:  # each side warm-started from its neighbour, the first from the given values
        x = values
        for d in delays:
            visit(d, x)
            x = tried[d].values

    ll = marginal.__getitem__
    sides = (np.arange(0.0, REFERENCE_DELAY_SPAN_S + 1e-9, step).tolist(),
             (-np.arange(step, REFERENCE_DELAY_SPAN_S + 1e-9, step)).tolist())
    with ThreadPoolExecutor(max_workers=2) as pool:  # the two sides at once (CasADi lets go of Python's lock)
        list(pool.map(side, sides))
    for h in (step / 2, step / 4):
        best = max(tried, key=ll)
        for d in (best - h, best + h):
            if abs(d) <= REFERENCE_DELAY_SPAN_S + 1e-9 and d not in tried:
                visit(d, tried[best].values)
    best = max(tried, key=ll)
    curvature, slope = envelope_parabola(marginal, best, step)
    if curvature < 0:  # the parabola's vertex, within the last refinement's reach
        vertex = best + float(np.clip(-slope / (2 * curvature), -step / 4, step / 4))
        if vertex not in tried and abs(vertex) <= REFERENCE_DELAY_SPAN_S:
            visit(vertex, tried[best].values)
            best = max(tried, key=ll)
    best = best if best in kept else next(iter(kept))  # a tie: the delay whose model was kept
    edge = best in (min(tried), max(tried))  # the profile may rise beyond the span
    model, fit = settled(kept[best], tried[best], best)
    name = next(n for n in model.names if n.endswith(REFERENCE_DELAY))
    fit.profile_se = {name: float(1.0 / np.sqrt(-2.0 * curvature)) if curvature < 0 and not edge else float("nan")}
    return model, fit


def envelope_parabola(marginal: dict, best: float, step: float) -> tuple:
    """(curvature, slope) at ``best`` of the parabola through the profile's points on the coarse grid
    (whole ping intervals) within two intervals of it; (0, 0) with fewer than three. The marginal
    ripples at the ping interval (RiverPro with a 2-s reference delay: 576 and 571 at +-0.67 s, 514 and
    531 at +-0.34 s from the best), so a parabola through the half and quarter steps as well curves up
    and leaves no standard error; the whole-interval points share one phase of the ripple and trace
    its envelope."""
    on_grid = [d for d in marginal if abs(d - best) <= 2 * step + 1e-9 and abs(d / step - round(d / step)) < 1e-6]
    if len(on_grid) < 3:
        return 0.0, 0.0
    curvature, slope, _ = np.polyfit(np.array(on_grid) - best, [marginal[d] for d in on_grid], 2)
    return float(curvature), float(slope)


PROFILE_REFINEMENTS = 6
PROFILE_SE_SHARE = 0.25  # the profile's maximum located to this share of its SE
PROFILE_WIDTH_SE = 4.0  # by a parabola through points at most this many SEs apart


def profile_maximum(log_likelihood, centre: float, half: float, lo: float, hi: float,
                    refinements: int = PROFILE_REFINEMENTS) -> tuple:
    """(best point, curvature there, {point: value}) of a one-dimensional profile ``log_likelihood``
    on [lo, hi]. From ``centre`` and ``centre`` +- ``half``: the vertex of the parabola through the best
    point and its nearest neighbours on either side (its two nearest where it is outermost), each step
    at most that parabola's width (up the slope by the width where it does not curve down), until the
    vertex lies within :data:`PROFILE_SE_SHARE` of the best point's standard error 1/sqrt(-2 curvature)
    and the three points within :data:`PROFILE_WIDTH_SE` of it (else the points one SE either side),
    at most ``refinements`` steps. The curvature is >= 0 where the profile does not curve down."""
    values = {}

    def visit(v: float) -> None:
        v = float(np.clip(v, lo, hi))
        if v not in values:
            values[v] = float(log_likelihood(v))

    def parabola():  # (best, curvature, slope at the best, the three points' width)
        best = max(values, key=values.__getitem__)
        below, above = [u for u in values if u < best], [u for u in values if u > best]
        # the nearest three alone could lie on one side of a bracketed best (winriver01 with a 4 % sound speed
        # written in: 0, -0.01 and -0.03 nearest -0.03 while -0.06 lay beyond it: its vertex was never visited)
        three = ([max(below), best, min(above)] if below and above else
                 sorted(sorted(values, key=lambda u: abs(u - best))[:3]))
        level = np.array([values[u] for u in three])
        if np.ptp(level) <= 1e-12 * max(1.0, float(np.max(np.abs(level)))):  # flat: the fit's round-off is no slope
            return best, 0.0, 0.0, max(three) - min(three)
        curvature, slope, _ = np.polyfit(np.array(three) - best, level, 2)
        return best, float(curvature), float(slope), max(three) - min(three)

    for v in (centre, centre - half, centre + half, centre - 2 * half, centre + 2 * half):
        if len(values) == 3:  # the last two only where a bound merged two of the first (a start at a bound)
            break
        visit(v)
    for _ in range(refinements):
        best, curvature, slope, width = parabola()
        if curvature >= 0:  # no maximum between them: walk on up the slope (a flat profile has none to walk)
            if slope == 0:
                break
            visit(best + float(np.sign(slope)) * width)
            continue
        step, se = -slope / (2 * curvature), 1.0 / np.sqrt(-2.0 * curvature)
        if abs(step) >= PROFILE_SE_SHARE * se:
            visit(best + float(np.clip(step, -width, width)))
        elif width > PROFILE_WIDTH_SE * se:  # a wide parabola's curvature understates a peak's
            for v in (best - se, best + se):
                visit(v)
        else:
            break  # the maximum is located well within its standard error, by points near enough to give it
    best, curvature, _, _ = parabola()
    return best, curvature, values


def marginal_profile(model: GapModel, name: str, values: dict, sigma: dict, pinned: dict, config: DiagnosisConfig,
                      terms: list, peaks, around: tuple | None = None):
    """(model, fit) at the maximum of the likelihood marginal over the per-ping velocities in the
    unknown ``name``, which scales the velocities the beams see (a sound speed, a beam angle): the
    joint fit the NLP minimises rewards a smaller velocity path, whose walk's rows shrink (winriver01,
    recorded at sea with a salinity setting of 0 ppt: the joint fit puts the sound speed 3.7 % low, the
    marginal 2.8 % high, the salinity's error). Each point is a fit with the unknown held, searched by
    :func:`profile_maximum` from 0 and +- the unknown's scale (or ``around``: an earlier profile's
    maximum and SE, the first points there and +- the SE); the curvature at the maximum gives its
    standard error (``Fit.profile_se``; NaN where it does not curve down); the model at the maximum is
    taken to its delays' fixed point (:func:`fixed_points`)."""
    i = model.names.index(name)
    lo, hi, step = float(model.lbx[i]), float(model.ubx[i]), float(model.scale[i])
    fits = {}

    def log_likelihood(v: float) -> float:  # started from the nearest point's fit
        near = min(fits, key=lambda u: abs(u - v)) if fits else None
        x = fits[near].values if near is not None else values
        fits[v] = model.solve(model.start(x, {name: v}), sigma, fixed={**pinned, name: v})
        return fits[v].log_likelihood(model)

    centre, half = around if around is not None else (0.0, step)
    best, curvature, _ = profile_maximum(log_likelihood, centre, max(half, 0.1 * step), lo, hi)
    model, fit = fixed_points(model.base, terms, peaks, config, model, fits[best], {**pinned, name: best})
    fit.profile_se = {name: float(1.0 / np.sqrt(-2.0 * curvature)) if curvature < 0 else float("nan")}
    return model, fit
