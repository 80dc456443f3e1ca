"""The base of a diagnosis, its fit and noise levels, and which catalog effects go on top of it.

1. Base fit (:class:`.model.GapModel` without effects): the calibration's measurement model,
   with a calibration's platform quantities pinned (lever arms, installation angles or heading
   misalignment and deviation) and its noise levels as the start; without one, what the runs
   determine (installation yaw or heading misalignment against a moving reference, lever arms).
   Navigation follows the reference (knots), so speed changes are the base's.
2. Noise levels per (run, channel group): independent where the data allow (attitude from the
   flexible pre-fit, bottom track from the four-beam error velocity), otherwise the first fit's
   residual level (:mod:`.diagnose` then lowers them to the lowest level any fitted model
   reached); with a velocity per ping (random walk) every level and the walk's intensity by
   variance components.
3. Which effects apply (:func:`applicable`: one the base already carries, or the data cannot
   show, is skipped with the reason) and their model terms (:func:`effect_terms`): shared effects
   (compass, beam angles, sound speed, latency, lever arms, installation) act on every run; per-run
   ones (moving bed, heave, forced roll) on each run separately.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...cases.case import Case
from ...models.effects import get_effect
from ..attitude_fit import fit_attitude
from ..calibration.problem import choose_attitude, irregular_attitude
from ..calibration.record import CalibrationRecord
from ..knots import knot_times, ping_knots
from ..measurement_model import EffectTerm, ModelSpec
from ..run_setup import RunSetup, choose_navigation, course_offset_rad, heading_centre
from ..statistics.normal_equations import VCE_RTOL, group_levels, largest_move, redundancy, scored_levels
from .config import DiagnosisConfig
from .model import DiagnosisBase, Fit, GapModel, Pins, free_jacobian, velocity_columns

INDEPENDENT_NOISE = ("heading", "pitch", "roll", "bt", "reference", "motion", "vertical")  # estimated without the model (pre-fit, error velocity, first differences)
PER_RUN_EFFECTS = ("moving_bed", "heave", "forced_roll", "surge")
# variance-component re-estimations of the base (each with a refit), until no level moves by more than VCE_RTOL. A random
# walk's levels crawl there by the redundancies' iteration (RiverPro's vertical level 9.8, 7.7, 6.3, 5.2 % a round
# after its third, still 2.5 % after twelve; neither Aitken's delta-squared per level nor SQUAREM settled it within
# ten): Fisher scoring (normal_equations.scored_levels) takes the steps where its dense algebra is cheap, 5 on RiverPro
# and winriver01; winriver02's 2500 unknowns iterate the redundancies, about 15 rounds
VCE_MAX_ITERATIONS = 20

def group_sigma(model: GapModel, raw: np.ndarray) -> dict:
    out = {}
    for i, key in enumerate(model.sigma_keys):
        m = (model.row_sigma == i) & (model.mask > 0)
        out[key] = float(np.sqrt(np.mean(raw[m] ** 2))) if m.any() else np.nan
    return out


def velocity_error(model: GapModel, fit: Fit) -> float | None:
    """RMS horizontal error of the per-ping velocity over ground corrected with the fitted model
    (all runs with a truth)."""
    errs = []
    for k, run in enumerate(model.base.runs):
        truth = run.case.truth
        if truth is None or truth.vessel_velocity_m_s is None:
            continue
        v = model.corrected_velocity(fit, k)
        err = v[:, :2] - truth.vessel_velocity_m_s[:, :2]
        errs.append(err[np.all(np.isfinite(err), axis=1)])
    if not errs or not np.concatenate(errs).size:
        return None
    err = np.concatenate(errs)
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


def base_from(cases: list, config: DiagnosisConfig, calibration: CalibrationRecord | None = None) -> DiagnosisBase:
    """The base of a diagnosis: the runs' attitude and navigation, the calibration's platform
    quantities pinned (or estimated from the runs), the starting noise levels."""
    runs, notes = [], []
    timing = "deep" if calibration and calibration.timing.split(",")[0] in ("deep", "exact") else "shallow"
    for case in cases:
        af = fit_attitude(case, max_modes=config.max_modes)
        own = None if calibration is None else calibration.run_of(case)
        if own and own.attitude_model is not None:  # this very run was calibrated: its motion model starts the fit
            af = dataclasses.replace(af, params=own.attitude_model)
        source, reason = choose_attitude(case, af, config.attitude)
        navigation = choose_navigation(case, source, config.navigation, irregular_attitude(af))
        knots = ping_knots(case) if navigation == "random_walk" else knot_times(case, None)
        runs.append(RunSetup(case, af, source, timing, knots, case.pings.bt_range_m is not None, reason,
                             navigation=navigation,
                             sample_interpolation=None if calibration is None else calibration.sample_interpolation()))
    head = runs[0].case.attitude.frame == "transducer"
    moving = any(r.moving_reference for r in runs)
    v = cases[0].vessel
    pins, sigma0, moving_bed = {}, {}, "off"
    installation, nominal, heading, centre = ("head" if head else "estimate" if moving else "fixed"), (0.0, 0.0, 0.0), \
        ("misalignment" if head and moving else "off"), (0.0, 0.0)
    if calibration is not None:
        if not head:
            installation = "fixed"
            try:
                angles, determined = calibration.installation_or_nominal()
            except ValueError:  # neither calibrated nor configured: level
                angles, determined = np.zeros(3), False
            nominal = tuple(float(a) for a in angles)
            notes.append("installation angles pinned at the calibration's" if determined else
                         "installation angles not determined by the calibration: its nominal ones are used")
        d = calibration.heading_misalignment_rad
        if head and moving and d is not None:
            deviation = calibration.compass_deviation_rad
            if deviation is not None and np.all(np.isfinite(deviation)):
                heading = "deviation"
                centre = heading_centre(runs)  # re-centre the calibration's correction on these runs' headings
                b, c, mean_sin, mean_cos = calibration.compass_deviation_applied()
                d = d + b * (centre[0] - mean_sin) + c * (centre[1] - mean_cos)
                pins.update({"compass_deviation_sin": b, "compass_deviation_cos": c})
            pins["heading_misalignment"] = float(d)
            notes.append("heading misalignment (and deviation) pinned at the calibration's")
        try:
            r = calibration.lever_arms_in("transducer" if head else "vessel")
        except ValueError:  # not in the file, or not determined: estimated from the runs
            r = None
        if r is not None:
            for a, value in zip("xyz", r.mean(axis=0)):
                pins[f"P_{a}"] = float(value)
            notes.append("lever arms pinned at the calibration's (head centre)")
        bed = calibration.moving_bed_velocity_m_s
        if bed is not None and all(calibration.holds(c) for c in cases) and calibration.moving_bed == "constant":
            moving_bed = "constant"  # these very runs were calibrated: their bed is the base's
            pins.update({"moving_bed_north": float(bed[0]), "moving_bed_east": float(bed[1])})
            notes.append("moving bed pinned at the calibration's (these runs are its own: by name or within its time span)")
        for k, case in enumerate(cases):  # a calibrated run's transducer depth, as its slant ranges gave it
            own = calibration.run_of(case)
            if own and own.transducer_depth_offset_m is not None and runs[k].use_ranges:
                name = "transducer_depth_offset_m" if len(cases) == 1 else f"run{k + 1}/transducer_depth_offset_m"
                pins[name] = own.transducer_depth_offset_m
        for group, value in calibration.noise_sigma.items():
            if isinstance(value, (int, float)) and value > 0:
                for k in range(len(runs)):
                    sigma0[(k, group)] = float(value)
    spec = ModelSpec(formulation="minimal", lever_box_m=0.5 * v.length_m if v.length_m else 10.0,
                     installation=installation, nominal_installation_ypr_rad=nominal,
                     yaw_centre_rad=course_offset_rad(runs) if installation == "estimate" or heading != "off" else 0.0,
                     heading=heading, moving_bed=moving_bed)
    for k, run in enumerate(runs):
        for group, value in run.noise_guess().items():
            if group in INDEPENDENT_NOISE or (k, group) not in sigma0:
                sigma0[(k, group)] = value
    if any(r.random_walk for r in runs):
        notes.append("vessel velocity at every ping under a random-walk prior, its intensity and the noise levels from "
                     "the data (variance components)")
    return DiagnosisBase(runs, spec, Pins(pins, "calibration" if calibration is not None else ""), sigma0, notes)


def fit_base(cases, config: DiagnosisConfig, calibration: CalibrationRecord | None = None):
    """(base, its model, its fit, noise levels): two passes, the noise of the groups without an
    independent estimate re-estimated from the first."""
    cases = [cases] if isinstance(cases, Case) else list(cases)
    base = base_from(cases, config, calibration)
    model = GapModel(base, solver=config.solver)
    centre = np.array([base.pins.values.get(f"P_{a}", 0.0) for a in "xyz"])
    angles = np.array([model.model.spec.yaw_centre_rad, 0.0, 0.0])
    x0 = model.model.initial_x([r.fit.params for r in base.runs], angles, centre, heading_guess=angles[0])
    x0 = model.start({**dict(zip(model.names, x0)), **base.pins.values})
    # installation angles held at their start (the course offset) first, then freed from that optimum: a
    # misfit the base cannot represent (an effect) must not drive them to their box in the first solve
    held = {n: float(x0[i]) for i, n in enumerate(model.names) if n.startswith("installation_")}
    if held:
        x0 = model.solve(x0, base.sigma0, fixed=held).x
    fit = model.solve(x0, base.sigma0)
    sigma = dict(base.sigma0)
    if model.random_walk:  # a velocity per ping: every noise level and the walk's intensity from the data
        fit, sigma, base.noise_moved, count = noise_from_data(model, fit)
        base.notes.append(settled_note(base.noise_moved, count))
        return base, model, fit, sigma
    rms = group_sigma(model, fit.raw)
    for key in model.sigma_keys:
        if key[1] not in INDEPENDENT_NOISE:
            sigma[key] = max(rms[key], 1e-6)
    fit = model.solve(fit.x, sigma)
    return base, model, fit, sigma


def noise_from_data(model: GapModel, fit: Fit, fixed: dict | None = None) -> tuple:
    """(fit, noise levels, the largest relative move of a level at the last re-estimation, the
    re-estimations made): variance-component re-estimations, each with a refit (``fixed``: unknowns
    held at their values), until settled (no level moves more than ``VCE_RTOL``) or
    :data:`VCE_MAX_ITERATIONS`; a scoring step (:func:`scored_components`) where the model is small
    enough, else the redundancies' step (:func:`variance_components`). What is left of the move is
    reported, not hidden."""
    sigma, moved, count = fit.sigma, np.inf, 0
    while count < VCE_MAX_ITERATIONS and moved > VCE_RTOL:
        new = scored_components(model, fit)
        if new is None:  # too large for the scoring's dense algebra
            new = variance_components(model, fit)
        moved, sigma = largest_move(new, sigma), new
        fit = model.solve(fit.x, sigma, fixed=fixed)
        count += 1
    return fit, sigma, moved, count


def settled_note(moved: float, count: int) -> str:
    """The base's noise levels in words: settled, or how far from it (what its standard errors scale with)."""
    head = f"noise levels re-estimated {count} times"
    if moved <= VCE_RTOL:
        return f"{head}, settled to {100 * VCE_RTOL:g} %"
    return f"{head}, NOT settled: they still moved {100 * moved:.1f} % at the last (the standard errors scale with them)"


