"""Vessel attitude models: damped roll, pitch and coupled yaw (Section 2.3, Section 3.1).

Each axis is a constant bias plus a sum of damped modes. One mode is the paper's
free decay released at t0 with zero rate (Eq. 34 for roll; Eq. 41 for pitch is the
same curve, since theta_a cos(x - eps) = theta_0 (cos x + v/n sin x) by Eq. 42):

    a(t) = A exp(-v (t - t0)) [cos n1 (t - t0) + (v / n1) sin n1 (t - t0)]

with n1 the damped circular frequency (Eq. 35) and v the decay rate; v = 0 gives a
steady wave-forced oscillation. Internally a mode is written about a fixed reference
time t_ref as exp(-v (t - t_ref)) [C cos n1 (t - t_ref) + S sin n1 (t - t_ref)]: the
same family, but linear in (C, S), so no two parameter sets give the same curve
(the paper's (A, t0) repeats itself every period). :func:`paper_to_cs` and
:func:`cs_to_paper` convert exactly.

A mode is a physical oscillation of the vessel: one frequency and decay, seen by
every axis with its own (C, S) -- a sensor whose axes are turned (inside an ADCP
head turned 45 degrees, say) sees the roll mode in both its roll and its pitch.
Yaw is a slow polynomial trend plus the same modes, so it shares their frequencies
and decays (the paper fits yaw with the roll model's t0 and n1; a free yaw
frequency overfits heading noise).

The parameters of a model live in one flat vector laid out by
:class:`AttitudeLayout`; :func:`attitude_function` returns a CasADi Function of
(t, p) used symbolically by the estimators and numerically by the simulator.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .rotations import euler_matrix, euler_matrix_and_rate, skew, unskew

def damped_mode(t, amplitude, t0, omega, decay):
    """Free decay released at t0 with zero rate (Eqs. 34, 41-42)."""
    tau = t - t0
    return amplitude * ca.exp(-decay * tau) * (
        ca.cos(omega * tau) + decay / omega * ca.sin(omega * tau)
    )


def mode_cs(t, c, s, omega, decay, t_ref):
    """exp(-v (t - t_ref)) [C cos n1 (t - t_ref) + S sin n1 (t - t_ref)]: Eq. 34 about t_ref."""
    ec, es, _, _ = mode_basis(t - t_ref, omega, decay)
    return c * ec + s * es


def mode_basis(tau, omega, decay):
    """(exp(-v tau) cos n1 tau, exp(-v tau) sin n1 tau) of Eq. 34 and their time derivatives, the
    same pair turned: (-v ec - n1 es, -v es + n1 ec)."""
    e = ca.exp(-decay * tau)
    ec, es = e * ca.cos(omega * tau), e * ca.sin(omega * tau)
    return ec, es, -decay * ec - omega * es, -decay * es + omega * ec


def paper_to_cs(amplitude, t0, omega, decay, t_ref):
    """(A, t0) of Eq. 34 -> (C, S) about t_ref, exactly."""
    d = t_ref - t0
    g = amplitude * np.exp(-decay * d)
    k = decay / omega
    return g * (np.cos(omega * d) + k * np.sin(omega * d)), g * (-np.sin(omega * d) + k * np.cos(omega * d))


def cs_to_paper(c, s, omega, decay, t_ref):
    """(C, S) about t_ref -> the paper's (phi_0, t_0) with t_0 within half a period of t_ref."""
    eps = np.arctan2(decay, omega)
    delta = np.arctan2(s, c)
    period = 2 * np.pi / omega
    t0 = t_ref + (delta - eps) / omega
    t0 = t_ref + (t0 - t_ref + period / 2) % period - period / 2
    amplitude = np.hypot(c, s) * np.exp(-decay * (t0 - t_ref)) / np.sqrt(1 + (decay / omega) ** 2)
    return amplitude, t0


