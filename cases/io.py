"""Read, validate and write case files (``docs/case-format.md``, version 1).

Every problem with a file is reported as a :class:`CaseFormatError` whose message is
one line: ``<file>: <HDF5 path>: expected ..., got ...``. Attributes are named as
``/group.attrs["name"]`` (the root group as ``/.attrs["name"]``).
"""

from __future__ import annotations

import json
import math
import contextlib
import os
import re

import h5py
import numpy as np

from .atomic import atomic_path
from .case import (
    ATTITUDE_FRAMES,
    FORMAT_NAME,
    FORMAT_VERSION,
    Attitude,
    Case,
    Environment,
    Instrument,
    Pings,
    Position,
    Reference,
    Truth,
    Vessel,
    Water,
    parse_utc,
)

__all__ = ["CaseFormatError", "read_case", "write_case", "validate_case", "case_warnings", "time_tolerance_s"]

_VESSEL_FIELDS = (
    "length_m",
    "beam_m",
    "height_m",
    "mass_kg",
    "draft_m",
    "displaced_volume_m3",
)
_SOUND_SPEED_INPUTS = ("temperature_c", "salinity_psu")  # optional /instrument attributes (not in the format: ignored if unreadable)
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


class CaseFormatError(ValueError):
    """A case file (or in-memory case) does not follow the case format.

    The message is a single line naming the file, the offending field and what was
    expected versus found.
    """


def _one_line(text: str) -> str:
    return re.sub(r"\s*[\r\n]+\s*", " ", text)


def _num(x) -> str:
    """Shortest exact text of a number (``repr`` of the float)."""
    return repr(float(x))


def _q(x) -> str:
    """A value for a message: strings in double quotes, numpy scalars as plain numbers."""
    if isinstance(x, str):
        return json.dumps(x)
    if isinstance(x, np.generic):
        return repr(x.item())
    return repr(x)


def _attr(group_name: str, name: str) -> str:
    return f'{group_name}.attrs["{name}"]'


# ----------------------------------------------------------------------------------
# validation of an in-memory case
# ----------------------------------------------------------------------------------


