"""Where the gap lies: per-channel residual statistics of a fit, ranked.

For every channel (each attitude axis, each beam's radial velocity and range, each
reference axis) the residuals are compared with the channel group's noise level:
chi-square per sample, whiteness (lag-1 autocorrelation and the Ljung-Box test), the
strongest Lomb-Scargle peak and whether it sits at a roll/pitch frequency or a
harmonic, correlation with physical regressors, and chi-square in time windows.
The score is the chi-square excess in standard deviations of its null distribution,
so channels of different sizes compare.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..attitude_fit import autocorrelation
from ..statistics.periodogram import lomb_scargle

N_WINDOWS = 6
LB_LAGS = 10


def _peak(t: np.ndarray, x: np.ndarray, lo: float, hi: float):
    """(angular frequency in rad/s, fraction of the variance) of the strongest Lomb-Scargle peak."""
    w = np.linspace(lo, hi, 600)
    p = lomb_scargle(t, x - x.mean(), w)
    k = int(np.argmax(p))
    return float(w[k]), float(2 * p[k] / max(len(x) * np.var(x), 1e-300))


def channel_report(name: str, t: np.ndarray, r: np.ndarray, sigma: float, regressors: dict,
                   mode_freqs: list[float]) -> dict:
    """Statistics of one channel's residuals ``r`` (finite samples only) at times ``t``."""
    n = r.size
    z = r / sigma
    chi2 = float(np.mean(z**2))
    score = (chi2 - 1.0) * np.sqrt(n / 2.0)
    out = {"channel": name, "n": int(n), "chi2_per_sample": chi2, "score": float(score),
           "rms": float(np.sqrt(np.mean(r**2))), "sigma": float(sigma), "mean_over_sigma": float(np.mean(z))}
    if n < 12:
        out["detail"] = f"chi2/n = {chi2:.2f} over {n} samples"
        return out
    order = np.argsort(t)
    t, r, z = t[order], r[order], z[order]
    lags = min(LB_LAGS, n // 4)
    rho = autocorrelation(r, lags)
    q = n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1)))
    out["lag1_autocorrelation"] = float(rho[0])
    out["ljung_box_p"] = float(stats.chi2.sf(q, lags))
    duration = t[-1] - t[0]
    lo, hi = max(4 * np.pi / max(duration, 1e-9), 0.05), min(np.pi / max(np.median(np.diff(t)), 1e-9), 20.0)
    if hi > lo:
        w, frac = _peak(t, r, lo, hi)
        out["peak_rad_s"], out["peak_variance_fraction"] = w, frac
        near = [f"{'mode' if k == 1 else f'{k}x mode'} {m / (2 * np.pi):.3g} Hz" for m in mode_freqs for k in (1, 2, 3)
                if abs(w - k * m) < 0.06 * k * m]
        out["peak_at"] = near[0] if near else None
    corr = {}
    for key, x in regressors.items():
        x = np.asarray(x, dtype=float)[order]
        if np.std(x) > 0 and np.std(r) > 0:
            corr[key] = float(np.corrcoef(x, r)[0, 1])
    out["correlation"] = corr
    edges = np.linspace(t[0], t[-1] + 1e-9, N_WINDOWS + 1)
    win = [float(np.mean(z[(t >= a) & (t < b)] ** 2)) if np.any((t >= a) & (t < b)) else float("nan")
           for a, b in zip(edges[:-1], edges[1:])]
    out["window_chi2"] = win
    out["windows_s"] = [[float(a), float(b)] for a, b in zip(edges[:-1], edges[1:])]
    out["detail"] = _words(out)
    return out


def _words(s: dict) -> str:
    parts = [f"chi2/n = {s['chi2_per_sample']:.2f}"]
    if abs(s["mean_over_sigma"]) > 3 / np.sqrt(s["n"]) and abs(s["mean_over_sigma"]) > 0.2:
        parts.append(f"offset {s['mean_over_sigma']:+.2f} sigma")
    if s.get("ljung_box_p", 1.0) < 1e-3:
        parts.append(f"not white (lag-1 r = {s['lag1_autocorrelation']:.2f})")
    if s.get("peak_variance_fraction", 0.0) > 0.1:
        at = f" = {s['peak_at']}" if s.get("peak_at") else ""
        f_hz = s["peak_rad_s"] / (2 * np.pi)  # in Hz and as a period, as the residual figure's frequency axis
        parts.append(f"peak at {f_hz:.3g} Hz (period {1 / f_hz:.3g} s){at} ({100 * s['peak_variance_fraction']:.0f}% "
                     "of variance)")
    strong = sorted(((abs(v), k, v) for k, v in s.get("correlation", {}).items() if abs(v) > 0.3), reverse=True)
    if strong:
        parts.append("correlates with " + ", ".join(f"{k} (r = {v:+.2f})" for _, k, v in strong[:2]))
    win = np.asarray(s.get("window_chi2", []), dtype=float)
    if win.size and np.nanmax(win) > 2.0 * max(np.nanmedian(win), 1e-12) and np.nanmax(win) > 2.0:
        k = int(np.nanargmax(win))
        a, b = s["windows_s"][k]
        parts.append(f"worst in {round(a) + 0:.0f}-{round(b) + 0:.0f} s (chi2/n = {win[k]:.1f})")
    return "; ".join(parts)


def rank(reports: list[dict]) -> list[dict]:
    """Channels by score, worst first, as ``{channel, score, detail}`` plus the statistics."""
    return sorted(reports, key=lambda d: -d["score"])
