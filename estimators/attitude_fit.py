"""Attitude-only fit of the sensor's angles: the starting point of every calibration.

Roll and pitch (of whatever frame the sensor sits in) are each a bias plus damped
modes (:mod:`adcpdyn.models.motion`), added greedily: the strongest Lomb-Scargle peak
of the current residual seeds a new mode (irregular sample times keep the true peak
above its aliases even below the mean Nyquist rate), (C, S) and the bias follow by
linear least squares over a small decay grid, then all of the axis' parameters are
refined by nonlinear least squares; a mode is kept when it lowers the Bayesian
information criterion by more than ``BIC_MARGIN``. Yaw is then linear in its
parameters (trend polynomial plus one coupling per roll and pitch mode), its trend
order chosen by BIC too. The two-stage baseline uses the same per-axis fit with
the paper's one mode per axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lombscargle

from ..cases.case import Case
from ..models.motion import AttitudeParams, mode_cs

BIC_MARGIN = 10.0
DECAY_GRID_1_S = (0.0, 0.03, 0.1, 0.3, 1.0)
MAX_DECAY_1_S = 3.0
MAX_OMEGA_RAD_S = 16.0
PERIODOGRAM_SAMPLES = 800


@dataclass(frozen=True)
class AxisFit:
    """One axis: bias, modes (n, 4) as (C, S, omega, decay), noise estimate and BIC trail."""

    bias: float
    modes: np.ndarray
    sigma: float
    rss: float
    bic_trail: list = field(default_factory=list)


@dataclass(frozen=True)
class AttitudeFit:
    params: AttitudeParams
    roll: AxisFit
    pitch: AxisFit
    heading_sigma: float
    yaw_trend_order: int

    @property
    def sigmas(self) -> np.ndarray:
        """Estimated noise (heading, pitch, roll) in rad."""
        return np.array([self.heading_sigma, self.pitch.sigma, self.roll.sigma])


def _axis_function(n_modes: int, n_samples: int, t_ref: float) -> ca.Function:
    """(t (1, n), q) -> (model (1, n), Jacobian (n, 1 + 4 k)) for one axis, per sample mapped."""
    t = ca.SX.sym("t")
    q = ca.SX.sym("q", 1 + 4 * n_modes)
    y = q[0]
    for k in range(n_modes):
        y = y + mode_cs(t, q[1 + 4 * k], q[2 + 4 * k], q[3 + 4 * k], q[4 + 4 * k], t_ref)
    one = ca.Function("axis1", [t, q], [y, ca.jacobian(y, q)])
    mapped = one.map(n_samples)
    tt = ca.MX.sym("t", 1, n_samples)
    qq = ca.MX.sym("q", 1 + 4 * n_modes)
    yy, jj = mapped(tt, qq)
    return ca.Function("axis", [tt, qq], [yy.T, jj.T if n_modes >= 0 else jj])


def _bic(rss: float, n: int, k: int) -> float:
    return n * np.log(max(rss, 1e-300) / n) + k * np.log(n)


def _linear_cs(t, resid, omega, decay, t_ref):
    """Best (C, S, bias shift) for a fixed frequency and decay, and the remaining RSS."""
    tau = t - t_ref
    e = np.exp(-decay * tau)
    A = np.column_stack([e * np.cos(omega * tau), e * np.sin(omega * tau), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(A, resid, rcond=None)
    return coef, float(np.sum((resid - A @ coef) ** 2))


def periodogram_peak(t, x, lo, hi, n_candidates=5) -> float:
    """Circular frequency of the highest Lomb-Scargle peak in [lo, hi].

    A grid at half the peak width (pi / duration) finds the candidate peaks, a fine
    grid around each of the highest few finds the maximum. Long series are thinned to
    ``PERIODOGRAM_SAMPLES`` evenly spread samples: the peak needs SNR, not every sample.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float) - np.mean(x)
    if t.size > PERIODOGRAM_SAMPLES:
        keep = np.unique(np.linspace(0, t.size - 1, PERIODOGRAM_SAMPLES).astype(int))
        t, x = t[keep], x[keep]
    width = 2 * np.pi / (t[-1] - t[0])
    coarse = np.arange(lo, hi, width / 2)
    power = lombscargle(t, x, coarse)
    best_omega, best_power = lo, -np.inf
    for i in np.argsort(power)[::-1][:n_candidates]:
        fine = np.linspace(max(lo, coarse[i] - width / 2), min(hi, coarse[i] + width / 2), 41)
        p = lombscargle(t, x, fine)
        if p.max() > best_power:
            best_omega, best_power = fine[int(np.argmax(p))], p.max()
    return float(best_omega)