class _Checker:
    def __init__(self, source: str):
        self.source = source

    def fail(self, field: str, msg: str):
        raise CaseFormatError(_one_line(f"{self.source}: {field}: {msg}"))

    def array(self, x, field: str) -> np.ndarray:
        try:
            a = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError):
            self.fail(field, f"expected a numeric array, got {type(x).__name__}")
        return a

    def shape(self, x, field: str, expected: tuple, spec: str | None = None,
              origin: str = "") -> np.ndarray:
        a = self.array(x, field)
        if a.shape != tuple(expected):
            spec = spec or str(tuple(expected))
            where = f" {origin}" if origin else ""
            self.fail(field, f"expected shape {spec}{where}, got {a.shape}")
        return a

    @staticmethod
    def _index(a: np.ndarray, mask: np.ndarray) -> str:
        idx = np.argwhere(mask)[0]
        return str(int(idx[0])) if a.ndim == 1 else str(tuple(int(i) for i in idx))

    def finite(self, a: np.ndarray, field: str, what: str = "values") -> None:
        bad = ~np.isfinite(a)
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected finite {what}, got {a[bad][0]} at index {i}")

    def no_inf(self, a: np.ndarray, field: str) -> None:
        bad = np.isinf(a)
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected finite values or NaN, got {a[bad][0]} at index {i}")

    def times(self, x, field: str, letter: str) -> np.ndarray:
        a = self.array(x, field)
        if a.ndim != 1:
            self.fail(field, f"expected shape ({letter},), got {a.shape}")
        if a.size == 0:
            self.fail(field, f"expected at least one sample ({letter} >= 1), got 0")
        self.finite(a, field, "times")
        bad = np.flatnonzero(~(np.diff(a) > 0))
        if bad.size:
            i = int(bad[0]) + 1
            self.fail(field, f"expected strictly increasing times, got {_num(a[i])} at "
                             f"index {i} after {_num(a[i - 1])} at index {i - 1}")
        return a

    def scalar(self, x, field: str) -> float:
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.number)):
            self.fail(field, f"expected a number, got {_q(x)}")
        return float(x)

    def positive(self, x, field: str) -> float:
        v = self.scalar(x, field)
        if not (math.isfinite(v) and v > 0):
            self.fail(field, f"expected a finite value > 0, got {_num(v)}")
        return v

    def non_negative(self, x, field: str) -> float:
        v = self.scalar(x, field)
        if not (math.isfinite(v) and v >= 0):
            self.fail(field, f"expected a finite value >= 0, got {_num(v)}")
        return v

    def max_abs(self, a: np.ndarray, field: str, limit: float, what: str) -> None:
        bad = np.abs(a) > limit
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected radians with {what}, got {_num(a[bad][0])} "
                             f"at index {i} (degrees?)")

    def within(self, a: np.ndarray, field: str, low: float, high: float, what: str) -> None:
        """Every finite value within [low, high]; NaN passes (missing)."""
        bad = np.isfinite(a) & ((a < low) | (a > high))
        if bad.any():
            i = self._index(a, bad)
            self.fail(field, f"expected {what}, got {_num(a[bad][0])} at index {i}")

    def string(self, x, field: str) -> str:
        if not isinstance(x, str):
            self.fail(field, f"expected a string, got {_q(x)}")
        return x

    def instance(self, x, cls, field: str) -> None:
        if not isinstance(x, cls):
            self.fail(field, f"expected {cls.__name__}, got {type(x).__name__}")


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
    c = _Checker(source)
    c.instance(case, Case, "/")
    c.string(case.name, _attr("/", "name"))
    c.string(case.description, _attr("/", "description"))

    # /instrument
    ins = case.instrument
    c.instance(ins, Instrument, "/instrument")
    g = "/instrument"
    alpha = c.scalar(ins.beam_angle_rad, _attr(g, "beam_angle_rad"))
    lo, hi = BEAM_ANGLE_RANGE_RAD
    if not (lo <= alpha <= hi):
        c.fail(_attr(g, "beam_angle_rad"),
               f"expected radians in [{lo:.4f}, {hi:.4f}] ({math.degrees(lo):g}-{math.degrees(hi):g} deg), "
               f"got {_num(alpha)}" + (" (degrees?)" if alpha > math.pi / 2 else ""))
    tr = c.non_negative(ins.transducer_radius_m, _attr(g, "transducer_radius_m"))
    if tr > MAX_TRANSDUCER_RADIUS_M:
        c.fail(_attr(g, "transducer_radius_m"), f"expected metres <= {MAX_TRANSDUCER_RADIUS_M:g}, got {_num(tr)}")
    f0 = c.positive(ins.frequency_hz, _attr(g, "frequency_hz"))
    if not FREQUENCY_RANGE_HZ[0] <= f0 <= FREQUENCY_RANGE_HZ[1]:
        c.fail(_attr(g, "frequency_hz"), f"expected an acoustic frequency, {FREQUENCY_RANGE_HZ[0]:g}-"
                                         f"{FREQUENCY_RANGE_HZ[1]:g} Hz, got {_num(f0)}")
    sound = c.positive(ins.sound_speed_m_s, _attr(g, "sound_speed_m_s"))
    lo, hi = SOUND_SPEED_RANGE_M_S
    if not (lo <= sound <= hi):
        c.fail(_attr(g, "sound_speed_m_s"), f"expected a sound speed in water, {lo:g}-{hi:g} m/s, got {_num(sound)}")
    nb = ins.n_beams
    if isinstance(nb, (bool, np.bool_)) or not isinstance(nb, (int, np.integer)) or nb != 4:
        c.fail(_attr(g, "n_beams"), f"expected 4, got {_q(nb)}")
    if ins.layout != "janus4":
        c.fail(_attr(g, "layout"), f'expected "janus4", got {_q(ins.layout)}')
    if ins.beam_dirs_t is not None:
        f = "/instrument/beam_dirs_t"
        d = c.shape(ins.beam_dirs_t, f, (4, 3))
        c.finite(d, f)
        norms = np.linalg.norm(d, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_TOL)
        if bad.size:
            i = int(bad[0])
            c.fail(f, f"expected unit vectors (|d| = 1 within {_UNIT_TOL:g}), "
                      f"got |d| = {_num(norms[i])} for beam {i + 1}")
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
             f"speed; the sound speed is {_num(sound)} m/s) or NaN")
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
    bed = c.positive(env.water_depth_m, _attr(g, "water_depth_m"))
    if bed > MAX_DEPTH_M:
        c.fail(_attr(g, "water_depth_m"), f"expected metres <= {MAX_DEPTH_M:g} (the deepest ocean), got {_num(bed)}")
    td = c.non_negative(env.transducer_depth_m, _attr(g, "transducer_depth_m"))
    if not td < bed:
        c.fail(_attr(g, "transducer_depth_m"), f'expected a transducer above the bed (< /environment.attrs'
                                                f'["water_depth_m"] = {_num(bed)} m), got {_num(td)}')
    beds = np.array([bed])
    if env.water_depth_per_ping_m is not None:
        f = "/environment/water_depth_m"
        wd = c.shape(env.water_depth_per_ping_m, f, (n,), "(N,)", n_from)
        c.no_inf(wd, f)
        if (wd <= 0).any():
            i = int(np.flatnonzero(wd <= 0)[0])
            c.fail(f, f"expected water depths > 0, got {_num(wd[i])} at index {i}")
        c.within(wd, f, np.nextafter(td, np.inf), MAX_DEPTH_M,
                 f"bed depths below the transducer (> transducer_depth_m = {_num(td)} m) and <= {MAX_DEPTH_M:g} m, "
                 "or NaN (missing: the attribute applies)")
        beds = np.where(np.isfinite(wd), wd, bed)
    if ranges is not None and np.isfinite(ranges).any():
        c.within(ranges, "/pings/bt_range_m", 0.0, MAX_RANGE_OVER_DEPTH * float(beds.max()),
                 f"slant ranges <= {MAX_RANGE_OVER_DEPTH:g} x the deepest bed ({_num(beds.max())} m)")

    # /vessel
    c.instance(case.vessel, Vessel, "/vessel")
    for name in _VESSEL_FIELDS:
        v = getattr(case.vessel, name)
        if v is not None:
            v = c.positive(v, _attr("/vessel", name))
            if v > _VESSEL_MAX[name]:
                c.fail(_attr("/vessel", name), f"expected a value <= {_VESSEL_MAX[name]:g} (larger than any ship), "
                                               f"got {_num(v)}")

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
                 f"cell depths between the transducer ({_num(td)} m) and the deepest bed ({_num(beds.max())} m)")
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
        c.fail(_attr("/attitude", "frame"), f"expected one of {allowed}, got {_q(a.frame)}")

    # /reference
    if case.reference is not None:
        r = case.reference
        c.instance(r, Reference, "/reference")
        f = _attr("/reference", "point_body_m")
        point = c.shape(r.point_body_m, f, (3,))
        c.finite(point, f)
        c.within(point, f, -MAX_LEVER_ARM_M, MAX_LEVER_ARM_M, f"metres within +-{MAX_LEVER_ARM_M:g} of G")
        if not isinstance(r.stationary, (bool, np.bool_)):
            c.fail(_attr("/reference", "stationary"), f"expected 0 or 1, got {_q(r.stationary)}")
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
                                  "out for instantaneous samples), got " + _q(w[~ordered][0].tolist()))
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
        f = _attr("/truth", "effects")
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
            c.string(val, _attr("/truth", key))
    _validate_site(case, c, n)


