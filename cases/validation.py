"""Validation of a case in memory (``docs/case-format.md``): shapes, units, signs and what no
instrument records, each refusal one line naming the field (:class:`.checks.CaseFormatError`);
and the warnings a valid but unusual case earns (:func:`case_warnings`).
"""

from __future__ import annotations

import json
import math

import numpy as np

from .case import (ATTITUDE_FRAMES, Attitude, Case, Environment, Instrument, Pings, Position, Reference, Truth, Vessel,
                   Water, parse_utc)
from .checks import VESSEL_FIELDS, Checker, attr_name, number_text, quoted

__all__ = ["validate_case", "case_warnings", "time_tolerance_s"]

_UNIT_TOL = 1e-6
_HEADING_MAX = 2.0 * math.pi + 1e-9

# Plausibility: beyond these bounds a file is refused (one line naming the field); what is
# only unusual is reported by :func:`case_warnings`.
SOUND_SPEED_RANGE_M_S = (1000.0, 2000.0)  # any water (and then some); 1e-3 m/s or 1e5 m/s is no sound speed
SOUND_SPEED_USUAL_M_S = (1400.0, 1600.0)  # fresh to salt water, 0-35 degC: outside this, a warning
BEAM_ANGLE_RANGE_RAD = (math.radians(5.0), math.radians(60.0))  # Janus instruments: 15-30 deg
BEAM_ANGLE_USUAL_RAD = (math.radians(10.0), math.radians(45.0))
MIN_BEAM_SPAN = 0.05  # smallest singular value of the (4, 3) beam matrix: the beams must span 3-D
MAX_SPEED_M_S = 20.0  # radial velocities (bottom track, water) and reference velocity components
MAX_TRANSDUCER_RADIUS_M = 2.0
FREQUENCY_RANGE_HZ = (1e3, 1e8)  # ADCPs: 38 kHz - 3 MHz
MAX_DEPTH_M = 12000.0  # the deepest ocean is 11 km
MAX_RANGE_OVER_DEPTH = 10.0  # a slant range more than 10 x the deepest bed is no range to that bed
MAX_LEVER_ARM_M = 100.0  # body-frame positions (reference point): no vessel is larger
_VESSEL_MAX = {"length_m": 500.0, "beam_m": 100.0, "height_m": 100.0, "draft_m": 50.0, "mass_kg": 1e9,
               "displaced_volume_m3": 1e6}  # the largest ships afloat, with margin


def time_tolerance_s(times) -> float:
    """How far beyond a sampled record a time still counts as inside it: one median sample
    interval (0 for a single sample)."""
    t = np.asarray(times, dtype=float)
    return float(np.median(np.diff(t))) if t.size > 1 else 0.0


