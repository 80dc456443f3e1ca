"""Velocity metrics of the paper's Tables 8 and 12, plus what magnitudes cannot see.

Magnitudes and directions use the horizontal velocity (what the paper plots and
tabulates); the vector error uses all three components. Pings where either the
estimate or the reference is NaN are left out.
"""

from __future__ import annotations

import numpy as np

from ..models.rotations import course_difference_rad


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


METRIC_LABELS = {
    "mean_m_s": "Mean (m/s)",
    "sd_m_s": "SD (m/s)",
    "rsd_pct": "RSD (%)",
    "mae_m_s": "MAE (m/s)",
    "mre_pct": "MRE (%)",
    "error_sd_m_s": "Err SD (m/s)",
    "error_rsd_pct": "Err RSD (%)",
    "displacement_m": "Disp (m)",
    "distance_error_m": "Dist err (m)",
    "distance_re_pct": "Dist RE (%)",
    "vector_error_rms_m_s": "Vec err (m/s)",
    "direction_error_rms_deg": "Dir err (deg)",
}


def format_table(rows: dict[str, dict[str, float]]) -> str:
    """A plain-text table, one row per method."""
    keys = list(METRIC_LABELS)
    width = max(12, max(len(k) for k in rows) + 2)
    head = "".join(f"{'method':<{width}}") + "".join(f"{METRIC_LABELS[k]:>15}" for k in keys)
    lines = [head]
    for name, m in rows.items():
        lines.append(f"{name:<{width}}" + "".join(f"{m[k]:>15.4f}" for k in keys))
    return "\n".join(lines)