def _validate_site(case: Case, c: _Checker, n: int) -> None:
    """Where and when (optional): ``/position``, ``/.attrs["time_origin_utc"]`` and the
    per-ping bed velocity ``/truth/moving_bed_velocity_m_s``."""
    if case.time_origin_utc is not None:
        f = _attr("/", "time_origin_utc")
        text = c.string(case.time_origin_utc, f)
        try:
            parse_utc(text)
        except ValueError:
            c.fail(f, f'expected an ISO 8601 UTC time such as "2022-08-19T20:14:21Z", got {_q(text)}')
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
                c.fail(f, f"expected degrees with |{name[:-4]}| <= {limit:g}, got {_num(x[i])} at index {i}")
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
        out.append(f"{_attr(g, 'sound_speed_m_s')}: {c:g} m/s is outside the usual {lo:g}-{hi:g} m/s of water "
                   "(radial velocities were converted with it)")
    off_axis = np.degrees(np.arccos(np.clip(ins.beam_directions()[:, 2], -1.0, 1.0)))
    lo, hi = np.degrees(BEAM_ANGLE_USUAL_RAD)
    if ((off_axis < lo) | (off_axis > hi)).any():
        out.append(f"{_attr(g, 'beam_angle_rad') if ins.beam_dirs_t is None else '/instrument/beam_dirs_t'}: beams "
                   f"{np.round(off_axis, 2).tolist()} deg from z_t, outside the usual {lo:g}-{hi:g} deg")
    if ins.beam_dirs_t is not None and np.max(np.abs(off_axis - math.degrees(ins.beam_angle_rad))) > 1.0:
        out.append(f"{_attr(g, 'beam_angle_rad')}: {math.degrees(ins.beam_angle_rad):.4g} deg disagrees with "
                   f"/instrument/beam_dirs_t ({np.round(off_axis, 2).tolist()} deg); the vectors are used")
    if not 1e4 <= float(ins.frequency_hz) <= 1e7:
        out.append(f"{_attr(g, 'frequency_hz')}: {float(ins.frequency_hz):g} Hz is outside the 10 kHz-10 MHz of ADCPs")
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