def scored_components(model: GapModel, fit: Fit) -> dict | None:
    """The noise levels after one Fisher-scoring step (:func:`~adcpdyn.estimators.statistics.normal_equations.scored_levels`)
    from the fit's levels; None where the model is too large for its dense algebra."""
    J, _ = free_jacobian(fit)
    return scored_levels(J, fit.raw, model.row_sigma, model.mask > 0, model.sigma_keys, fit.sigma)


def variance_components(model: GapModel, fit: Fit) -> dict:
    """Each (run, group)'s noise level from the fit's residuals over their redundancy (Helmert /
    Foerstner variance-component estimation: sigma_g^2 = e_g^T e_g / (n_g - sum of the group's
    leverages)); the random walk's intensity is one of them (REML for a linear-Gaussian walk)."""
    J, cols = free_jacobian(fit)
    used = model.mask > 0
    r = redundancy(J, model.row_sigma, used, len(model.sigma_keys), local=velocity_columns(model, cols))
    return group_levels(fit.raw, model.row_sigma, used, model.sigma_keys, r, fit.sigma)


def applicable(base: DiagnosisBase, name: str) -> tuple[bool, str]:
    """Whether an effect can be tried on top of this base, and why not."""
    e = get_effect(name)
    if base.sampled and e.needs_motion_model:
        return False, "acts on the motion model only; the beams use the sensor's samples (which hold it already)"
    moving = any(r.moving_reference for r in base.runs)
    stationary = all(r.knots is None for r in base.runs)  # the vessel is known to stay put
    if name == "moving_bed" and not moving and not stationary:
        return False, "a moving bed is indistinguishable from vessel motion without a reference"
    if e.needs_reference and not moving and not (name == "moving_bed" and stationary):
        return False, "needs a moving reference velocity"
    if name == "surge" and not stationary:  # a run held still (the pool) has no navigation to follow a surge
        how = ("a velocity at every ping" if any(r.random_walk for r in base.runs)
               else "a piecewise-linear velocity")
        return False, f"part of the base: its navigation ({how} through the reference or bottom track) follows speed changes"
    if name == "forced_roll":
        return False, ("part of the base: its motion model's modes may be steady (wave-forced), as the calibration's; an "
                       "oscillation it misses shows as a gap at its frequency")
    if name == "installation_misalignment" and base.spec.installation == "estimate":
        return False, "part of the base: the installation angles are estimated against the moving reference"
    if name == "installation_misalignment" and base.spec.installation == "head":
        return False, ("not observable: a sensor inside the head turns with the head, so the beams' attitude does not "
                       "depend on how the head sits in the vessel (notes on the paper, erratum 5); its heading against "
                       "the reference is the base's heading misalignment")
    if name == "compass_offset" and base.spec.heading != "off" and "heading_misalignment" not in base.pins.values:
        return False, "part of the base: the heading misalignment it estimates against the reference is a constant heading error"
    if name == "deep_water_timing" and base.runs[0].timing != "shallow":
        return False, "part of the base: the calibration's two-way timing"
    return True, ""


def effect_terms(base: DiagnosisBase, name: str) -> list:
    """The model terms of one effect: shared by all runs, or one per run for per-run effects."""
    e = get_effect(name)
    if name in PER_RUN_EFFECTS and len(base.runs) > 1:
        return [EffectTerm(e, k) for k in range(len(base.runs))]
    return [EffectTerm(e)]


def pinned_effect_parameters(model: GapModel, base: DiagnosisBase) -> dict:
    """Effect unknowns the base already carries: the compass's constant against a free misalignment."""
    out = {}
    if base.spec.heading != "off" and "heading_misalignment" not in base.pins.values:
        out.update({n: 0.0 for n in model.effect_names if n.endswith("compass_deviation.A_rad")})
    return out