@dataclass(frozen=True)
class AttitudeLayout:
    """Shape of an attitude model: number of shared modes and the yaw trend's order.

    Parameters
    ----------
    n_modes : int
        Damped modes (>= 0), each with one frequency and decay shared by all axes.
    yaw_trend_order : int
        Degree of the yaw trend polynomial in (t - t_ref_s).
    t_ref_s : float
        Reference time of the (C, S) mode form and of the yaw trend.
    """

    n_modes: int = 1
    yaw_trend_order: int = 1
    t_ref_s: float = 0.0

    def __post_init__(self):
        for name in ("n_modes", "yaw_trend_order"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"AttitudeLayout.{name}: expected an integer >= 0, got {value!r}")

    @property
    def size(self) -> int:
        """Length of the flat parameter vector."""
        return 2 * self.n_modes + 2 * (1 + 2 * self.n_modes) + (self.yaw_trend_order + 1) + 2 * self.n_modes

    def slices(self) -> dict[str, slice]:
        """Where each block sits in the flat vector."""
        out, k = {}, 0
        n = self.n_modes
        for name, size in (("modes", 2 * n), ("roll_bias", 1), ("roll_cs", 2 * n), ("pitch_bias", 1),
                           ("pitch_cs", 2 * n), ("yaw_trend", self.yaw_trend_order + 1), ("yaw_cs", 2 * n)):
            out[name] = slice(k, k + size)
            k += size
        return out

    def names(self) -> list[str]:
        """A name for every entry of the flat vector."""
        n = self.n_modes
        names = [f"mode{k + 1}_{q}" for k in range(n) for q in ("omega", "decay")]
        for axis in ("roll", "pitch"):
            names += [f"{axis}_bias"] + [f"{axis}_mode{k + 1}_{q}" for k in range(n) for q in ("cos", "sin")]
        names += [f"yaw_trend{k}" for k in range(self.yaw_trend_order + 1)]
        names += [f"yaw_mode{k + 1}_{q}" for k in range(n) for q in ("cos", "sin")]
        return names