# ----------------------------------------------------------------------------------
# reading
# ----------------------------------------------------------------------------------


class _Reader:
    def __init__(self, source: str):
        self.c = _Checker(source)

    def _member(self, parent: h5py.Group, name: str, kind: type, required: bool):
        path = f"{parent.name.rstrip('/')}/{name}"
        obj = parent.get(name)
        word, other = ("group", "dataset") if kind is h5py.Group else ("dataset", "group")
        if obj is None:
            if required:
                self.c.fail(path, f"expected a required {word}, got none (missing)")
            return None, path
        if not isinstance(obj, kind):
            self.c.fail(path, f"expected a {word}, got a {other}")
        return obj, path

    def group(self, parent: h5py.Group, name: str, required: bool = True):
        return self._member(parent, name, h5py.Group, required)[0]

    def dataset(self, grp: h5py.Group, name: str, required: bool = True):
        obj, path = self._member(grp, name, h5py.Dataset, required)
        if obj is None:
            return None
        if obj.dtype.kind not in "iuf":
            self.c.fail(path, f"expected a numeric dataset, got dtype {obj.dtype}")
        return np.array(obj[()], dtype=np.float64)

    def _raw_attr(self, grp: h5py.Group, name: str, required: bool):
        if name not in grp.attrs:
            if required:
                self.c.fail(_attr(grp.name, name),
                            "expected a required attribute, got none (missing)")
            return None
        try:
            return grp.attrs[name]
        except (OSError, TypeError) as exc:
            self.c.fail(_attr(grp.name, name), f"expected a readable attribute, got {exc}")

    def _numeric(self, grp, name, v) -> np.ndarray:
        a = np.asarray(v) if not isinstance(v, (str, bytes)) else None
        if a is None or a.dtype.kind not in "iufb":
            shown = _text(v)
            self.c.fail(_attr(grp.name, name),
                        f"expected a number, got {_q(v if shown is None else shown)}")
        return a

    def scalar(self, grp, name, required=True, default=None):
        v = self._raw_attr(grp, name, required)
        if v is None:
            return default
        a = self._numeric(grp, name, v)
        if a.size != 1:
            self.c.fail(_attr(grp.name, name), f"expected a scalar, got shape {a.shape}")
        return a.reshape(())[()]

    def float_attr(self, grp, name, required=True, default=None):
        v = self.scalar(grp, name, required, default)
        return None if v is None else float(v)

    def int_attr(self, grp, name, required=True, default=None):
        v = self.scalar(grp, name, required, default)
        if v is None:
            return None
        if not float(v).is_integer():
            self.c.fail(_attr(grp.name, name), f"expected an integer, got {_num(v)}")
        return int(v)

    def vector_attr(self, grp, name, required=True, default=None):
        v = self._raw_attr(grp, name, required)
        if v is None:
            return default
        return np.array(self._numeric(grp, name, v), dtype=np.float64)

    def str_attr(self, grp, name, required=True, default=None):
        v = self._raw_attr(grp, name, required)
        if v is None:
            return default
        s = _text(v)
        if s is None:
            self.c.fail(_attr(grp.name, name), f"expected a string, got {_q(v)}")
        return s


