"""Field errors injected into a recorded run, on its recorded channels (attitude samples,
reference, radials), written independently of the fitted model: the check that a diagnosis
finds what a field crew meets is then not the model testing itself.

Each error is named after the catalog effect that should explain it; sizes are the field's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...cases.case import Case
from ...cases.sound_speed import rescale_sound_speed
from ..calibration.moving_bed_decision import mean_flow
from ..run_setup import has_moving_reference
from ...models.effects import get_effect

FIELD_ERRORS = {  # name -> (catalog effect, unit, typical sizes)
    "compass_offset_deg": ("compass_offset", "deg", (2.0, 4.0)),
    "attitude_latency_s": ("attitude_latency", "s", (0.3, 1.0)),
    "reference_latency_s": ("reference_latency", "s", (0.5, 2.0)),
    "moving_bed_m_s": ("moving_bed", "m/s", (0.1, 0.3)),
    "sound_speed_relative": ("sound_speed_error", "", (0.02, 0.04)),
    "tilt_lowpass_s": ("tilt_lowpass", "s", (0.5, 1.5)),
    "heave_m_s": ("heave", "m/s", (0.05, 0.15)),
}
HEAVE_OMEGA_RAD_S = 1.0  # the injected heave's frequency (a 6.3-s swell)
ERROR_UNKNOWNS = {
    # error -> (the unknowns of its catalog effect it moves, the change of each per unit of the error
    # (None: set by the run's course), whether that effect's linearised detection limit bounds it)
    "compass_offset_deg": (("A_rad",), (float(np.radians(1.0)),), True),
    "attitude_latency_s": (("delay_s",), (1.0,), True),
    "reference_latency_s": (("delay_s",), (1.0,), True),
    "sound_speed_relative": (("relative_error",), (-1.0,), True),
    # the low-pass's linearisation at tau = 0 moves the tilts only, while undoing the filter also moves
    # their rates by tau y'' (noisy samples' second derivative): its limit is its forward signature's
    "tilt_lowpass_s": (("tau_s",), (1.0,), False),
    # the bed is injected downstream (across the mean course without a water profile), in a mix of north
    # and east the flow or the course sets
    "moving_bed_m_s": (("velocity_north_m_s", "velocity_east_m_s"), None, True),
    # heave has none: its limit depends on its frequency (:mod:`.signal_limit` gives its signature's)
}


def detection_limit(error: str, limits: dict) -> float | None:
    """The smallest size of ``error`` (its own unit) the diagnosis takes on a file, from its catalog
    effect's per-unknown detection limits (full names -> value, :func:`.covariance.detection_limits`):
    each unknown's limit over its change per unit of the error, the harder of them (a bed: the
    harder of north and east); None where the effect's limit does not bound the error or is missing."""
    names, per_unit, bounded = ERROR_UNKNOWNS.get(error, ((), None, False))
    if not bounded:
        return None
    scale = dict(zip(names, per_unit or (1.0,) * len(names)))
    found = [v / abs(scale[k.rsplit(".", 1)[-1]]) for k, v in limits.items()
             if k.rsplit(".", 1)[-1] in scale and np.isfinite(v)]
    return float(max(found)) if found else None


WRITTEN_INTO_REFERENCE = ("reference_latency_s", "moving_bed_m_s")  # injected into the reference velocity


def needs_reference(error: str) -> bool:
    """Whether ``error`` shows only against a moving reference velocity: written into it
    (:data:`WRITTEN_INTO_REFERENCE`), or named by a catalog effect observable only against one. A constant
    compass offset turns every velocity alike, which without an Earth-frame reference nothing tells
    (RDI_withBT, no GNSS: its signal limit had read 7.5 deg, the linearised walk's prior rows taking
    the turned velocity increments for a misfit, where turning them costs nothing)."""
    return error in WRITTEN_INTO_REFERENCE or get_effect(FIELD_ERRORS[error][0]).needs_reference