@dataclass(frozen=True)
class AttitudeParams:
    """Numbers of one attitude model; ``pack``/``unpack`` map to the flat vector.

    ``modes`` is (n, 2): damped circular frequency (rad/s) and decay rate (1/s) of each
    physical mode; ``roll_cs``, ``pitch_cs`` and ``yaw_cs`` are (n, 2) arrays of each
    axis' (C, S) on those modes about ``t_ref_s`` (see :func:`mode_cs`); yaw adds a
    trend polynomial in (t - t_ref_s), lowest order first.
    """

    modes: np.ndarray
    roll_bias: float
    roll_cs: np.ndarray
    pitch_bias: float
    pitch_cs: np.ndarray
    yaw_trend: np.ndarray
    yaw_cs: np.ndarray
    t_ref_s: float = 0.0

    @property
    def layout(self) -> AttitudeLayout:
        return AttitudeLayout(n_modes=int(np.shape(self.modes)[0]), yaw_trend_order=int(len(self.yaw_trend) - 1),
                              t_ref_s=float(self.t_ref_s))

    def pack(self) -> np.ndarray:
        n = self.layout.n_modes
        for name in ("roll_cs", "pitch_cs", "yaw_cs"):
            if np.shape(getattr(self, name)) != (n, 2):
                raise ValueError(f"{name}: expected shape ({n}, 2) for {n} modes, got {np.shape(getattr(self, name))}")
        return np.concatenate([
            np.reshape(self.modes, -1), [self.roll_bias], np.reshape(self.roll_cs, -1), [self.pitch_bias],
            np.reshape(self.pitch_cs, -1), np.asarray(self.yaw_trend, dtype=float), np.reshape(self.yaw_cs, -1),
        ]).astype(float)

    @classmethod
    def unpack(cls, p, layout: AttitudeLayout) -> "AttitudeParams":
        p = np.asarray(p, dtype=float).reshape(-1)
        if p.size != layout.size:
            raise ValueError(f"attitude parameters: expected {layout.size} values for {layout}, got {p.size}")
        s = layout.slices()
        n = layout.n_modes
        return cls(
            modes=p[s["modes"]].reshape(n, 2),
            roll_bias=float(p[s["roll_bias"]][0]),
            roll_cs=p[s["roll_cs"]].reshape(n, 2),
            pitch_bias=float(p[s["pitch_bias"]][0]),
            pitch_cs=p[s["pitch_cs"]].reshape(n, 2),
            yaw_trend=p[s["yaw_trend"]].copy(),
            yaw_cs=p[s["yaw_cs"]].reshape(n, 2),
            t_ref_s=layout.t_ref_s,
        )

    @classmethod
    def from_axis_modes(cls, roll_modes, roll_bias, pitch_modes, pitch_bias, yaw_trend, yaw_coupling=None,
                        t_ref_s: float = 0.0, yaw_modes=()) -> "AttitudeParams":
        """Build from per-axis modes in the paper's form: rows (A, t0, omega, decay).

        Roll's and pitch's modes become shared modes (zero on the other axis); yaw
        follows each mode scaled by ``yaw_coupling`` (one value per roll then pitch mode).
        ``yaw_modes`` are further modes of the heading alone (a boat wandering about its
        course while steered), zero on roll and pitch.
        """
        rows = [np.asarray(m, dtype=float).reshape(-1, 4) for m in (roll_modes, pitch_modes)]
        n_r, n_p = len(rows[0]), len(rows[1])
        coupling = np.zeros(n_r + n_p) if yaw_coupling is None else np.asarray(yaw_coupling, dtype=float)
        if coupling.size != n_r + n_p:
            raise ValueError(f"yaw_coupling: expected {n_r + n_p} values (one per roll and pitch mode), got {coupling.size}")
        modes = np.array([[w, v] for rws in rows for _, _, w, v in rws]).reshape(-1, 2)
        cs = np.array([paper_to_cs(a, t0, w, v, t_ref_s) for rws in rows for a, t0, w, v in rws]).reshape(-1, 2)
        roll_cs, pitch_cs = cs.copy(), cs.copy()
        roll_cs[n_r:] = 0.0
        pitch_cs[:n_r] = 0.0
        yaw_cs = cs * coupling[:, None]
        yaw_rows = np.asarray(yaw_modes, dtype=float).reshape(-1, 4)
        if yaw_rows.size:
            modes = np.vstack([modes, yaw_rows[:, 2:4]])
            own = np.array([paper_to_cs(a, t0, w, v, t_ref_s) for a, t0, w, v in yaw_rows]).reshape(-1, 2)
            roll_cs, pitch_cs = (np.vstack([x, np.zeros_like(own)]) for x in (roll_cs, pitch_cs))
            yaw_cs = np.vstack([yaw_cs, own])
        return cls(modes, float(roll_bias), roll_cs, float(pitch_bias), pitch_cs, np.asarray(yaw_trend, dtype=float),
                   yaw_cs, float(t_ref_s))

    def to_dict(self) -> dict:
        """JSON-ready description; each axis' mode also in the paper's (phi_0, t_0) form."""

        def axis(bias, cs):
            out = []
            for (c, s), (w, v) in zip(cs, self.modes):
                a, t0 = cs_to_paper(c, s, w, v, self.t_ref_s)
                out.append({"cos_rad": float(c), "sin_rad": float(s), "paper_amplitude_rad": float(a), "paper_t0_s": float(t0)})
            return {"bias_rad": float(bias), "modes": out}

        return {
            "t_ref_s": float(self.t_ref_s),
            "modes": [{"omega_rad_s": float(w), "decay_1_s": float(v), "period_s": float(2 * np.pi / w)} for w, v in self.modes],
            "roll": axis(self.roll_bias, self.roll_cs),
            "pitch": axis(self.pitch_bias, self.pitch_cs),
            "yaw": {"trend_coefficients": [float(c) for c in self.yaw_trend], **axis(0.0, self.yaw_cs)},
        }

    @classmethod
    def from_dict(cls, d: dict) -> "AttitudeParams":
        modes = np.array([[m["omega_rad_s"], m["decay_1_s"]] for m in d["modes"]], dtype=float).reshape(-1, 2)
        cs = lambda ax: np.array([[m["cos_rad"], m["sin_rad"]] for m in d[ax]["modes"]], dtype=float).reshape(-1, 2)
        return cls(modes, float(d["roll"]["bias_rad"]), cs("roll"), float(d["pitch"]["bias_rad"]), cs("pitch"),
                   np.array(d["yaw"]["trend_coefficients"], dtype=float), cs("yaw"), float(d.get("t_ref_s", 0.0)))