def _optional_number(v) -> float | None:
    """An attribute the format does not define, read where it is one finite number, else None (ignored)."""
    try:
        x = np.asarray(v, dtype=float).ravel()
    except (TypeError, ValueError):
        return None
    return float(x[0]) if x.size == 1 and np.isfinite(x[0]) else None


def _identity_text(v) -> str:
    """An identity attribute (make, model, serial number) as text, a numeric serial included; "" when absent."""
    if v is None:
        return ""
    text = _text(v)
    if text is None:
        v = np.asarray(v).ravel()
        text = str(v[0].item()) if v.size == 1 else ""
    return text.strip()


def _text(v) -> str | None:
    """A str from a str/bytes attribute value (possibly a 1-element array), else None."""
    if isinstance(v, np.ndarray) and v.size == 1:
        v = v.reshape(())[()]
    if isinstance(v, bytes):
        try:
            return v.decode("utf-8")
        except UnicodeDecodeError:
            return v.decode("latin-1")
    if isinstance(v, str):
        return str(v)
    return None


def _attr_as_text(v) -> str:
    s = _text(v)
    if s is not None:
        return s
    try:
        return json.dumps(np.asarray(v).tolist())
    except (TypeError, ValueError):
        return str(v)


def _read(f: h5py.File, rd: _Reader) -> Case:
    root = f["/"]
    fmt = rd.str_attr(root, "format")
    if fmt != FORMAT_NAME:
        rd.c.fail(_attr("/", "format"), f'expected "{FORMAT_NAME}", got {_q(fmt)}')
    version = rd.scalar(root, "version")
    if isinstance(version, (bool, np.bool_)) or version != FORMAT_VERSION:
        rd.c.fail(_attr("/", "version"), f"expected {FORMAT_VERSION}, got {_q(version)}")
    # A missing name is the only omission we forgive: the file's stem serves.
    name = rd.str_attr(root, "name", required=False, default=None) or os.path.splitext(os.path.basename(f.filename))[0]
    description = rd.str_attr(root, "description", required=False, default="")

    g = rd.group(root, "instrument")
    instrument = Instrument(
        beam_angle_rad=rd.float_attr(g, "beam_angle_rad"),
        transducer_radius_m=rd.float_attr(g, "transducer_radius_m"),
        frequency_hz=rd.float_attr(g, "frequency_hz"),
        sound_speed_m_s=rd.float_attr(g, "sound_speed_m_s"),
        n_beams=rd.int_attr(g, "n_beams"),
        layout=rd.str_attr(g, "layout"),
        beam_dirs_t=rd.dataset(g, "beam_dirs_t", required=False),
        beam_pos_t=rd.dataset(g, "beam_pos_t", required=False),
        **{k: _identity_text(rd._raw_attr(g, k, False)) for k in ("make", "model", "serial_number")},
        **{k: _optional_number(rd._raw_attr(g, k, False)) for k in _SOUND_SPEED_INPUTS},
    )

    g = rd.group(root, "environment")
    environment = Environment(
        water_depth_m=rd.float_attr(g, "water_depth_m"),
        transducer_depth_m=rd.float_attr(g, "transducer_depth_m"),
        water_depth_per_ping_m=rd.dataset(g, "water_depth_m", required=False),
    )

    g = rd.group(root, "vessel", required=False)
    vessel = Vessel() if g is None else Vessel(
        **{k: rd.float_attr(g, k, required=False) for k in _VESSEL_FIELDS})

    g = rd.group(root, "pings")
    pings = Pings(
        time_s=rd.dataset(g, "time_s"),
        bt_radial_m_s=rd.dataset(g, "bt_radial_m_s"),
        bt_range_m=rd.dataset(g, "bt_range_m", required=False),
    )

    g = rd.group(root, "water", required=False)
    water = None if g is None else Water(
        cell_depth_m=rd.dataset(g, "cell_depth_m"),
        radial_m_s=rd.dataset(g, "radial_m_s"),
    )

    g = rd.group(root, "attitude")
    attitude = Attitude(
        time_s=rd.dataset(g, "time_s"),
        heading_rad=rd.dataset(g, "heading_rad"),
        pitch_rad=rd.dataset(g, "pitch_rad"),
        roll_rad=rd.dataset(g, "roll_rad"),
        frame=rd.str_attr(g, "frame"),
    )

    reference = None
    g = rd.group(root, "reference", required=False)
    if g is not None:
        stationary = rd.int_attr(g, "stationary", required=False, default=0)
        if stationary not in (0, 1):
            rd.c.fail(_attr(g.name, "stationary"), f"expected 0 or 1, got {stationary}")
        reference = Reference(
            time_s=rd.dataset(g, "time_s", required=False),
            velocity_m_s=rd.dataset(g, "velocity_m_s", required=False),
            point_body_m=rd.vector_attr(g, "point_body_m", required=False,
                                        default=np.zeros(3)),
            stationary=bool(stationary),
            window_s=rd.dataset(g, "window_s", required=False),
        )

    truth = None
    g = rd.group(root, "truth", required=False)
    if g is not None:
        text = rd.str_attr(g, "effects", required=False, default="[]")
        try:
            effects = json.loads(text)
        except json.JSONDecodeError as exc:
            rd.c.fail(_attr(g.name, "effects"), f"expected a JSON list, got invalid JSON ({exc})")
        if not isinstance(effects, list):
            rd.c.fail(_attr(g.name, "effects"),
                      f"expected a JSON list, got {type(effects).__name__}")
        extra = {}
        for key in g.attrs:
            if key == "effects":
                continue
            with contextlib.suppress(OSError, TypeError):
                extra[key] = _attr_as_text(g.attrs[key])
        truth = Truth(
            radius_vectors_m=rd.dataset(g, "radius_vectors_m"),
            installation_ypr_rad=rd.dataset(g, "installation_ypr_rad"),
            vessel_velocity_m_s=rd.dataset(g, "vessel_velocity_m_s"),
            water_velocity_m_s=rd.dataset(g, "water_velocity_m_s", required=False),
            moving_bed_velocity_m_s=rd.dataset(g, "moving_bed_velocity_m_s", required=False),
            effects=effects,
            extra_attrs=extra,
        )

    return Case(name=name, description=description, instrument=instrument,
                environment=environment, vessel=vessel, pings=pings, water=water,
                attitude=attitude, reference=reference, truth=truth, **_read_site(root, rd))