def injected_values(cases, error: str, size: float, calibration=None) -> dict:
    """What an injection of ``size`` puts into its catalog effect's unknowns (their last name ->
    value), to check an estimate and its standard error against: each unknown's change per unit
    of the error (:data:`ERROR_UNKNOWNS`), the bed where :func:`injected_bed_direction` sends it; empty for an
    error whose effect has no such values (heave: its frequency is the effect's own)."""
    names, per_unit, _ = ERROR_UNKNOWNS.get(error, ((), None, False))
    if error == "moving_bed_m_s":
        return dict(zip(names, (float(v) for v in size * _unit(injected_bed_direction(cases, calibration)))))
    return {} if per_unit is None else {n: float(size * p) for n, p in zip(names, per_unit)}


def estimate_z(estimate: dict | None, se: dict | None, injected: dict, own: dict | None = None) -> float | None:
    """The largest |estimate - (own + injected)| / SE over the effect's unknowns (full names ending
    in the injected ones' last names; ``own``: full name -> the file's own value, held under the
    injection and named as moved from it); None without an estimate, or where an unknown has no
    finite, positive standard error (held at a bound)."""
    if not estimate or not se or not injected:
        return None
    z = []
    for name, value in estimate.items():
        last = name.rsplit(".", 1)[-1]
        if last not in injected:
            continue
        s = se.get(name)
        if s is None or not np.isfinite(s) or s <= 0 or value is None:
            return None
        z.append(abs(value - (own or {}).get(name, 0.0) - injected[last]) / s)
    return float(max(z)) if z else None


def _unit(direction_rad: float) -> np.ndarray:
    """The horizontal unit vector (north, east) towards ``direction_rad`` (clockwise from north)."""
    return np.array([np.cos(direction_rad), np.sin(direction_rad)])


def injected_bed_direction(cases, calibration=None) -> float:
    """Where an injected bed moves (rad, clockwise from north): downstream, the direction of the runs'
    mean water velocity in the true Earth frame (the calibration's heading misalignment, or a vessel
    sensor's installation angles, turning the sensed one), as a bed moves with the near-bed flow;
    without a water profile, across the runs' mean course to its left."""
    cases = [cases] if isinstance(cases, Case) else list(cases)
    turn = getattr(calibration, "heading_misalignment_rad", None)
    flow = mean_flow(cases, getattr(calibration, "installation_ypr_rad", None),
                     float(turn) if turn is not None and np.isfinite(turn) else 0.0)
    return flow["direction_rad"] if flow else survey_course(cases) - np.pi / 2


def survey_course(cases) -> float:
    """The mean course over ground of one run or of a survey's runs together (rad from north):
    the direction of the mean of every reference velocity."""
    cases = [cases] if isinstance(cases, Case) else list(cases)
    v = np.vstack([c.reference.velocity_m_s for c in cases])
    return float(np.arctan2(np.nanmean(v[:, 1]), np.nanmean(v[:, 0])))


def inject_survey(cases, error: str, size: float, calibration=None) -> list:
    """Every run of a survey (one boat, one river) with the same field error of ``size``
    (:func:`inject`): one compass, one clock, one sound speed, one bed, which moves downstream in
    every run (:func:`injected_bed_direction`, the calibration's heading turning the flow's)."""
    cases = [cases] if isinstance(cases, Case) else list(cases)
    towards = injected_bed_direction(cases, calibration) if error == "moving_bed_m_s" else None
    return [inject(c, error, size, bed_rad=towards) for c in cases]