def attitude_ypr(t, p, layout: AttitudeLayout):
    """Yaw, pitch, roll (3x1 expression) at time t for flat parameters p."""
    return attitude_ypr_and_rate(t, p, layout)[0]


def attitude_ypr_and_rate(t, p, layout: AttitudeLayout):
    """Yaw, pitch, roll and their time derivatives (two 3x1 expressions) at time t (Eq. 34).

    Each mode's basis pair and its derivative (:func:`mode_basis`) serve all three axes, so the
    rates cost a few products instead of a derivative of each axis's sum."""
    s = layout.slices()
    modes = p[s["modes"]]
    tau = t - layout.t_ref_s
    basis = [mode_basis(tau, modes[2 * k], modes[2 * k + 1]) for k in range(layout.n_modes)]
    values, rates = [], []
    for axis in ("yaw", "pitch", "roll"):
        cs = p[s[f"{axis}_cs"]]
        if axis == "yaw":
            trend = p[s["yaw_trend"]]
            value, rate = 0, 0
            for k in range(layout.yaw_trend_order + 1):
                value = value + trend[k] * tau ** k
                if k:
                    rate = rate + k * trend[k] * tau ** (k - 1)
        else:
            value, rate = p[s[f"{axis}_bias"]][0], 0
        for k, (ec, es, dec, des) in enumerate(basis):
            value = value + cs[2 * k] * ec + cs[2 * k + 1] * es
            rate = rate + cs[2 * k] * dec + cs[2 * k + 1] * des
        values.append(value)
        rates.append(rate)
    return ca.vertcat(*values), ca.vertcat(*rates)


def attitude_function(layout: AttitudeLayout, sym=ca.SX) -> ca.Function:
    """CasADi Function ``attitude(t, p) -> (ypr, Lambda, dLambda_dt, Omega, omega)``.

    Lambda (Eq. 7) maps body to Earth; dLambda_dt is its exact time derivative by
    algorithmic differentiation; Omega = dLambda/dt Lambda^T (Eq. 32) is the
    Earth-frame angular velocity tensor and omega its axial vector (Earth frame).
    """
    t = sym.sym("t")
    p = sym.sym("p", layout.size)
    return _attitude_from_ypr(t, p, *attitude_ypr_and_rate(t, p, layout))


LOCAL_ATTITUDE_SIZE = 8
DEVIATION_BAND_RAD_S = 0.1  # the compass deviation's heading: the samples' heading smoothed above this (periods < 1 min)


def local_attitude_function(sym=ca.SX) -> ca.Function:
    """The measured attitude about one time, as an attitude model: same signature as
    :func:`attitude_function`, with p = [t_k, yaw, pitch, roll (rad), their rates (rad/s),
    the slow heading] and ypr(t) = ypr_k + rate (t - t_k). With p from
    :func:`local_attitude_params` it is the sensor's samples interpolated linearly (used when no
    motion model fits the run). The slow heading (``p[7]``, the samples' heading smoothed over a
    minute) is what a compass deviation is a function of: the noisy reading there would make the
    deviation a regression on the compass's own noise (errors in variables)."""
    t = sym.sym("t")
    p = sym.sym("p", LOCAL_ATTITUDE_SIZE)
    return _attitude_from_ypr(t, p, p[1:4] + p[4:7] * (t - p[0]))