def fit_axis(t, y, t_ref: float, max_modes: int = 3, fixed_modes: int | None = None,
             omega_band=None) -> AxisFit:
    """Bias plus damped modes for one angle series (radians).

    Parameters
    ----------
    t, y : (M,) arrays
    t_ref : float
        Reference time of the (C, S) mode form.
    max_modes : int
        Upper bound on the number of modes tried.
    fixed_modes : int, optional
        Fit exactly this many modes, no information criterion (the paper uses 1).
    omega_band : (float, float), optional
        Search band for the damped frequency in rad/s.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = t.size
    duration = t[-1] - t[0]
    lo, hi = omega_band or (max(2 * np.pi * 2 / duration, 0.2), MAX_OMEGA_RAD_S)
    q = np.array([np.mean(y)])
    rss = float(np.sum((y - q[0]) ** 2))
    trail = [{"modes": 0, "bic": _bic(rss, n, 1)}]
    target = fixed_modes if fixed_modes is not None else max_modes
    for k in range(1, target + 1):
        fun = _axis_function(k, n, t_ref)
        resid = y - np.asarray(_axis_function(k - 1, n, t_ref)(t[None, :], q)[0]).ravel()
        if np.ptp(resid) == 0:
            break
        omega = periodogram_peak(t, resid, lo, hi)
        best = min((_linear_cs(t, resid, omega, d, t_ref) + (d,) for d in DECAY_GRID_1_S), key=lambda r: r[1])
        (c, s, shift), _, decay = best
        q0 = np.concatenate([[q[0] + shift], q[1:], [c, s, omega, decay]])
        lower = np.concatenate([[-np.inf], np.tile([-np.inf, -np.inf, lo, 0.0], k)])
        upper = np.concatenate([[np.inf], np.tile([np.inf, np.inf, hi, MAX_DECAY_1_S], k)])
        q0 = np.clip(q0, lower + 1e-12, upper - 1e-12)
        sol = least_squares(
            lambda qq: np.asarray(fun(t[None, :], qq)[0]).ravel() - y,
            q0,
            jac=lambda qq: np.asarray(fun(t[None, :], qq)[1]).reshape(n, -1),
            bounds=(lower, upper),
            x_scale="jac",
        )
        rss_k = float(2 * sol.cost)
        bic_k = _bic(rss_k, n, 1 + 4 * k)
        trail.append({"modes": k, "bic": bic_k})
        if fixed_modes is None and bic_k > trail[-2]["bic"] - BIC_MARGIN:
            trail[-1]["rejected"] = True
            break
        q, rss = sol.x, rss_k
    n_modes = (q.size - 1) // 4
    sigma = float(np.sqrt(rss / max(n - q.size, 1)))
    return AxisFit(bias=float(q[0]), modes=q[1:].reshape(n_modes, 4), sigma=sigma, rss=rss, bic_trail=trail)


def fit_attitude(case: Case, max_modes: int = 3, fixed_modes: int | None = None, max_trend_order: int = 2,
                 t_ref: float | None = None) -> AttitudeFit:
    """Fit the sensor's roll, pitch and heading samples of a case (see module docstring)."""
    a = case.attitude
    t = a.time_s
    t_ref = float(case.pings.time_s[0]) if t_ref is None else float(t_ref)
    ypr = a.ypr()
    roll = fit_axis(t, ypr[:, 2], t_ref, max_modes, fixed_modes)
    pitch = fit_axis(t, ypr[:, 1], t_ref, max_modes, fixed_modes)

    # Yaw: trend polynomial plus the roll and pitch oscillations, each scaled (linear).
    osc = []
    for modes in (roll.modes, pitch.modes):
        for c, s, w, v in modes:
            tau = t - t_ref
            osc.append(np.exp(-v * tau) * (c * np.cos(w * tau) + s * np.sin(w * tau)))
    best = None
    for order in range(max_trend_order + 1):
        A = np.column_stack([(t - t_ref) ** k for k in range(order + 1)] + osc)
        coef, *_ = np.linalg.lstsq(A, ypr[:, 0], rcond=None)
        rss = float(np.sum((ypr[:, 0] - A @ coef) ** 2))
        bic = _bic(rss, t.size, A.shape[1])
        if best is None or bic < best[0] - BIC_MARGIN:
            best = (bic, order, coef, rss, A.shape[1])
    _, order, coef, rss, k = best
    params = AttitudeParams(
        roll_modes=roll.modes,
        roll_bias=roll.bias,
        pitch_modes=pitch.modes,
        pitch_bias=pitch.bias,
        yaw_trend=coef[: order + 1],
        yaw_coupling=coef[order + 1:],
        t_ref_s=t_ref,
    )
    return AttitudeFit(params, roll, pitch, float(np.sqrt(rss / max(t.size - k, 1))), order)
