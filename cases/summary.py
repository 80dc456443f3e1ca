"""A readable summary of a case (``adcpdyn info``)."""

from __future__ import annotations

import numpy as np
from scipy.signal import lombscargle

from ..models.janus import error_velocity
from ..models.motion import MIN_SPLINE_SAMPLES, fast_axes
from ..text import prose
from .case import Case


def dominant_period_s(t, x, f_min_hz=0.02, f_max_hz=3.0) -> float:
    """Period of the strongest Lomb-Scargle peak of irregular samples, sought from ``f_min_hz`` up
    to ``f_max_hz`` or the samples' Nyquist frequency (0.5 / median interval), whichever is lower:
    with one sample per ping and a few per cent of jitter, a peak above it is an alias, not a
    motion (NaN if too few samples or no band left)."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(t) & np.isfinite(x)
    t, x = t[ok], x[ok]
    if t.size < 8 or np.ptp(x) == 0:
        return float("nan")
    f_max_hz = min(f_max_hz, sampled_nyquist_hz(t))
    if f_max_hz <= f_min_hz:
        return float("nan")
    x = x - np.polyval(np.polyfit(t - t[0], x, 1), t - t[0])
    f = np.linspace(f_min_hz, f_max_hz, 3000)
    power = lombscargle(t, x, 2 * np.pi * f)
    return float(1.0 / f[np.argmax(power)])


def sampled_nyquist_hz(t) -> float:
    """0.5 / the median interval of sample times (NaN for fewer than two)."""
    dt = np.diff(np.asarray(t, dtype=float))
    return 0.5 / float(np.median(dt)) if dt.size else float("nan")


def error_velocity_levels(radial_m_s, beam_dirs) -> tuple[float, float, int]:
    """(RMS error velocity, per-beam noise it implies, pings used) of four-beam pings: the error
    velocity (RDI's, :func:`~adcpdyn.models.janus.error_velocity`) is what no rigid velocity
    explains, so for independent beam noise sigma its RMS is sigma |e|, e the error row; NaN where
    no ping has four beams."""
    err, norm = error_velocity(radial_m_s, beam_dirs)
    err = err[np.isfinite(err)]
    if not err.size:
        return float("nan"), float("nan"), 0
    rms = float(np.sqrt(np.mean(err**2)))
    return rms, rms / norm, int(err.size)


def _intervals(t):
    dt = np.diff(t)
    return f"{dt.mean():.3f} s mean interval ({dt.min():.3f}-{dt.max():.3f} s)" if dt.size else "single sample"


LABEL_WIDTH = 13  # "instrument   ": a wrapped line continues under the values


def summarise(case: Case) -> str:
    """Multi-line description: instrument, durations, rates, motion, groups present."""
    ins, env, p, a = case.instrument, case.environment, case.pings, case.attitude
    dur = p.time_s[-1] - p.time_s[0]
    lost = np.isnan(p.bt_radial_m_s)
    lines = [
        f"case         {case.name}: {case.description}",
        f"instrument   {ins.layout}, beam angle {np.rad2deg(ins.beam_angle_rad):.2f} deg, "
        f"f0 {ins.frequency_hz / 1e3:.1f} kHz, c {ins.sound_speed_m_s:.1f} m/s"
        + (f" (from {ins.temperature_c:.2f} deg C, salinity setting {ins.salinity_psu:g} ppt)"
           if ins.temperature_c is not None and ins.salinity_psu is not None else "")
        + f", tr {ins.transducer_radius_m * 100:.2f} cm"
        + (", custom beam vectors" if ins.beam_dirs_t is not None else ""),
        f"environment  water depth {env.water_depth_m:.2f} m"
        + (" (per ping)" if env.water_depth_per_ping_m is not None else "")
        + f", transducer depth {env.transducer_depth_m:.2f} m",
        f"pings        {p.n} over {dur:.1f} s, {_intervals(p.time_s)}; lost beams {int(lost.sum())} of {lost.size}"
        + ("; slant ranges" if p.bt_range_m is not None else ""),
    ]
    rms, beam, used = error_velocity_levels(p.bt_radial_m_s, ins.beam_directions())
    if used:
        lines.append(f"  error vel  RMS {rms:.4f} m/s over {used} four-beam pings: about {beam:.4f} m/s of noise per beam")
    ypr = a.ypr()
    amp = lambda x: 0.5 * (np.nanpercentile(x, 99) - np.nanpercentile(x, 1))
    missing = int((~a.complete()).sum())
    lines.append(f"attitude     {a.time_s.size} samples ({a.frame} frame), {_intervals(a.time_s)}"
                 + (f"; {missing} with a NaN angle" if missing else ""))
    nyquist_hz = sampled_nyquist_hz(a.time_s)
    for label, x in (("roll", ypr[:, 2]), ("pitch", ypr[:, 1])):
        lines.append(
            f"  {label:<6}     amplitude {np.rad2deg(amp(x)):.2f} deg, mean {np.rad2deg(np.nanmean(x)):.2f} deg, "
            f"dominant period {dominant_period_s(a.time_s, x):.2f} s"
            + (f" (sought up to the samples' Nyquist {nyquist_hz:.2g} Hz)" if nyquist_hz < 3.0 else "")
        )
    heading = ypr[np.isfinite(ypr[:, 0]), 0]
    lines.append(f"  heading    {np.rad2deg(heading[0]) % 360:.1f} -> {np.rad2deg(heading[-1]) % 360:.1f} deg, "
                 f"span {np.rad2deg(np.ptp(heading)):.1f} deg")
    complete = a.complete()
    if complete.sum() >= MIN_SPLINE_SAMPLES:
        fast = [f"{n} {100 * v:.0f} %" for n, v in fast_axes(a.time_s[complete], ypr[complete]).items()]
        lines.append("  joined     " + (f"linearly where the beams take the samples: {', '.join(fast)} of the variance "
                                        "above half their Nyquist frequency, where a smoothing spline would cut into "
                                        "the motion" if fast else "by a smoothing spline within the motion band where "
                                        "the beams take the samples"))
    if case.water is not None:
        d = case.water.cell_depth_m
        lines.append(f"water        {d.size} cells, {d[0]:.2f}-{d[-1]:.2f} m deep")
    if case.reference is not None:
        r = case.reference
        if r.velocity_m_s is not None and r.time_s is not None:
            speeds = np.hypot(r.velocity_m_s[:, 0], r.velocity_m_s[:, 1])
            speed = np.nanmean(speeds) if np.isfinite(speeds).any() else float("nan")
            lines.append(f"reference    {r.time_s.size} samples, {_intervals(r.time_s)}, mean speed {speed:.3f} m/s, "
                         f"point {np.round(r.point_body_m, 3).tolist()} m")
        else:
            lines.append("reference    stationary vessel (velocity zero)")
    if case.position is not None:
        pos = case.position
        lines.append(f"position     {pos.time_s.size} fixes, median {np.median(pos.latitude_deg):.5f} N "
                     f"{np.median(pos.longitude_deg):.5f} E")
    if case.time_origin_utc is not None:
        lines.append(f"clock        zero at {case.time_origin_utc} (UTC)")
    if case.vessel.length_m:
        v = case.vessel
        lines.append(f"vessel       {v.length_m} x {v.beam_m} x {v.height_m} m, {v.mass_kg} kg")
    if case.truth is not None:
        names = [e.get("name", "?") for e in case.truth.effects]
        lines.append(f"truth        present; effects: {', '.join(names) if names else 'none'}")
    groups = ["instrument", "environment", "pings", "attitude"] + [
        g for g, present in (("vessel", case.vessel.length_m is not None), ("water", case.water is not None),
                             ("reference", case.reference is not None), ("position", case.position is not None),
                             ("truth", case.truth is not None)) if present
    ]
    lines.append(f"groups       {', '.join(groups)}")
    return "\n".join(prose(line, indent=" " * LABEL_WIDTH) for line in lines)
