"""Velocity metrics of the paper's Tables 8 and 12, plus what magnitudes cannot see.

Magnitudes and directions use the horizontal velocity (what the paper plots and
tabulates); the vector error uses all three components. Pings where either the
estimate or the reference is NaN are left out.
"""

from __future__ import annotations

import numpy as np

from ...models.rotations import course_difference_rad


def _trapezoid_displacement(t, v):
    return np.trapezoid(v, t, axis=0)


def velocity_metrics(time_s, estimate_m_s, reference_m_s) -> dict[str, float]:
    """Mean, SD, RSD, MAE, MRE, error SD, error RSD of the horizontal speed; displacement
    magnitude, distance error and RE; RMS vector error and RMS direction error (deg).

    A reference component that is NaN throughout (a reference with no vertical, as video
    trackers and some GNSS give) is left out of the vector error; otherwise pings where a
    component is NaN are left out. Without any ping to compare, every metric is NaN.
    """
    t = np.asarray(time_s, dtype=float)
    est = np.asarray(estimate_m_s, dtype=float)
    ref = np.asarray(reference_m_s, dtype=float)
    if est.shape != ref.shape or est.ndim != 2 or est.shape[1] != 3:
        raise ValueError(f"estimate_m_s/reference_m_s: expected equal shapes (N, 3), got {est.shape} and {ref.shape}")
    axes = np.isfinite(ref).any(axis=0)
    axes[:2] = True
    est, ref = est[:, axes], ref[:, axes]
    ok = np.all(np.isfinite(est), axis=1) & np.all(np.isfinite(ref), axis=1)
    t, est, ref = t[ok], est[ok], ref[ok]
    if t.size == 0:
        return {"n_pings": 0, **{k: float("nan") for k in METRIC_LABELS}}
    s_est = np.hypot(est[:, 0], est[:, 1])
    s_ref = np.hypot(ref[:, 0], ref[:, 1])
    err = s_est - s_ref
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(err) / s_ref
    moving = s_ref > 1e-3
    dang = course_difference_rad(est, ref)
    d_est = np.linalg.norm(_trapezoid_displacement(t, est[:, :2]))
    d_ref = np.linalg.norm(_trapezoid_displacement(t, ref[:, :2]))
    return {
        "n_pings": int(ok.sum()),
        "mean_m_s": float(np.mean(s_est)),
        "sd_m_s": float(np.std(s_est)),
        "rsd_pct": float(100 * np.std(s_est) / np.mean(s_est)),
        "mae_m_s": float(np.mean(np.abs(err))),
        "mre_pct": float(100 * np.mean(rel[moving])) if moving.any() else float("nan"),
        "error_sd_m_s": float(np.std(err)),
        "error_rsd_pct": float(100 * np.std(err) / np.mean(s_ref)) if np.mean(s_ref) > 0 else float("nan"),
        "displacement_m": float(d_est),
        "distance_error_m": float(abs(d_est - d_ref)),
        "distance_re_pct": float(100 * abs(d_est - d_ref) / d_ref) if d_ref > 0 else float("nan"),
        "vector_error_rms_m_s": float(np.sqrt(np.mean(np.sum((est - ref) ** 2, axis=1)))),
        "direction_error_rms_deg": float(np.rad2deg(np.sqrt(np.mean(dang[moving] ** 2)))) if moving.any() else float("nan"),
    }


# The paper's metrics as the terminal shows them, (header, unit, decimals, scale from SI): velocities
# in mm/s (a pool boat's 8 mm/s and a ship's 5000 mm/s both legible with one decimal), distances in m
# (up to 3 decimals, 3 significant digits: 0.390 m, 1035 m), percentages with one decimal.
METRIC_COLUMNS = {
    "mean_m_s": ("Mean", "mm/s", 1, 1e3),
    "sd_m_s": ("SD", "mm/s", 1, 1e3),
    "rsd_pct": ("RSD", "%", 1, 1.0),
    "mae_m_s": ("MAE", "mm/s", 1, 1e3),
    "mre_pct": ("MRE", "%", 1, 1.0),
    "error_sd_m_s": ("ErrSD", "mm/s", 1, 1e3),
    "error_rsd_pct": ("ErrRSD", "%", 1, 1.0),
    "displacement_m": ("Disp", "m", 3, 1.0),  # in m: 3 decimals at most, 3 significant digits
    "distance_error_m": ("DistErr", "m", 3, 1.0),
    "distance_re_pct": ("DistRE", "%", 1, 1.0),
    "vector_error_rms_m_s": ("VecErr", "mm/s", 1, 1e3),
    "direction_error_rms_deg": ("DirErr", "deg", 1, 1.0),
}
METRIC_LABELS = {k: f"{head} ({unit})" for k, (head, unit, _, _) in METRIC_COLUMNS.items()}
METRIC_LEGEND = ("Speeds horizontal. R: relative (to the mean); MAE, MRE: mean absolute, relative error; "
                 "Err: speed error; Disp: displacement, Dist: its error; VecErr, DirErr: RMS vector, course error")


def format_table(rows: dict[str, dict[str, float]]) -> str:
    """A plain-text table, one row per method, at most :data:`~adcpdyn.text.TABLE_WIDTH`
    characters wide: a unit under every header and the abbreviations in words below."""
    from ...text import Column, text_table

    columns = [Column(k, head, unit, decimals, scale, significant=3 if unit == "m" else None)
               for k, (head, unit, decimals, scale) in METRIC_COLUMNS.items()]
    return text_table(rows, columns, first="method", legend=METRIC_LEGEND)
