"""What the attitude record covers: no verb extrapolates the attitude, model or samples.

Every verb that uses the attitude (``correct``, ``compare``, ``calibrate``, ``diagnose``,
one case or many) calls :func:`restrict_to_coverage` on the case it read, and works on
what it returns. The tolerance is stated once: a time within one median sample interval
of a record's ends counts as inside it (:func:`~adcpdyn.cases.validation.time_tolerance_s`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .case import Case
from .validation import time_tolerance_s, validate_case

__all__ = ["MAX_DROPPED_FRACTION", "restrict_to_coverage", "reference_at"]

MAX_DROPPED_FRACTION = 0.5  # more pings than this outside the attitude record: refused, not trimmed


def _span(t: np.ndarray, tol: float) -> str:
    return f"[{t[0]:.6g}, {t[-1]:.6g}] s (+- {tol:.3g} s)"


def restrict_to_coverage(case: Case, source: str | None = None,
                         max_dropped_fraction: float = MAX_DROPPED_FRACTION) -> tuple[Case, str | None]:
    """The case restricted to what its attitude record covers, and a one-line note of what was left out.

    1. Attitude samples with a NaN angle (missing) are left out; at least two complete
       samples must remain.
    2. Pings outside the record of the complete samples, [t_1 - tol, t_M + tol] with tol one
       median sample interval, are left out with every per-ping row (water profile,
       per-ping bed depth, truth). None left, or more than ``max_dropped_fraction`` of them
       outside: refused.
    3. Reference samples outside the attitude record (+- tol) or the kept pings' span (+- one
       median reference or ping interval, the larger) are left out; none left: refused. A
       reference with no finite horizontal velocity at all is left out entirely, and so are
       slant ranges that are all NaN (a channel without data is no channel).

    Parameters
    ----------
    case : Case
        A valid case (as :func:`~adcpdyn.cases.io.read_case` returns).
    source : str, optional
        Prefix of messages (the file name; default the case's name).
    max_dropped_fraction : float
        Largest share of the pings that may be left out.

    Returns
    -------
    (Case, str or None)
        The restricted case (the same object when nothing was left out) and a one-line note
        saying what was left out (None when nothing was).

    Raises
    ------
    ValueError
        One line, ``SOURCE: FIELD: expected ..., got ...``.
    """
    source = source or case.name
    a, p = case.attitude, case.pings
    notes = []

    complete = a.complete()
    if complete.sum() < 2:
        raise ValueError(f"{source}: /attitude: expected at least 2 samples with finite heading, pitch and roll (the "
                         f"attitude is interpolated or fitted between samples), got {int(complete.sum())}")
    if not complete.all():
        n_bad = int((~complete).sum())
        a = a.subset(complete)
        notes.append(f"{n_bad} of {complete.size} attitude samples with a NaN angle left out")
    ta = a.time_s
    tol = time_tolerance_s(ta)

    t = p.time_s
    keep = (t >= ta[0] - tol) & (t <= ta[-1] + tol)
    n_out = int((~keep).sum())
    if not keep.any():
        raise ValueError(f"{source}: /pings/time_s: expected pings inside the attitude record {_span(ta, tol)}, got "
                         f"none of {t.size} pings at [{t[0]:.6g}, {t[-1]:.6g}] s")
    if n_out > max_dropped_fraction * t.size:
        raise ValueError(f"{source}: /pings/time_s: expected at most {max_dropped_fraction:.0%} of the pings outside "
                         f"the attitude record {_span(ta, tol)} (the attitude is never extrapolated), got {n_out} of "
                         f"{t.size} at [{t[0]:.6g}, {t[-1]:.6g}] s")
    changes = {}
    if n_out:
        notes.append(f"{n_out} of {t.size} pings outside the attitude record {_span(ta, tol)} left out "
                     "(the attitude is never extrapolated)")
        kept = case.ping_subset(keep)
        changes.update(pings=kept.pings, environment=kept.environment, water=kept.water, truth=kept.truth)
        t = t[keep]
    if not complete.all():
        changes["attitude"] = a

    pings = changes.get("pings", p)
    if pings.bt_range_m is not None and not np.isfinite(pings.bt_range_m).any():
        notes.append("/pings/bt_range_m: no finite slant range; left out")
        changes["pings"] = dataclasses.replace(pings, bt_range_m=None)

    ref = case.reference
    if ref is not None and ref.time_s is not None and ref.velocity_m_s is not None:
        horizontal = np.isfinite(ref.velocity_m_s[:, :2]).all(axis=1)
        if not horizontal.any():
            notes.append("/reference: no sample with a finite horizontal velocity; the reference is left out")
            changes["reference"] = None
        else:
            tr_ = ref.time_s
            tol_r = max(time_tolerance_s(tr_), time_tolerance_s(p.time_s))
            inside = ((tr_ >= ta[0] - tol) & (tr_ <= ta[-1] + tol) & (tr_ >= t[0] - tol_r) & (tr_ <= t[-1] + tol_r))
            if not inside.any():
                raise ValueError(f"{source}: /reference/time_s: expected samples inside the attitude record "
                                 f"{_span(ta, tol)} and the pings' span {_span(t, tol_r)}, got none of {tr_.size} "
                                 f"at [{tr_[0]:.6g}, {tr_[-1]:.6g}] s")
            if not inside.all():
                n_ref = int((~inside).sum())
                notes.append(f"{n_ref} of {tr_.size} reference samples outside the pings' span and attitude record "
                             "left out")
                changes["reference"] = ref.subset(inside)

    if not changes:
        return case, None
    out = case.replace(**changes)
    validate_case(out, source=f"{source} (inside the attitude record)")
    return out, f"{source}: " + "; ".join(notes)


def reference_at(case: Case, times) -> np.ndarray | None:
    """The reference velocity at ``times``, (n, 3), interpolated linearly per component over its
    finite samples; NaN outside the reference record (+- one median interval: never
    extrapolated) and for a component with no finite sample. Zeros for a stationary
    reference, None without one."""
    times = np.asarray(times, dtype=float)
    ref = case.reference
    if ref is None:
        return None
    if ref.velocity_m_s is None or ref.time_s is None:
        return np.zeros((times.size, 3)) if ref.stationary else None
    out = np.full((times.size, 3), np.nan)
    tol = time_tolerance_s(ref.time_s)
    for j in range(3):
        ok = np.isfinite(ref.velocity_m_s[:, j])
        if not ok.any():
            continue
        tj, vj = ref.time_s[ok], ref.velocity_m_s[ok, j]
        inside = (times >= tj[0] - tol) & (times <= tj[-1] + tol)
        out[inside, j] = np.interp(times[inside], tj, vj)
    return out