def validate_case(case: Case, source: str = "<memory>") -> None:
    """Check a case against the format and raise on the first problem found.

    Parameters
    ----------
    case : Case
        The case to check.
    source : str, optional
        Name used as the prefix of error messages (normally the file name).

    Raises
    ------
    CaseFormatError
        With a one-line message naming the HDF5 field, what was expected and what
        was found: wrong shapes (in terms of N pings, M attitude samples, L reference
        samples, K cells), times that are not finite and strictly increasing, angles
        that look like degrees, infinite or all-NaN attitude angles, unsupported beam
        layouts, an all-NaN bottom-track beam, non-unit beam vectors, non-positive
        frequency, sound speed or water depth, an unknown attitude frame, a moving
        reference without samples, or malformed truth effects. And what no instrument
        records (the bounds are this module's constants): a sound speed outside
        1000-2000 m/s, a beam angle outside 5-60 deg, beams that do not span 3-D,
        radial or reference velocities beyond 20 m/s, a transducer at or below the
        bed, cells above the transducer or below the deepest bed, slant ranges <= 0
        or beyond ten times the deepest bed, an attitude or reference record that does
        not overlap the pings (within one median sample interval:
        :func:`time_tolerance_s`). NaN (missing) is accepted wherever the format allows
        it: radial velocities, slant ranges, water radials, reference velocity
        components, per-ping bed depths (the attribute applies), attitude samples
        (left out by the verbs that use the attitude, :mod:`adcpdyn.cases.coverage`).
        What is only unusual is reported by :func:`case_warnings`.
    """
    c = Checker(source)
    c.instance(case, Case, "/")
    c.string(case.name, attr_name("/", "name"))
    c.string(case.description, attr_name("/", "description"))

    # /instrument
    ins = case.instrument
    c.instance(ins, Instrument, "/instrument")
    g = "/instrument"
    alpha = c.scalar(ins.beam_angle_rad, attr_name(g, "beam_angle_rad"))
    lo, hi = BEAM_ANGLE_RANGE_RAD
    if not (lo <= alpha <= hi):
        c.fail(attr_name(g, "beam_angle_rad"),
               f"expected radians in [{lo:.4f}, {hi:.4f}] ({math.degrees(lo):g}-{math.degrees(hi):g} deg), "
               f"got {number_text(alpha)}" + (" (degrees?)" if alpha > math.pi / 2 else ""))
    tr = c.non_negative(ins.transducer_radius_m, attr_name(g, "transducer_radius_m"))
    if tr > MAX_TRANSDUCER_RADIUS_M:
        c.fail(attr_name(g, "transducer_radius_m"), f"expected metres <= {MAX_TRANSDUCER_RADIUS_M:g}, got {number_text(tr)}")
    f0 = c.positive(ins.frequency_hz, attr_name(g, "frequency_hz"))
    if not FREQUENCY_RANGE_HZ[0] <= f0 <= FREQUENCY_RANGE_HZ[1]:
        c.fail(attr_name(g, "frequency_hz"), f"expected an acoustic frequency, {FREQUENCY_RANGE_HZ[0]:g}-"
                                         f"{FREQUENCY_RANGE_HZ[1]:g} Hz, got {number_text(f0)}")
    sound = c.positive(ins.sound_speed_m_s, attr_name(g, "sound_speed_m_s"))
    lo, hi = SOUND_SPEED_RANGE_M_S
    if not (lo <= sound <= hi):
        c.fail(attr_name(g, "sound_speed_m_s"), f"expected a sound speed in water, {lo:g}-{hi:g} m/s, got {number_text(sound)}")
    nb = ins.n_beams
    if isinstance(nb, (bool, np.bool_)) or not isinstance(nb, (int, np.integer)) or nb != 4:
        c.fail(attr_name(g, "n_beams"), f"expected 4, got {quoted(nb)}")
    if ins.layout != "janus4":
        c.fail(attr_name(g, "layout"), f'expected "janus4", got {quoted(ins.layout)}')
    if ins.beam_dirs_t is not None:
        f = "/instrument/beam_dirs_t"
        d = c.shape(ins.beam_dirs_t, f, (4, 3))
        c.finite(d, f)
        norms = np.linalg.norm(d, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_TOL)
        if bad.size:
            i = int(bad[0])
            c.fail(f, f"expected unit vectors (|d| = 1 within {_UNIT_TOL:g}), "
                      f"got |d| = {number_text(norms[i])} for beam {i + 1}")
        off_axis = np.degrees(np.arccos(np.clip(d[:, 2], -1.0, 1.0)))
        lo, hi = np.degrees(BEAM_ANGLE_RANGE_RAD)
        bad = np.flatnonzero((off_axis < lo) | (off_axis > hi))
        if bad.size:
            i = int(bad[0])
            c.fail(f, f"expected beams {lo:g}-{hi:g} deg from z_t (out of the face), got {off_axis[i]:.6g} deg "
                      f"for beam {i + 1}")
        span = np.linalg.svd(d, compute_uv=False)[-1]
        if span < MIN_BEAM_SPAN:
            c.fail(f, f"expected beams spanning 3-D (smallest singular value >= {MIN_BEAM_SPAN:g}), got "
                      f"{span:.3g} (beams parallel or in one plane)")
    if ins.beam_pos_t is not None:
        f = "/instrument/beam_pos_t"
        pos = c.shape(ins.beam_pos_t, f, (4, 3))
        c.finite(pos, f)
        c.within(pos, f, -MAX_TRANSDUCER_RADIUS_M, MAX_TRANSDUCER_RADIUS_M,
                 f"positions within {MAX_TRANSDUCER_RADIUS_M:g} m of P")

    # /pings (first: N is needed by the other groups)
    p = case.pings
    c.instance(p, Pings, "/pings")
    t = c.times(p.time_s, "/pings/time_s", "N")
    n = t.size
    n_from = f"with N={n} from /pings/time_s"
    f = "/pings/bt_radial_m_s"
    bt = c.shape(p.bt_radial_m_s, f, (n, 4), "(N, 4)", n_from)
    c.no_inf(bt, f)
    c.within(bt, f, -MAX_SPEED_M_S, MAX_SPEED_M_S, f"|radial velocity| <= {MAX_SPEED_M_S:g} m/s (a vessel's "
             f"speed; the sound speed is {number_text(sound)} m/s) or NaN")
    dead = np.flatnonzero(np.isnan(bt).all(axis=0))
    if dead.size:
        c.fail(f, f"expected data in every beam, got all NaN in beam {int(dead[0]) + 1}")
    ranges = None
    if p.bt_range_m is not None:
        f = "/pings/bt_range_m"
        ranges = c.shape(p.bt_range_m, f, (n, 4), "(N, 4)", n_from)
        c.no_inf(ranges, f)
        c.within(ranges, f, np.nextafter(0.0, 1.0), np.inf, "slant ranges > 0 or NaN")

    # /environment
    env = case.environment
    c.instance(env, Environment, "/environment")
    g = "/environment"
    bed = c.positive(env.water_depth_m, attr_name(g, "water_depth_m"))
    if bed > MAX_DEPTH_M:
        c.fail(attr_name(g, "water_depth_m"), f"expected metres <= {MAX_DEPTH_M:g} (the deepest ocean), got {number_text(bed)}")
    td = c.non_negative(env.transducer_depth_m, attr_name(g, "transducer_depth_m"))
    if not td < bed:
        c.fail(attr_name(g, "transducer_depth_m"), f'expected a transducer above the bed (< /environment.attrs'
                                                f'["water_depth_m"] = {number_text(bed)} m), got {number_text(td)}')
    beds = np.array([bed])
    if env.water_depth_per_ping_m is not None:
        f = "/environment/water_depth_m"
        wd = c.shape(env.water_depth_per_ping_m, f, (n,), "(N,)", n_from)
        c.no_inf(wd, f)
        if (wd <= 0).any():
            i = int(np.flatnonzero(wd <= 0)[0])
            c.fail(f, f"expected water depths > 0, got {number_text(wd[i])} at index {i}")
        c.within(wd, f, np.nextafter(td, np.inf), MAX_DEPTH_M,
                 f"bed depths below the transducer (> transducer_depth_m = {number_text(td)} m) and <= {MAX_DEPTH_M:g} m, "
                 "or NaN (missing: the attribute applies)")
        beds = np.where(np.isfinite(wd), wd, bed)
    if ranges is not None and np.isfinite(ranges).any():
        c.within(ranges, "/pings/bt_range_m", 0.0, MAX_RANGE_OVER_DEPTH * float(beds.max()),
                 f"slant ranges <= {MAX_RANGE_OVER_DEPTH:g} x the deepest bed ({number_text(beds.max())} m)")

    # /vessel
    c.instance(case.vessel, Vessel, "/vessel")
    for name in VESSEL_FIELDS:
        v = getattr(case.vessel, name)
        if v is not None:
            v = c.positive(v, attr_name("/vessel", name))
            if v > _VESSEL_MAX[name]:
                c.fail(attr_name("/vessel", name), f"expected a value <= {_VESSEL_MAX[name]:g} (larger than any ship), "
                                               f"got {number_text(v)}")

    # /water
    k = None
    if case.water is not None:
        w = case.water
        c.instance(w, Water, "/water")
        f = "/water/cell_depth_m"
        cd = c.array(w.cell_depth_m, f)
        if cd.ndim != 1:
            c.fail(f, f"expected shape (K,), got {cd.shape}")
        if cd.size == 0:
            c.fail(f, "expected at least one cell (K >= 1; leave /water out when there is no profile), got 0")
        c.finite(cd, f)
        c.within(cd, f, np.nextafter(td, np.inf), np.nextafter(float(beds.max()), 0.0),
                 f"cell depths between the transducer ({number_text(td)} m) and the deepest bed ({number_text(beds.max())} m)")
        k = cd.size
        f = "/water/radial_m_s"
        wr = c.shape(w.radial_m_s, f, (n, 4, k), "(N, 4, K)",
                     f"with N={n} from /pings/time_s and K={k} from /water/cell_depth_m")
        c.no_inf(wr, f)
        c.within(wr, f, -MAX_SPEED_M_S, MAX_SPEED_M_S, f"|radial velocity| <= {MAX_SPEED_M_S:g} m/s or NaN")

    # /attitude
    a = case.attitude
    c.instance(a, Attitude, "/attitude")
    ta = c.times(a.time_s, "/attitude/time_s", "M")
    m_from = f"with M={ta.size} from /attitude/time_s"
    limits = {
        "heading_rad": (_HEADING_MAX, "|heading| <= 2*pi"),
        "pitch_rad": (math.pi / 2, "|pitch| <= pi/2"),
        "roll_rad": (math.pi / 2, "|roll| <= pi/2"),
    }
    complete = np.ones(ta.size, dtype=bool)
    for name, (limit, what) in limits.items():
        f = f"/attitude/{name}"
        ang = c.shape(getattr(a, name), f, (ta.size,), "(M,)", m_from)
        c.no_inf(ang, f)  # NaN: a missing sample (left out by every verb that uses the attitude)
        if np.isnan(ang).all():
            c.fail(f, "expected at least one finite angle (NaN only where a sample is missing), got all NaN")
        c.max_abs(ang, f, limit, what)
        complete &= np.isfinite(ang)
    if not complete.any():
        c.fail("/attitude", "expected at least one sample with finite heading, pitch and roll, got none")
    tol = time_tolerance_s(ta)
    inside = (t >= ta[0] - tol) & (t <= ta[-1] + tol)
    if not inside.any():
        c.fail("/attitude/time_s", f"expected a record overlapping the pings (within {tol:.3g} s, one median "
                                   f"attitude interval), got [{ta[0]:.6g}, {ta[-1]:.6g}] s for pings at "
                                   f"[{t[0]:.6g}, {t[-1]:.6g}] s")
    if a.frame not in ATTITUDE_FRAMES:
        allowed = ", ".join(f'"{x}"' for x in ATTITUDE_FRAMES)
        c.fail(attr_name("/attitude", "frame"), f"expected one of {allowed}, got {quoted(a.frame)}")

    # /reference
    if case.reference is not None:
        r = case.reference
        c.instance(r, Reference, "/reference")
        f = attr_name("/reference", "point_body_m")
        point = c.shape(r.point_body_m, f, (3,))
        c.finite(point, f)
        c.within(point, f, -MAX_LEVER_ARM_M, MAX_LEVER_ARM_M, f"metres within +-{MAX_LEVER_ARM_M:g} of G")
        if not isinstance(r.stationary, (bool, np.bool_)):
            c.fail(attr_name("/reference", "stationary"), f"expected 0 or 1, got {quoted(r.stationary)}")
        if not r.stationary:
            for name in ("time_s", "velocity_m_s"):
                if getattr(r, name) is None:
                    c.fail(f"/reference/{name}", 'expected a dataset when '
                           '/reference.attrs["stationary"] is 0, got none')
        if r.velocity_m_s is not None and r.time_s is None:
            c.fail("/reference/time_s", "expected a dataset when "
                   "/reference/velocity_m_s is present, got none")
        if r.time_s is not None:
            tr = c.times(r.time_s, "/reference/time_s", "L")
            if r.velocity_m_s is not None:
                f = "/reference/velocity_m_s"
                vr = c.shape(r.velocity_m_s, f, (tr.size, 3), "(L, 3)", f"with L={tr.size} from /reference/time_s")
                c.no_inf(vr, f)
                c.within(vr, f, -MAX_SPEED_M_S, MAX_SPEED_M_S, f"velocity components within +-{MAX_SPEED_M_S:g} m/s or NaN")
            if r.window_s is not None:
                f = "/reference/window_s"
                w = c.shape(r.window_s, f, (tr.size, 2), "(L, 2)", f"with L={tr.size} from /reference/time_s")
                c.finite(w, f)
                if w.size and np.isfinite(w).all():
                    tol_w = time_tolerance_s(tr)
                    ordered = w[:, 1] > w[:, 0]
                    inside = (tr >= w[:, 0] - tol_w) & (tr <= w[:, 1] + tol_w)
                    if not ordered.all():
                        c.fail(f, "expected each window's end after its start (an averaging interval; leave the dataset "
                                  "out for instantaneous samples), got " + quoted(w[~ordered][0].tolist()))
                    elif not inside.all():
                        c.fail(f, f"expected every sample's time inside its window, got time {tr[~inside][0]:.6g} s outside")
            tol = max(time_tolerance_s(tr), time_tolerance_s(t))
            if not ((tr >= t[0] - tol) & (tr <= t[-1] + tol)).any():
                c.fail("/reference/time_s", f"expected a record overlapping the pings (within {tol:.3g} s), got "
                                            f"[{tr[0]:.6g}, {tr[-1]:.6g}] s for pings at [{t[0]:.6g}, {t[-1]:.6g}] s")

    # /truth
    if case.truth is not None:
        tt = case.truth
        c.instance(tt, Truth, "/truth")
        f = "/truth/radius_vectors_m"
        rv = c.shape(tt.radius_vectors_m, f, (4, 3))
        c.finite(rv, f)
        c.within(rv, f, -MAX_LEVER_ARM_M, MAX_LEVER_ARM_M, f"metres within +-{MAX_LEVER_ARM_M:g} of G")
        f = "/truth/installation_ypr_rad"
        ypr = c.shape(tt.installation_ypr_rad, f, (3,))
        c.finite(ypr, f)
        c.max_abs(ypr, f, math.pi, "|angle| <= pi")
        f = "/truth/vessel_velocity_m_s"
        vt = c.shape(tt.vessel_velocity_m_s, f, (n, 3), "(N, 3)", n_from)
        c.finite(vt, f)
        c.within(vt, f, -MAX_SPEED_M_S, MAX_SPEED_M_S, f"velocity components within +-{MAX_SPEED_M_S:g} m/s")
        if tt.water_velocity_m_s is not None:
            f = "/truth/water_velocity_m_s"
            wv = c.array(tt.water_velocity_m_s, f)
            if k is not None:
                c.shape(wv, f, (n, k, 3), "(N, K, 3)",
                        f"with N={n} from /pings/time_s and K={k} from /water/cell_depth_m")
            elif wv.ndim != 3 or wv.shape[0] != n or wv.shape[2] != 3:
                c.fail(f, f"expected shape (N, K, 3) {n_from}, got {wv.shape}")
            c.no_inf(wv, f)
            c.within(wv, f, -MAX_SPEED_M_S, MAX_SPEED_M_S, f"velocity components within +-{MAX_SPEED_M_S:g} m/s or NaN")
        f = attr_name("/truth", "effects")
        if not isinstance(tt.effects, list):
            c.fail(f, f"expected a JSON list, got {type(tt.effects).__name__}")
        for i, e in enumerate(tt.effects):
            if not (isinstance(e, dict) and isinstance(e.get("name"), str)
                    and isinstance(e.get("params", {}), dict)):
                c.fail(f, f'expected items {{"name": str, "params": {{...}}}}, '
                          f"got item {i}: {json.dumps(e, default=repr)}")
        try:
            json.dumps(tt.effects)
        except (TypeError, ValueError) as exc:
            c.fail(f, f"expected JSON-serialisable effects, got {exc}")
        if not isinstance(tt.extra_attrs, dict):
            c.fail("/truth", f"expected extra_attrs as a dict, got {type(tt.extra_attrs).__name__}")
        for key, val in tt.extra_attrs.items():
            if not isinstance(key, str) or key == "effects" or not key:
                c.fail("/truth", f"expected extra attribute names other than "
                                 f'"effects", got {key!r}')
            c.string(val, attr_name("/truth", key))
    _validate_site(case, c, n)