def local_attitude_params(time_s, ypr_rad, times) -> np.ndarray:
    """(7, n) parameters of :func:`local_attitude_function` at ``times``: the samples'
    linear interpolation (heading unwrapped) and the slope of the segment holding each time."""
    time_s = np.asarray(time_s, dtype=float)
    times = np.asarray(times, dtype=float).reshape(-1)
    ypr = np.asarray(ypr_rad, dtype=float).copy()
    ypr[:, 0] = np.unwrap(ypr[:, 0])
    j = np.clip(np.searchsorted(time_s, times, side="right") - 1, 0, time_s.size - 2)
    slope = (ypr[j + 1] - ypr[j]) / (time_s[j + 1] - time_s[j])[:, None]
    at = ypr[j] + slope * (times - time_s[j])[:, None]
    return np.vstack([times, at.T, slope.T, at[:, 0]])


UNDERSAMPLED_SHARE = 0.5  # an axis with more of its variance than this above half the Nyquist frequency


def share_above_half_nyquist(time_s, ypr_rad) -> np.ndarray:
    """Per axis (heading unwrapped, pitch, roll), the share of the samples' variance (a cubic trend
    removed: turns and drifts) above half their Nyquist frequency, from the periodogram at the median
    sample interval: where the smoothing spline's band stops."""
    from scipy.signal import periodogram

    t = np.asarray(time_s, dtype=float)
    ypr = np.asarray(ypr_rad, dtype=float).copy()
    ypr[:, 0] = np.unwrap(ypr[:, 0])
    dt = float(np.median(np.diff(t)))
    cubic = lambda y: y - np.polyval(np.polyfit(t - t[0], y, 3), t - t[0])
    f, power = periodogram(np.column_stack([cubic(ypr[:, j]) for j in range(3)]), fs=1.0 / dt, detrend=False, axis=0)
    total = power.sum(axis=0)
    return np.where(total > 0, power[2 * np.pi * f > 0.5 * np.pi / dt].sum(axis=0) / np.where(total > 0, total, 1), 0.0)


def fast_axes(time_s, ypr_rad) -> dict:
    """The axes (name -> share) of complete samples with most of their variance
    (:data:`UNDERSAMPLED_SHARE`) above half their Nyquist frequency: motion sampled too sparsely
    for a smoothing spline's band (empty with fewer than ``MIN_SPLINE_SAMPLES``)."""
    if len(time_s) < MIN_SPLINE_SAMPLES:
        return {}
    share = share_above_half_nyquist(time_s, ypr_rad)
    return {n: float(v) for n, v in zip(("heading", "pitch", "roll"), share) if v > UNDERSAMPLED_SHARE}


SAMPLE_INTERPOLATIONS = ("spline", "linear")
MIN_SPLINE_SAMPLES = 5
BAND_RESPONSE = 0.98  # the smoothing keeps this much of the amplitude at the top of the motion band
BAND_MARGIN = 1.2  # the band's top: this times the fastest motion mode


