"""Lomb-Scargle periodogram of one or more series sampled at the same irregular times.

The classic power (Scargle 1982; ``scipy.signal.lombscargle``'s default normalisation):
P(w) = 0.5 [ (sum y cos w(t - tau))^2 / sum cos^2 w(t - tau) + (sum y sin w(t - tau))^2 / sum sin^2 w(t - tau) ]
with tan 2 w tau = sum sin 2wt / sum cos 2wt. scipy (1.17) evaluates the cosine and sine of
every (time, frequency) pair twice per series; here exp(i w t) is evaluated once per pair and
shared by every column, and the tau shift is applied in closed form: with z = exp(i w t),
C + iS = sum y z, C2 + iS2 = sum z^2 and R = |C2 + iS2|, YC + iYS = (C + iS) exp(-i w tau),
sum cos^2 = (n + R) / 2 and sum sin^2 = (n - R) / 2. A 3000-ping transect's attitude pre-fit
spent 4.7 s in scipy's periodogram (9808 frequencies x 800 samples x 2 axes a scan).
"""

from __future__ import annotations

import numpy as np

FREQUENCY_BLOCK = 512  # frequencies a pass holds: (samples x block) complex values, a few MB


def lomb_scargle(t, y, omega) -> np.ndarray:
    """Lomb-Scargle power of ``y`` ((n,) or (n, k) columns, the mean not removed) at times ``t`` (n,)
    and angular frequencies ``omega`` (m,) in rad/s: (m,), or (m, k) for columns. Equal to
    ``scipy.signal.lombscargle(t, y[:, j], omega)`` (its default normalisation) to rounding."""
    t = np.asarray(t, dtype=float).ravel()
    y = np.asarray(y, dtype=float)
    columns = y.reshape(t.size, -1)
    omega = np.asarray(omega, dtype=float).ravel()
    n = t.size
    floor = np.finfo(float).epsneg * n  # scipy's guard on the normalised sums, in these units
    power = np.empty((omega.size, columns.shape[1]))
    for lo in range(0, omega.size, FREQUENCY_BLOCK):
        w = omega[lo:lo + FREQUENCY_BLOCK]
        z = np.exp(1j * np.outer(t, w))  # (n, b)
        double = np.einsum("ij,ij->j", z, z)  # sum exp(2i w t): C2 + i S2
        shifted = (columns.T @ z) * np.exp(-0.5j * np.angle(double))  # (k, b): YC + i YS
        r = np.abs(double)
        cc, ss = np.maximum(0.5 * (n + r), floor), np.maximum(0.5 * (n - r), floor)
        power[lo:lo + FREQUENCY_BLOCK] = (0.5 * (shifted.real**2 / cc + shifted.imag**2 / ss)).T
    return power[:, 0] if y.ndim == 1 else power
