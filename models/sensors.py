"""Sensor models: attitude sampled at a low irregular rate, reference velocity.

An attitude sensor aligned with the vessel reads the Euler angles of Lambda; one
inside the ADCP head reads those of Lambda Lambda_tb (``docs/notes-on-the-paper.md``
erratum 5). A reference (GNSS antenna, video target) at body point p moves with
V_a + dLambda/dt p (erratum 6).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .rotations import euler_matrix, matrix_euler

ATTITUDE_FRAMES = ("vessel", "transducer")


def sensed_attitude(Lam, installation_ypr, frame: str):
    """Euler angles (yaw, pitch, roll) the attitude sensor reads, as an expression."""
    if frame == "vessel":
        return matrix_euler(Lam)
    if frame == "transducer":
        Ltb = euler_matrix(installation_ypr[0], installation_ypr[1], installation_ypr[2])
        return matrix_euler(ca.mtimes(Lam, Ltb))
    raise ValueError(f"frame: expected one of {ATTITUDE_FRAMES}, got {frame!r}")


def reference_point_velocity(vessel_velocity, dLam, point_body_m):
    """Earth velocity of a body point: V_a + dLambda/dt p (Eq. 23 form)."""
    return vessel_velocity + ca.mtimes(dLam, ca.reshape(point_body_m, 3, 1))


def compass_correction(heading, misalignment, deviation_sin=0.0, deviation_cos=0.0, mean_sin=0.0, mean_cos=0.0):
    """Heading correction of a compass: true heading = sensor heading + this.

    misalignment + B (sin psi - mean_sin) + C (cos psi - mean_cos): a constant (declination not
    set, hard-iron offset, a head turned on its mount) plus the one-cycle deviation of the
    sensor heading psi, written about the mean (sin, cos) of the headings it was fitted on, so
    that the misalignment is the mean correction over them (what those headings determine).
    Works on numbers and on CasADi expressions.
    """
    sin, cos = (ca.sin, ca.cos) if isinstance(heading, (ca.SX, ca.MX)) else (np.sin, np.cos)
    return misalignment + deviation_sin * (sin(heading) - mean_sin) + deviation_cos * (cos(heading) - mean_cos)


def irregular_times(rng: np.random.Generator, t_start: float, t_end: float, interval_min_s: float, interval_max_s: float) -> np.ndarray:
    """Sample times with intervals drawn uniformly in [interval_min_s, interval_max_s]."""
    if not 0 < interval_min_s <= interval_max_s:
        raise ValueError(f"sample interval: expected 0 < min <= max, got [{interval_min_s}, {interval_max_s}]")
    n_max = int(np.ceil((t_end - t_start) / interval_min_s)) + 2
    steps = rng.uniform(interval_min_s, interval_max_s, n_max)
    t = t_start + np.concatenate([[0.0], np.cumsum(steps)])
    return t[t <= t_end]


def ar1_noise(white, rho: float) -> np.ndarray:
    """Unit-variance AR(1) noise along axis 0 from white N(0, 1) draws.

    e_0 = w_0, e_k = rho e_{k-1} + sqrt(1 - rho^2) w_k: stationary from the first sample,
    variance 1 and lag-1 autocorrelation rho (sample to sample, whatever the spacing).
    rho = 0 returns ``white`` itself (bit for bit).
    """
    white = np.asarray(white, dtype=float)
    if not -1.0 < rho < 1.0:
        raise ValueError(f"rho: expected a lag-1 autocorrelation in (-1, 1), got {rho!r}")
    if rho == 0.0 or white.shape[0] < 2:
        return white
    from scipy.signal import lfilter

    out = np.empty_like(white)
    out[0] = white[0]
    out[1:], _ = lfilter([np.sqrt(1.0 - rho**2)], [1.0, -rho], white[1:], axis=0, zi=(rho * white[0])[None, ...])
    return out


def quantise(x, step):
    """Round to the sensor's resolution (no-op for step <= 0)."""
    x = np.asarray(x, dtype=float)
    return np.round(x / step) * step if step > 0 else x


def wrap_heading(psi):
    """Compass heading in [0, 2 pi)."""
    return np.mod(psi, 2 * np.pi)