@dataclass(frozen=True)
class SampledAttitude:
    """The sensor's samples as the attitude (:func:`local_attitude_function` about each time): what
    the calibration, corrections and diagnosis use where no motion model follows the run.

    ``interpolation``: ``spline`` (default) takes each time's angle and rate from a smoothing
    spline per axis that keeps the motion band and rejects the noise above it: the response of
    the spline's penalty, about 1 / (1 + lambda dt omega^4), is ``BAND_RESPONSE`` at the top of
    the band (``BAND_MARGIN`` times ``band_rad_s``, the fastest motion mode; half the Nyquist
    frequency when no band is given, and never above). The secant of a linear segment is the
    rate at the segment's midpoint, 15-30 % off at 6 samples per roll period, and differences
    the sensor's noise: it biased lever arms and looked like effects in the diagnosis.
    ``linear`` joins the samples with straight lines. ``reason``: why this interpolation, in words.
    """

    time_s: np.ndarray
    ypr_rad: np.ndarray
    interpolation: str = "spline"
    band_rad_s: float | None = None
    reason: str = "smoothed within the motion band"

    def __post_init__(self):
        if self.interpolation not in SAMPLE_INTERPOLATIONS:
            raise ValueError(f"interpolation: expected one of {list(SAMPLE_INTERPOLATIONS)}, got {self.interpolation!r}")

    @functools.cached_property
    def _spline(self):
        from scipy.interpolate import make_smoothing_spline

        t = np.asarray(self.time_s, dtype=float)
        ypr = np.asarray(self.ypr_rad, dtype=float).copy()
        ypr[:, 0] = np.unwrap(ypr[:, 0])
        if t.size < MIN_SPLINE_SAMPLES:
            return None
        dt = float(np.median(np.diff(t)))
        top = 0.5 * np.pi / dt  # half the Nyquist frequency
        if self.band_rad_s:
            top = min(top, BAND_MARGIN * float(self.band_rad_s))
        lam = (1 / BAND_RESPONSE - 1) / (dt * top**4)
        return make_smoothing_spline(t, ypr, lam=lam)  # the three axes in one call (scipy's per-sample loop once)

    def params_at(self, times, tilt_lead_s: float = 0.0) -> np.ndarray:
        """(7, n) local attitude parameters at ``times``. ``tilt_lead_s`` (tau) adds tau times the
        derivative to pitch and roll and to their rates: the inverse of a first-order low-pass
        (x = y + tau y', x' = y' + tau y''; the linear interpolation has no y'')."""
        spline = self._spline if self.interpolation == "spline" else None
        if spline is None:
            p = local_attitude_params(self.time_s, self.ypr_rad, times)
            p[2:4] += tilt_lead_s * p[5:7]
            p[7] = self.deviation_heading_at(times)
            return p
        times = np.asarray(times, dtype=float).reshape(-1)
        inside = np.clip(times, self.time_s[0], self.time_s[-1])  # held beyond the record, never extrapolated by the spline
        at = spline(inside)
        rate = spline.derivative()(inside)
        if tilt_lead_s:
            accel = spline.derivative(2)(inside)[:, 1:]
            at[:, 1:] += tilt_lead_s * rate[:, 1:]
            rate[:, 1:] += tilt_lead_s * accel
        return np.vstack([inside, at.T, rate.T, self.deviation_heading_at(inside)])

    @functools.cached_property
    def _slow_heading(self):
        from scipy.interpolate import make_smoothing_spline

        t = np.asarray(self.time_s, dtype=float)
        if t.size < MIN_SPLINE_SAMPLES:
            return None
        dt = float(np.median(np.diff(t)))
        lam = (1 / BAND_RESPONSE - 1) / (dt * DEVIATION_BAND_RAD_S**4)
        return make_smoothing_spline(t, np.unwrap(np.asarray(self.ypr_rad, dtype=float)[:, 0]), lam=lam)

    def deviation_heading_at(self, times) -> np.ndarray:
        """The heading a compass deviation is evaluated at (rad, unwrapped like :meth:`params_at`'s):
        the samples' heading smoothed above ``DEVIATION_BAND_RAD_S``, following turns of a minute and
        longer, not the reading's noise; the linear interpolation where too few samples."""
        times = np.clip(np.asarray(times, dtype=float).reshape(-1), self.time_s[0], self.time_s[-1])
        spline = self._slow_heading
        return self.heading_at(times) if spline is None else spline(times)

    def heading_at(self, times) -> np.ndarray:
        """Heading (rad, unwrapped) interpolated linearly, held at the end values outside the samples."""
        return np.interp(times, self.time_s, np.unwrap(self.ypr_rad[:, 0]))