def _read_site(root: h5py.Group, rd: _Reader) -> dict:
    """``/position`` and ``/.attrs["time_origin_utc"]`` (both optional)."""
    g = rd.group(root, "position", required=False)
    position = None if g is None else Position(
        time_s=rd.dataset(g, "time_s"),
        latitude_deg=rd.dataset(g, "latitude_deg"),
        longitude_deg=rd.dataset(g, "longitude_deg"),
    )
    return {"position": position,
            "time_origin_utc": rd.str_attr(root, "time_origin_utc", required=False, default=None)}


def read_case(path) -> Case:
    """Read and validate a case file.

    Parameters
    ----------
    path : str or os.PathLike
        The HDF5 case file.

    Returns
    -------
    Case
        Arrays as float64; optional groups and datasets that are absent are ``None``
        (``/vessel`` absent gives ``Vessel()``). Unknown groups and attributes are
        ignored, except that unknown ``/truth`` attributes go to
        ``Truth.extra_attrs`` as strings.

    Raises
    ------
    CaseFormatError
        If the file is not HDF5 or does not follow the format (one-line message
        prefixed by the file name, naming the field).
    FileNotFoundError
        If the file does not exist.
    """
    source = os.fspath(path)
    rd = _Reader(source)
    if not os.path.exists(source):
        raise FileNotFoundError(f"{source}: no such file")
    if os.path.isdir(source):
        rd.c.fail("/", "expected an HDF5 file, got a folder")
    kind = _other_file_kind(source)
    if kind:
        rd.c.fail("/", f"expected an adcpdyn case (HDF5, format adcp-case), got {kind}")
    try:
        f = h5py.File(source, "r")
    except FileNotFoundError:
        raise FileNotFoundError(f"{source}: no such file") from None
    except OSError as exc:
        rd.c.fail("/", f"expected an HDF5 file, got an unreadable file ({exc})")
    with f:
        if "format" not in f["/"].attrs and ("_NCProperties" in f["/"].attrs or "Conventions" in f["/"].attrs):
            rd.c.fail("/", "expected an adcpdyn case (HDF5, format adcp-case), got a netCDF file (an export: "
                           "`adcpdyn export` writes these from a case; give the case itself)")
        case = _read(f, rd)
    validate_case(case, source=source)
    return case