def _validate_site(case: Case, c: Checker, n: int) -> None:
    """Where and when (optional): ``/position``, ``/.attrs["time_origin_utc"]`` and the
    per-ping bed velocity ``/truth/moving_bed_velocity_m_s``."""
    if case.time_origin_utc is not None:
        f = attr_name("/", "time_origin_utc")
        text = c.string(case.time_origin_utc, f)
        try:
            parse_utc(text)
        except ValueError:
            c.fail(f, f'expected an ISO 8601 UTC time such as "2022-08-19T20:14:21Z", got {quoted(text)}')
    if case.position is not None:
        pos = case.position
        c.instance(pos, Position, "/position")
        tp = c.times(pos.time_s, "/position/time_s", "P")
        p_from = f"with P={tp.size} from /position/time_s"
        for name, limit in (("latitude_deg", 90.0), ("longitude_deg", 180.0)):
            f = f"/position/{name}"
            x = c.shape(getattr(pos, name), f, (tp.size,), "(P,)", p_from)
            c.finite(x, f)
            bad = np.abs(x) > limit
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                c.fail(f, f"expected degrees with |{name[:-4]}| <= {limit:g}, got {number_text(x[i])} at index {i}")
    if case.truth is not None and case.truth.moving_bed_velocity_m_s is not None:
        f = "/truth/moving_bed_velocity_m_s"
        c.finite(c.shape(case.truth.moving_bed_velocity_m_s, f, (n, 3), "(N, 3)",
                         f"with N={n} from /pings/time_s"), f)