def attitude_expansion(attitude_fun: ca.Function, t0, p, order: int = 2):
    """``attitude_fun``'s outputs about ``t0`` as their Taylor polynomials of ``order`` in t - t0: a
    callable ``t -> [ypr, Lambda, dLambda_dt, Omega, omega]`` (SX expressions).

    The coefficients are the outputs' time derivatives at t0 by algorithmic differentiation of the
    same Function, so they reuse its sines, cosines and exponentials at t0: the attitude a moment
    after a time where it is already evaluated, without evaluating it again. The remainder is
    below max|d^(order+1)/dt^(order+1)| |t - t0|^(order+1) / (order+1)!.
    """
    h = ca.SX.sym("h")
    coefficients = []
    for out in attitude_fun(t0 + h, p):
        terms, d = [], out
        for k in range(order + 1):
            terms.append(ca.substitute(d, h, ca.SX(0)) / math.factorial(k))
            if k < order:
                d = ca.reshape(ca.jacobian(ca.vec(d), h), d.shape)
        coefficients.append(terms)

    def at(t):
        dt = t - t0
        values = []
        for terms in coefficients:
            v = terms[-1]
            for c in reversed(terms[:-1]):  # Horner
                v = c + dt * v
            values.append(v)
        return values

    return at


HEADING_CORRECTION_SIZE = 3  # misalignment, deviation B (sin), deviation C (cos)


def heading_corrected_function(attitude_fun: ca.Function, mean_sin: float = 0.0, mean_cos: float = 0.0,
                               sym=ca.SX) -> ca.Function:
    """An attitude model whose heading is the sensor's corrected to true north:
    ``attitude(t, [p; h]) -> (ypr, Lambda, dLambda_dt, Omega, omega)`` with
    h = (misalignment, B, C) and yaw = psi_s + delta, delta the
    :func:`~adcpdyn.models.sensors.compass_correction` (deviation about the headings' mean sine
    and cosine ``mean_sin``, ``mean_cos``). Same signature as ``attitude_fun``, so every model
    that takes an attitude Function takes this one.

    Lambda = Rz(delta) Lambda_s exactly (a yaw offset of Eq. 7), and dLambda/dt = Rz(delta)
    dLambda_s/dt: a compass error turns the measured rotation, it is no rotation itself. (The
    correction's own rate, delta'(psi) dpsi/dt, is a percent of the yaw rate per degree of
    deviation; left in, it would make the deviation a free yaw-rate scale that soaks up any
    rate misfit.)
    """
    from .sensors import compass_correction

    t = sym.sym("t")
    p = sym.sym("p", attitude_fun.size_in(1))
    h = sym.sym("h", HEADING_CORRECTION_SIZE)
    ypr_s, Lam_s, dLam_s, _, _ = attitude_fun(t, p)
    delta = compass_correction(ypr_s[0], h[0], h[1], h[2], mean_sin, mean_cos)
    Rz = euler_matrix(delta, 0, 0)
    Lam, dLam = ca.mtimes(Rz, Lam_s), ca.mtimes(Rz, dLam_s)
    Omega = ca.mtimes(dLam, Lam.T)
    inner = ca.Function("attitude_corrected", [t, p, h], [ca.vertcat(ypr_s[0] + delta, ypr_s[1], ypr_s[2]), Lam, dLam,
                                                           Omega, unskew(Omega)])
    t2, p2 = sym.sym("t"), sym.sym("p", p.shape[0] + HEADING_CORRECTION_SIZE)
    outputs = inner(t2, p2[:p.shape[0]], p2[p.shape[0]:])
    return ca.Function("attitude", [t2, p2], outputs, ["t", "p"], ["ypr", "Lambda", "dLambda_dt", "Omega", "omega"])