def _other_file_kind(source: str) -> str | None:
    """What a file that is not HDF5 evidently is (a CALIB.json, an instrument file), from its first bytes."""
    with open(source, "rb") as fh:
        head = fh.read(64)
    if head.startswith(b"\x89HDF"):
        return None
    text = head.lstrip()
    if text.startswith(b"{"):
        return "a JSON file (a CALIB.json or DIAG.json? `adcpdyn calibrate` writes them; cases are .h5)"
    if head[:2] == b"\x7f\x7f":
        return "a TRDI PD0 file (run `adcpdyn import` on it first)"
    return None


# ----------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------


def _ds(grp: h5py.Group, name: str, data) -> None:
    if data is not None:
        grp.create_dataset(name, data=np.asarray(data, dtype=np.float64))


def _write(f: h5py.File, case: Case) -> None:
    f.attrs["format"] = FORMAT_NAME
    f.attrs["version"] = np.int64(FORMAT_VERSION)
    f.attrs["name"] = case.name
    f.attrs["description"] = case.description

    ins = case.instrument
    g = f.create_group("instrument")
    g.attrs["beam_angle_rad"] = np.float64(ins.beam_angle_rad)
    g.attrs["transducer_radius_m"] = np.float64(ins.transducer_radius_m)
    g.attrs["frequency_hz"] = np.float64(ins.frequency_hz)
    g.attrs["sound_speed_m_s"] = np.float64(ins.sound_speed_m_s)
    g.attrs["n_beams"] = np.int64(ins.n_beams)
    g.attrs["layout"] = str(ins.layout)
    for key in ("make", "model", "serial_number"):  # the instrument's identity (attributes the format lets producers add)
        if getattr(ins, key):
            g.attrs[key] = str(getattr(ins, key))
    for key in _SOUND_SPEED_INPUTS:  # what its sound speed was computed from, where known
        if getattr(ins, key) is not None:
            g.attrs[key] = np.float64(getattr(ins, key))
    _ds(g, "beam_dirs_t", ins.beam_dirs_t)
    _ds(g, "beam_pos_t", ins.beam_pos_t)

    env = case.environment
    g = f.create_group("environment")
    g.attrs["water_depth_m"] = np.float64(env.water_depth_m)
    g.attrs["transducer_depth_m"] = np.float64(env.transducer_depth_m)
    _ds(g, "water_depth_m", env.water_depth_per_ping_m)

    present = {k: getattr(case.vessel, k) for k in _VESSEL_FIELDS
               if getattr(case.vessel, k) is not None}
    if present:
        g = f.create_group("vessel")
        for k, v in present.items():
            g.attrs[k] = np.float64(v)

    g = f.create_group("pings")
    _ds(g, "time_s", case.pings.time_s)
    _ds(g, "bt_radial_m_s", case.pings.bt_radial_m_s)
    _ds(g, "bt_range_m", case.pings.bt_range_m)

    if case.water is not None:
        g = f.create_group("water")
        _ds(g, "cell_depth_m", case.water.cell_depth_m)
        _ds(g, "radial_m_s", case.water.radial_m_s)

    a = case.attitude
    g = f.create_group("attitude")
    for name in ("time_s", "heading_rad", "pitch_rad", "roll_rad"):
        _ds(g, name, getattr(a, name))
    g.attrs["frame"] = str(a.frame)

    if case.reference is not None:
        r = case.reference
        g = f.create_group("reference")
        _ds(g, "time_s", r.time_s)
        _ds(g, "velocity_m_s", r.velocity_m_s)
        _ds(g, "window_s", r.window_s)
        g.attrs["point_body_m"] = np.asarray(r.point_body_m, dtype=np.float64)
        g.attrs["stationary"] = np.int64(1 if r.stationary else 0)

    if case.truth is not None:
        t = case.truth
        g = f.create_group("truth")
        _ds(g, "radius_vectors_m", t.radius_vectors_m)
        _ds(g, "installation_ypr_rad", t.installation_ypr_rad)
        _ds(g, "vessel_velocity_m_s", t.vessel_velocity_m_s)
        _ds(g, "water_velocity_m_s", t.water_velocity_m_s)
        g.attrs["effects"] = json.dumps(t.effects)
        for k, v in t.extra_attrs.items():
            g.attrs[k] = str(v)
    _write_site(f, case)