def case_warnings(case: Case) -> list[str]:
    """What is unusual in a valid case but not impossible: one line each, naming the field.

    The verbs print them (``warning: ...``) and keep them in their outputs; what the
    attitude record does not cover is said by :func:`adcpdyn.cases.coverage.restrict_to_coverage`.
    """
    out = []
    ins, env, p, a = case.instrument, case.environment, case.pings, case.attitude
    g = "/instrument"
    c = float(ins.sound_speed_m_s)
    lo, hi = SOUND_SPEED_USUAL_M_S
    if not lo <= c <= hi:
        out.append(f"{attr_name(g, 'sound_speed_m_s')}: {c:g} m/s is outside the usual {lo:g}-{hi:g} m/s of water "
                   "(radial velocities were converted with it)")
    off_axis = np.degrees(np.arccos(np.clip(ins.beam_directions()[:, 2], -1.0, 1.0)))
    lo, hi = np.degrees(BEAM_ANGLE_USUAL_RAD)
    if ((off_axis < lo) | (off_axis > hi)).any():
        out.append(f"{attr_name(g, 'beam_angle_rad') if ins.beam_dirs_t is None else '/instrument/beam_dirs_t'}: beams "
                   f"{np.round(off_axis, 2).tolist()} deg from z_t, outside the usual {lo:g}-{hi:g} deg")
    if ins.beam_dirs_t is not None and np.max(np.abs(off_axis - math.degrees(ins.beam_angle_rad))) > 1.0:
        out.append(f"{attr_name(g, 'beam_angle_rad')}: {math.degrees(ins.beam_angle_rad):.4g} deg disagrees with "
                   f"/instrument/beam_dirs_t ({np.round(off_axis, 2).tolist()} deg); the vectors are used")
    if not 1e4 <= float(ins.frequency_hz) <= 1e7:
        out.append(f"{attr_name(g, 'frequency_hz')}: {float(ins.frequency_hz):g} Hz is outside the 10 kHz-10 MHz of ADCPs")
    if env.water_depth_per_ping_m is not None:
        missing = int(np.isnan(env.water_depth_per_ping_m).sum())
        if missing:
            out.append(f"/environment/water_depth_m: {missing} of {p.n} per-ping bed depths are NaN; "
                       f"the attribute's {env.water_depth_m:g} m is used there")
    beds = env.depth_at_pings(p.n)
    if p.bt_range_m is not None and np.isfinite(p.bt_range_m).any():
        expected = (beds[:, None] - env.transducer_depth_m) / ins.beam_directions()[None, :, 2]
        ratio = float(np.nanmedian(p.bt_range_m / expected))
        if not 0.5 <= ratio <= 2.0:
            out.append(f"/pings/bt_range_m: slant ranges are {ratio:.3g} x what the bed depth and beam angle give "
                       "(median); vertical ranges, or the wrong bed depth?")
    if case.water is not None:
        below = case.water.cell_depth_m[None, :] >= beds[:, None]
        if below.any():
            out.append(f"/water/cell_depth_m: {int(below.any(axis=0).sum())} cells lie below the bed at "
                       f"{int(below.any(axis=1).sum())} of {p.n} pings (their radials there are no water)")
    missing = ~a.complete()
    if missing.any():
        out.append(f"/attitude: {int(missing.sum())} of {missing.size} samples have a NaN angle (missing)")
    ref = case.reference
    if ref is not None and ref.time_s is not None and ref.velocity_m_s is not None:
        for j, axis in enumerate(("north", "east", "down")):
            if np.isnan(ref.velocity_m_s[:, j]).all():
                out.append(f"/reference/velocity_m_s: the {axis} component is NaN throughout (the reference gives none)")
        tol = max(time_tolerance_s(ref.time_s), time_tolerance_s(p.time_s))
        covered = (p.time_s >= ref.time_s[0] - tol) & (p.time_s <= ref.time_s[-1] + tol)
        if covered.mean() < 0.9:
            out.append(f"/reference/time_s: the reference record covers {covered.mean():.0%} of the pings")
    return out