def _attitude_from_ypr(t, p, ypr, ypr_rate=None) -> ca.Function:
    Lam, dLam, w_b = euler_matrix_and_rate(ypr, ca.jacobian(ypr, t) if ypr_rate is None else ypr_rate)
    omega = ca.mtimes(Lam, w_b)  # Omega = dLambda/dt Lambda^T = Lambda skew(w_b) Lambda^T = skew(Lambda w_b)
    Omega = skew(omega)
    return ca.Function(
        "attitude",
        [t, p],
        [ypr, Lam, dLam, Omega, omega],
        ["t", "p"],
        ["ypr", "Lambda", "dLambda_dt", "Omega", "omega"],
    )


def with_extra_mode(p, layout: AttitudeLayout, omega, decay, roll_cs, pitch_cs):
    """Flat parameters of ``layout`` plus one mode (roll and pitch (C, S); yaw not coupled)
    -> (p', layout'): an oscillation the model adds, e.g. steady wave-forced roll."""
    s = layout.slices()
    seg = lambda name: p[s[name]]
    p_new = ca.vertcat(seg("modes"), omega, decay, seg("roll_bias"), seg("roll_cs"), roll_cs[0], roll_cs[1],
                       seg("pitch_bias"), seg("pitch_cs"), pitch_cs[0], pitch_cs[1], seg("yaw_trend"), seg("yaw_cs"), 0, 0)
    return p_new, AttitudeLayout(layout.n_modes + 1, layout.yaw_trend_order, layout.t_ref_s)


def stack_matrices(block: np.ndarray, n: int) -> np.ndarray:
    """(3, 3n) horizontally mapped CasADi output -> (n, 3, 3)."""
    return np.asarray(block).reshape(3, n, 3).transpose(1, 0, 2)


EVAL_CHUNK = 8192


@functools.lru_cache(maxsize=32)
def _mapped_attitude(layout: AttitudeLayout, n: int) -> ca.Function:
    return attitude_function(layout).map(n)


@functools.lru_cache(maxsize=8)
def _mapped_local_attitude(n: int) -> ca.Function:
    return local_attitude_function().map(n)


def evaluate_attitude(params: AttitudeParams | SampledAttitude, times, anchor_s=None) -> dict[str, np.ndarray]:
    """Numeric attitude at many times: ypr (n,3), Lambda, dLambda_dt, Omega (n,3,3), omega (n,3).

    ``params``: a motion model, or the sensor's samples (:class:`SampledAttitude`); with
    samples, ``anchor_s`` (same shape as ``times``) is the time whose sample segment is
    extended to each time (a ping's transmit time for its receive times, as the
    calibration's measurement model does), default the time itself.
    Evaluated in chunks through one cached mapped Function per layout (building a map
    over n costs O(n), so it is built once per chunk size, not per call).
    """
    times = np.asarray(times, dtype=float).reshape(-1)
    anchors = times if anchor_s is None else np.broadcast_to(np.asarray(anchor_s, dtype=float), times.shape).reshape(-1)
    n = times.size
    sampled = isinstance(params, SampledAttitude)
    p = None if sampled else params.pack()
    parts = []
    for start in range(0, n, EVAL_CHUNK):
        chunk = times[start:start + EVAL_CHUNK]
        size = EVAL_CHUNK if n > EVAL_CHUNK else n
        padded = np.pad(chunk, (0, size - chunk.size), mode="edge")
        if sampled:
            anchor = np.pad(anchors[start:start + EVAL_CHUNK], (0, size - chunk.size), mode="edge")
            out = _mapped_local_attitude(size)(padded[None, :], params.params_at(anchor))
        else:
            out = _mapped_attitude(params.layout, size)(padded[None, :], p)
        parts.append([o.full() for o in out])
    cat = lambda k, rows: np.concatenate([part[k] for part in parts], axis=1)[:, : n * rows]
    out = [cat(0, 1), cat(1, 3), cat(2, 3), cat(3, 3), cat(4, 1)]
    return {
        "ypr": out[0].T,
        "Lambda": stack_matrices(out[1], n),
        "dLambda_dt": stack_matrices(out[2], n),
        "Omega": stack_matrices(out[3], n),
        "omega": out[4].T,
    }