def _write_site(f: h5py.File, case: Case) -> None:
    """``/position``, ``/.attrs["time_origin_utc"]``, ``/truth/moving_bed_velocity_m_s`` when present."""
    if case.time_origin_utc is not None:
        f.attrs["time_origin_utc"] = str(case.time_origin_utc)
    if case.position is not None:
        g = f.create_group("position")
        for name in ("time_s", "latitude_deg", "longitude_deg"):
            _ds(g, name, getattr(case.position, name))
    if case.truth is not None:
        _ds(f["truth"], "moving_bed_velocity_m_s", case.truth.moving_bed_velocity_m_s)


def write_case(case: Case, path) -> None:
    """Validate a case and write it atomically as a version-1 case file.

    The file is written to a temporary file in the destination directory, flushed
    to disk and moved onto ``path`` with :func:`os.replace`, so ``path`` is either
    left untouched or holds the complete new file.

    Parameters
    ----------
    case : Case
        The case to write.
    path : str or os.PathLike
        Destination file; replaced if it exists.

    Raises
    ------
    CaseFormatError
        If the case is invalid (nothing is written).
    OSError
        If the file cannot be written (no temporary file is left behind).
    """
    target = os.fspath(path)
    validate_case(case, source=target)
    with atomic_path(target) as tmp:
        with h5py.File(tmp, "w") as f:
            _write(f, case)