def inject(case: Case, error: str, size: float, bed_rad: float | None = None) -> Case:
    """``case`` with one field error of ``size`` (units of :data:`FIELD_ERRORS`) written into what
    the instruments recorded.

    - compass_offset_deg: every heading sample turned by ``size`` (true = read - size);
    - attitude_latency_s: attitude samples stamped ``size`` late (the sample stamped t holds t - size);
    - reference_latency_s: reference velocities stamped ``size`` late;
    - moving_bed_m_s: a bed moving at ``size`` towards ``bed_rad`` (default :func:`injected_bed_direction` of
      the run alone: downstream): the bottom track sees v - u, so the reference, which sees v, gets + u;
    - sound_speed_relative: radials (bottom track and water), slant ranges and cell distances scaled
      by 1 + size (the instrument's sound speed off by that fraction,
      :func:`~adcpdyn.cases.sound_speed.rescale_sound_speed`);
    - tilt_lowpass_s: pitch and roll samples read through a first-order low-pass of time constant
      ``size`` (exact for a signal linear between samples);
    - heave_m_s: the boat heaving at :data:`HEAVE_OMEGA_RAD_S` with vertical velocity amplitude
      ``size`` (down positive): every radial gains w cos(beam angle), every slant range loses
      z / cos(beam angle) (the beams' tilt, a few degrees, neglected: cos 4 deg = 0.998).

    Where the run's water depth is derived from its ranges (an imported file), it is derived again
    from the changed ranges, as importing the erroneous file would: a uniform change of the ranges
    then moves the depth with them, and only what differs between the beams is left in the ranges.
    """
    if error not in FIELD_ERRORS:
        raise ValueError(f"error: expected one of {sorted(FIELD_ERRORS)}, got {error!r}")
    if error in WRITTEN_INTO_REFERENCE and not has_moving_reference(case):
        raise ValueError(f"error: {error} needs a moving reference velocity; {case.name} has none")
    att, ref = case.attitude, case.reference
    if error == "compass_offset_deg":
        return case.replace(attitude=dataclasses.replace(att, heading_rad=att.heading_rad + np.radians(size)))
    if error == "attitude_latency_s":
        return case.replace(attitude=dataclasses.replace(att, time_s=att.time_s + size))
    if error == "sound_speed_relative":  # recorded with the instrument's sound speed x (1 + size)
        recorded = rescale_sound_speed(case, 1 + size)
        return recorded.replace(instrument=case.instrument)  # the instrument still believes its own sound speed
    if error == "tilt_lowpass_s":
        return case.replace(attitude=dataclasses.replace(att, pitch_rad=lowpass(att.time_s, att.pitch_rad, size),
                                                         roll_rad=lowpass(att.time_s, att.roll_rad, size)))
    if error == "heave_m_s":
        p, t = case.pings, case.pings.time_s - case.pings.time_s[0]
        z = size / HEAVE_OMEGA_RAD_S * np.sin(HEAVE_OMEGA_RAD_S * t)
        w = size * np.cos(HEAVE_OMEGA_RAD_S * t)
        c = np.cos(case.instrument.beam_angle_rad)
        rng = None if p.bt_range_m is None else p.bt_range_m - (z / c)[:, None]
        return case.with_recorded_pings(dataclasses.replace(p, bt_radial_m_s=p.bt_radial_m_s + (w * c)[:, None], bt_range_m=rng))
    if error == "reference_latency_s":
        return case.replace(reference=ref.shifted(size))
    v = ref.velocity_m_s
    u = size * np.append(_unit(injected_bed_direction(case) if bed_rad is None else bed_rad), 0.0)
    return case.replace(reference=dataclasses.replace(ref, velocity_m_s=v + u))


def lowpass(t: np.ndarray, x: np.ndarray, tau_s: float) -> np.ndarray:
    """First-order low-pass y' = (x - y) / tau of samples x(t), x linear between samples (exact
    first-order-hold discretisation: y_k = a y_k-1 + b0 x_k + b1 x_k-1, a = exp(-h / tau)); NaN
    samples are held over, the output starts at the first finite sample."""
    x = np.asarray(x, dtype=float)
    y = np.full_like(x, np.nan)
    ok = np.flatnonzero(np.isfinite(x))
    if ok.size == 0:
        return y
    prev_t, prev_x, prev_y = t[ok[0]], x[ok[0]], x[ok[0]]
    y[ok[0]] = prev_y
    for k in ok[1:]:
        h = t[k] - prev_t
        a = np.exp(-h / tau_s)
        g = tau_s / h * (1 - a)
        prev_y = a * prev_y + (1 - g) * x[k] + (g - a) * prev_x
        prev_t, prev_x = t[k], x[k]
        y[k] = prev_y
    return y
