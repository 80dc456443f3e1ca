"""Attitude-only fit of the sensor's angles: the starting point of every calibration.

Roll and pitch (of whatever frame the sensor sits in) share damped modes
(:mod:`adcpdyn.models.motion`), added greedily: the strongest Lomb-Scargle peak of
the current residuals seeds a new mode (irregular sample times keep the true peak
above its aliases even below the mean Nyquist rate; regular ones are searched up to
their Nyquist frequency, :func:`resolved_omega`), each axis' (C, S) and bias
follow by linear least squares over a small decay grid, then everything is refined
by nonlinear least squares in the modes alone, the amplitudes projected out (variable
projection: the joint fit's optimum); a mode is kept when it lowers the Bayesian information
criterion by more than ``BIC_MARGIN``. Yaw is then linear in its parameters (trend
polynomial plus (C, S) on every mode), its trend order chosen by BIC too. The
two-stage baseline fits each axis separately with the paper's one mode.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..cases.case import Case
from ..models.motion import AttitudeParams, fast_axes
from .statistics.periodogram import lomb_scargle

BIC_MARGIN = 10.0
DECAY_GRID_1_S = (0.0, 0.03, 0.1, 0.3, 1.0)
MAX_DECAY_1_S = 3.0
MAX_OMEGA_RAD_S = 16.0
ALIAS_WINDOW = 0.9  # a frequency where the samples' spectral window is this coherent aliases zero frequency
WINDOW_SAMPLES = 1000  # the window is a property of the sampling: its first samples tell it
MAX_TILT_AMPLITUDE_RAD = np.pi / 2  # a roll or pitch mode beyond a quarter turn is no motion: an alias the samples do not bound
PERIODOGRAM_SAMPLES = 800
DENSE_NYQUIST_FRACTION = 0.75  # long records sampled this densely get FFT candidates
# frequencies of a half-width candidate grid above which a record (jittered, so no FFT) gets its candidates from
# COARSE_WINDOWS windows of its own: at 16 rad/s, records longer than about 3200 s (an hour's transect keeps its grid)
COARSE_MAX_FREQUENCIES = 16384
COARSE_WINDOWS = 3
COARSE_WINDOW_FREQUENCIES = 8192  # each window's own grid: about 1600 s long at 16 rad/s
# the modes' nonlinear refinement takes at most this many of a record's samples (a random share, seeded); amplitudes,
# residuals and BIC are those of every sample
MODE_FIT_SAMPLES = 20_000
MODE_FIT_SEED = 0


def random_share(n: int, count: int, seed: int) -> np.ndarray:
    """``count`` (at least 2) of the indices 0..n-1 drawn at random (seeded), sorted, the first and last
    among them: a share of a record's samples whose times alias no mode, as every k-th would."""
    if count >= n:
        return np.arange(n)
    inner = np.random.default_rng(seed).choice(np.arange(1, n - 1), max(count, 2) - 2, replace=False)
    return np.concatenate([[0], np.sort(inner), [n - 1]])


@dataclass(frozen=True)
class ModeFit:
    """Shared modes (n, 2) = (omega, decay) and, per axis, bias and (C, S) (n, 2)."""

    modes: np.ndarray
    biases: np.ndarray  # (A,)
    cs: np.ndarray  # (A, n, 2)
    sigmas: np.ndarray  # (A,)
    bic_trail: list = field(default_factory=list)


@dataclass(frozen=True)
class AttitudeFit:
    params: AttitudeParams
    sigmas: np.ndarray  # noise (heading, pitch, roll), rad
    yaw_trend_order: int
    bic_trail: list = field(default_factory=list)

    @property
    def heading_sigma(self) -> float:
        return float(self.sigmas[0])


def autocorrelation(x, lags: int) -> np.ndarray:
    """Autocorrelation of a residual series (mean removed) at lags 1..``lags``; 0 for a constant one."""
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    d = float(np.dot(x, x)) or 1.0
    return np.array([np.dot(x[:-k], x[k:]) / d for k in range(1, lags + 1)])


def periodogram_peak(t, x, lo, hi, n_candidates=5) -> float:
    """Circular frequency of the highest Lomb-Scargle peak in [lo, hi] (columns of x summed).

    A grid at half the peak width (pi / duration) finds the candidate peaks, a fine
    grid around each of the highest few finds the maximum. Long series are thinned to
    ``PERIODOGRAM_SAMPLES`` evenly spread samples: the peak needs SNR, not every sample.
    A long record sampled densely (mean Nyquist at least ``DENSE_NYQUIST_FRACTION`` of
    ``hi``) gets its candidates from an FFT of the record interpolated to a uniform grid
    instead: the half-width grid has as many frequencies as the record has seconds
    times the band, and Lomb-Scargle's cost is that times the samples. A record too
    long for that grid whose jittered samples resolve beyond their mean Nyquist rate
    (no FFT) gets them from windows of its own (:func:`_window_candidates`), the fine
    grids then spanning the windows' peak width at a quarter of the record's.
    """
    t = np.asarray(t, dtype=float)
    x = np.atleast_2d(np.asarray(x, dtype=float).T).T
    x = x - x.mean(axis=0)
    width = 2 * np.pi / (t[-1] - t[0])
    dense = t.size > PERIODOGRAM_SAMPLES and np.pi / np.median(np.diff(t)) >= DENSE_NYQUIST_FRACTION * hi
    candidates = _fft_candidates(t, x, lo, hi, n_candidates) if dense else None
    span = width / 2  # how far from a candidate the maximum may lie
    if candidates is None and (hi - lo) / (width / 2) > COARSE_MAX_FREQUENCIES:  # a long record, jittered samples
        candidates, span = _window_candidates(t, x, lo, hi, n_candidates)
    t, x = _thinned(t, x)
    power = lambda grid: lomb_scargle(t, x, grid).sum(axis=1)
    if candidates is None:
        coarse = np.arange(lo, hi, width / 2)
        candidates = coarse[np.argsort(power(coarse))[::-1][:n_candidates]]
    best_omega, best_power = lo, -np.inf
    n_fine = max(41, int(np.ceil(2 * span / (width / 4))) + 1)  # at most a quarter of the record's peak width apart
    for omega in candidates:
        fine = np.linspace(max(lo, omega - span), min(hi, omega + span), n_fine)
        pf = power(fine)
        if pf.max() > best_power:
            best_omega, best_power = fine[int(np.argmax(pf))], pf.max()
    return float(best_omega)


def _thinned(t, x):
    """At most ``PERIODOGRAM_SAMPLES`` evenly spread samples."""
    if t.size <= PERIODOGRAM_SAMPLES:
        return t, x
    keep = np.unique(np.linspace(0, t.size - 1, PERIODOGRAM_SAMPLES).astype(int))
    return t[keep], x[keep]


def _window_candidates(t, x, lo, hi, n_candidates) -> tuple[np.ndarray, float]:
    """Candidate peaks of a record too long for a half-width grid over [lo, hi] (more than
    ``COARSE_MAX_FREQUENCIES`` frequencies, each a pass over the thinned samples: an 18-hour record of
    jittered pings had 331000): each of ``COARSE_WINDOWS`` windows (the start, the middle, the end), long
    enough for a grid of ``COARSE_WINDOW_FREQUENCIES``, gives its highest peaks on its own half-width grid;
    and how far from a candidate the record's maximum may lie (half the windows' peak width)."""
    length = COARSE_WINDOW_FREQUENCIES * np.pi / (hi - lo)
    starts = np.linspace(t[0], t[-1] - length, COARSE_WINDOWS)
    coarse = np.arange(lo, hi, np.pi / length)
    found = []
    for a in starts:
        inside = (t >= a) & (t <= a + length)
        tw, xw = _thinned(t[inside], x[inside])
        if tw.size > 3:
            found.append(coarse[np.argsort(lomb_scargle(tw, xw, coarse).sum(axis=1))[::-1][:n_candidates]])
    return np.unique(np.concatenate(found)), np.pi / length


def _fft_candidates(t, x, lo, hi, n_candidates) -> np.ndarray:
    """The ``n_candidates`` highest bins in [lo, hi] of the summed power spectrum of x
    interpolated to a uniform grid (Nyquist 1.25 hi), zero-padded to half the peak width."""
    dt = np.pi / (1.25 * hi)
    grid = np.arange(t[0], t[-1], dt)
    xi = np.column_stack([np.interp(grid, t, x[:, j]) for j in range(x.shape[1])])
    n_fft = int(2 ** np.ceil(np.log2(2 * grid.size)))
    spectrum = np.sum(np.abs(np.fft.rfft(xi, n=n_fft, axis=0)) ** 2, axis=1)
    omega = 2 * np.pi * np.fft.rfftfreq(n_fft, dt)
    band = (omega >= lo) & (omega <= hi)
    return omega[band][np.argsort(spectrum[band])[::-1][:n_candidates]]


def _bic(rss: float, n: int, k: int) -> float:
    return n * np.log(max(rss, 1e-300) / n) + k * np.log(n)


def _design(t, modes, t_ref):
    tau = t - t_ref
    cols = [np.ones_like(t)]
    for w, v in modes:
        e = np.exp(-v * tau)
        cols += [e * np.cos(w * tau), e * np.sin(w * tau)]
    return np.column_stack(cols)


class _ProjectedModes:
    """The modes' frequencies and decays alone (variable projection, Golub and Pereyra 1973): for given
    modes every axis' bias and (C, S) follow by linear least squares on the shared design X, so the
    residuals are P Y / scale, P the projector onto the complement of X's columns. Their Jacobian is
    Kaufman's -P (dX/dtheta) c, whose gradient is the exact one (the term it leaves out is orthogonal to
    the residuals): the same optimum as the joint fit of all 2 n + A (1 + 2 n) parameters, whose
    (A M) x (2 n + A (1 + 2 n)) Jacobian cost an SVD an iteration (10^5 samples: fit_attitude 1.96 s
    with the joint fit, 1.08 s with this one)."""

    def __init__(self, t, Y, t_ref: float, scale):
        self.t, self.tau, self.Y, self.t_ref, self.scale = t, t - t_ref, Y, t_ref, scale
        self._at = None

    def _solve(self, theta):
        """(X, X's orthonormal basis Q, the coefficients (1 + 2 n, A), the weighted residuals (M, A)) at ``theta``,
        kept for the Jacobian least_squares asks for where it has just evaluated."""
        key = theta.tobytes()
        if self._at is None or self._at[0] != key:
            X = _design(self.t, theta.reshape(-1, 2), self.t_ref)
            Q, R = np.linalg.qr(X)
            c = np.linalg.lstsq(R, Q.T @ self.Y, rcond=None)[0]
            self._at = (key, X, Q, c, (self.Y - X @ c) / self.scale)
        return self._at[1:]

    def coefficients(self, theta) -> np.ndarray:
        """Each axis' [bias, C_k, S_k]* (1 + 2 n, A) at the modes ``theta``."""
        return self._solve(np.asarray(theta, dtype=float))[2]

    def residuals(self, theta) -> np.ndarray:
        return self._solve(theta)[3].T.reshape(-1)

    def jacobian(self, theta) -> np.ndarray:
        X, Q, c, _ = self._solve(theta)
        tau = self.tau[:, None]
        J = np.empty((self.Y.size, theta.size))
        for k in range(theta.size // 2):
            ec, es = X[:, 1 + 2 * k, None], X[:, 2 + 2 * k, None]
            C, S = c[1 + 2 * k], c[2 + 2 * k]  # (A,)
            for j, (dc, ds) in enumerate(((-tau * es, tau * ec), (-tau * ec, -tau * es))):  # d/d omega, d/d decay
                v = dc * C + ds * S  # (M, A): dX/dtheta c
                v -= Q @ (Q.T @ v)
                J[:, 2 * k + j] = (v / -self.scale).T.reshape(-1)
        return J


def resolved_omega(t) -> float:
    """The highest mode frequency (rad/s) the sample times ``t`` tell from its aliases: pi / dt (the
    Nyquist frequency of their median interval dt) where their spectral window |mean exp(i w t_k)|
    at w = 2 pi / dt exceeds ``ALIAS_WINDOW`` (every sample at nearly one phase: a mode of w looks
    like a constant and one of w - v like one of v), else ``MAX_OMEGA_RAD_S`` (jittered pings resolve
    modes above their mean Nyquist rate)."""
    t = np.sort(np.asarray(t, dtype=float))[:WINDOW_SAMPLES]
    dt = float(np.median(np.diff(t))) if t.size > 2 else 0.0
    if dt <= 0:
        return MAX_OMEGA_RAD_S
    window = abs(np.exp(2j * np.pi / dt * (t - t[0])).mean())
    return float(min(MAX_OMEGA_RAD_S, np.pi / dt)) if window > ALIAS_WINDOW else MAX_OMEGA_RAD_S


def fit_modes(t, Y, t_ref: float, max_modes: int = 3, fixed_modes: int | None = None, omega_band=None) -> ModeFit:
    """Shared damped modes of one or more angle series (columns of Y, radians).

    Greedy: the highest summed Lomb-Scargle peak of the residuals seeds a mode; its
    decay comes from a small grid with every axis' (bias, C, S) by linear least
    squares; then all frequencies, decays and amplitudes are refined by nonlinear
    least squares (:class:`_ProjectedModes`). A mode is kept while BIC drops by more than ``BIC_MARGIN``
    (``fixed_modes`` skips the criterion). A record of more than :data:`MODE_FIT_SAMPLES` samples refines its
    frequencies and decays on a random share of that many (:func:`random_share`), its amplitudes, residuals
    and BIC on every sample (an 18-hour river run of 10^5 samples: the refinement's three solves had taken
    2.5 s of its 4.2 s).
    """
    t = np.asarray(t, dtype=float)
    Y = np.atleast_2d(np.asarray(Y, dtype=float).T).T
    M, A = Y.shape
    duration = t[-1] - t[0]
    lo, hi = omega_band or (max(2 * np.pi * 2 / duration, 0.2), resolved_omega(t))
    scale = np.maximum(np.std(Y, axis=0), 1e-6)
    modes = np.zeros((0, 2))
    full = _ProjectedModes(t, Y, t_ref, scale)
    fit = full
    if M > MODE_FIT_SAMPLES:
        sub = random_share(M, MODE_FIT_SAMPLES, MODE_FIT_SEED)
        fit = _ProjectedModes(t[sub], Y[sub], t_ref, scale)  # the refinement's samples
    coef = full.coefficients(modes.reshape(-1))  # (1 + 2n, A)
    rss = float(np.sum(full.residuals(modes.reshape(-1)) ** 2))
    trail = [{"modes": 0, "bic": _bic(rss, M * A, A)}]
    target = fixed_modes if fixed_modes is not None else max_modes
    for k in range(1, target + 1):
        resid = Y - _design(t, modes, t_ref) @ coef
        if np.ptp(resid) == 0 or lo >= hi:  # nothing left, or no frequency the samples resolve
            break
        omega = periodogram_peak(t, resid / scale, lo, hi)
        trials = [np.vstack([modes, [omega, decay]]).reshape(-1) for decay in DECAY_GRID_1_S]
        trial = min(trials, key=lambda q: float(np.sum(fit.residuals(q) ** 2)))  # the decay grid's best start
        lower, upper = np.tile([lo, 0.0], k), np.tile([hi, MAX_DECAY_1_S], k)
        sol = least_squares(fit.residuals, np.clip(trial, lower, upper), jac=fit.jacobian,
                            bounds=(lower, upper), x_scale="jac")
        c = full.coefficients(sol.x)  # (1 + 2k, A)
        rss_k = float(2 * sol.cost) if fit is full else float(np.sum(full.residuals(sol.x) ** 2))
        bic_k = _bic(rss_k, M * A, 2 * k + A * (1 + 2 * k))
        trail.append({"modes": k, "bic": bic_k})
        cs = c[1:].T.reshape(A, k, 2)  # per axis, per mode: (C, S)
        amplitude = float(np.hypot(cs[..., 0], cs[..., 1]).max())
        if amplitude > MAX_TILT_AMPLITUDE_RAD:  # e.g. a mode at the sampling rate (every sample at one phase)
            trail[-1].update(rejected=True, why=f"amplitude {amplitude:.3g} rad: not bounded by the samples")
            break
        if fixed_modes is None and bic_k > trail[-2]["bic"] - BIC_MARGIN:
            trail[-1]["rejected"] = True
            break
        modes, coef = sol.x.reshape(k, 2), c
        rss = rss_k
    n = len(modes)
    resid = Y - _design(t, modes, t_ref) @ coef
    sigmas = np.sqrt(np.sum(resid**2, axis=0) / max(M - (1 + 2 * n) - 2 * n / A, 1))
    return ModeFit(modes, coef[0], coef[1:].T.reshape(A, n, 2), sigmas, trail)


def fit_attitude(case: Case, max_modes: int = 3, fixed_modes: int | None = None, max_trend_order: int = 2,
                 t_ref: float | None = None, per_axis: bool = False) -> AttitudeFit:
    """Fit the sensor's roll, pitch and heading samples of a case (see module docstring).

    ``per_axis=True`` fits roll and pitch separately, each with its own modes (the
    paper's way, used by the two-stage baseline); otherwise the modes are shared.
    """
    a = case.attitude
    t_ref = float(case.pings.time_s[0]) if t_ref is None else float(t_ref)
    ypr = a.ypr()
    valid = np.all(np.isfinite(ypr), axis=1)  # missing samples (NaN) are left out, not interpolated
    if valid.sum() < 3:
        raise ValueError(f"{case.name}: attitude: expected at least 3 samples with heading, pitch and roll, got {int(valid.sum())}")
    t, ypr = a.time_s[valid], ypr[valid]
    if per_axis:
        fr = fit_modes(t, ypr[:, 2], t_ref, max_modes, fixed_modes)
        fp = fit_modes(t, ypr[:, 1], t_ref, max_modes, fixed_modes)
        modes = np.vstack([fr.modes, fp.modes])
        roll_cs = np.vstack([fr.cs[0], np.zeros_like(fp.cs[0])])
        pitch_cs = np.vstack([np.zeros_like(fr.cs[0]), fp.cs[0]])
        biases, sig_tilt, trail = (fr.biases[0], fp.biases[0]), (fp.sigmas[0], fr.sigmas[0]), fr.bic_trail + fp.bic_trail
    else:
        f = fit_modes(t, ypr[:, [2, 1]], t_ref, max_modes, fixed_modes)
        modes, roll_cs, pitch_cs = f.modes, f.cs[0], f.cs[1]
        biases, sig_tilt, trail = (f.biases[0], f.biases[1]), (f.sigmas[1], f.sigmas[0]), f.bic_trail

    # Yaw: trend polynomial plus every mode with its own (C, S): linear least squares.
    osc = _design(t, modes, t_ref)[:, 1:]
    best = None
    for order in range(max_trend_order + 1):
        X = np.column_stack([(t - t_ref) ** k for k in range(order + 1)] + [osc])
        coef, *_ = np.linalg.lstsq(X, ypr[:, 0], rcond=None)
        rss = float(np.sum((ypr[:, 0] - X @ coef) ** 2))
        bic = _bic(rss, t.size, X.shape[1])
        if best is None or bic < best[0] - BIC_MARGIN:
            best = (bic, order, coef, rss, X.shape[1])
    _, order, coef, rss, k = best
    params = AttitudeParams(
        modes=modes, roll_bias=float(biases[0]), roll_cs=roll_cs, pitch_bias=float(biases[1]), pitch_cs=pitch_cs,
        yaw_trend=coef[: order + 1], yaw_cs=coef[order + 1:].reshape(-1, 2), t_ref_s=t_ref,
    )
    sig_heading = float(np.sqrt(rss / max(t.size - k, 1)))
    return AttitudeFit(params, np.array([sig_heading, *sig_tilt]), order, trail)


def undersampled_axes(case: Case) -> dict:
    """The axes (name -> share) with most of their variance (:data:`~adcpdyn.models.motion.UNDERSAMPLED_SHARE`) above half
    the complete samples' Nyquist frequency: motion the sensor samples too sparsely to follow
    between samples, so that a delay of a whole sample interval fits nearly as well as none."""
    ok = case.attitude.complete()
    return fast_axes(case.attitude.time_s[ok], case.attitude.ypr()[ok])


def sampled_attitude(case: Case, fit: AttitudeFit | None = None, interpolation: str | None = None):
    """The sensor's complete samples as the attitude (:class:`~adcpdyn.models.motion.SampledAttitude`),
    smoothed within the motion band of the pre-fit's modes: one recipe for the calibration, the
    corrections and the diagnosis, so that all three put the same attitude in the beams. Where an
    axis has most of its variance (:data:`~adcpdyn.models.motion.UNDERSAMPLED_SHARE`) above half the samples' Nyquist
    frequency, the sensor samples the motion too sparsely for the spline's band, whose penalty cuts
    into the motion (winriver01, 1.31-s samples: 94 % of its roll variance there, the spline 0.30 deg
    rms off its roll samples; the beams fit linear segments far better, log-likelihood -3628 against
    -3813): the samples are then joined linearly. ``interpolation`` (a calibration's, as its runs
    joined the same sensor's samples) takes the place of that choice."""
    from ..models.motion import SampledAttitude

    fit = fit or fit_attitude(case)
    a = case.attitude
    ypr = a.ypr()
    ok = np.all(np.isfinite(ypr), axis=1)
    modes = np.asarray(fit.params.modes)
    band = float(np.max(modes[:, 0])) if modes.size else None
    if interpolation is not None:
        return SampledAttitude(a.time_s[ok], ypr[ok], interpolation=interpolation, band_rad_s=band,
                               reason=("joined linearly" if interpolation == "linear" else "smoothed within the motion band")
                               + ", as the calibration's runs")
    fast = fast_axes(a.time_s[ok], ypr[ok])
    if fast:
        fast = ", ".join(f"{n} {100 * v:.0f} %" for n, v in fast.items())
        return SampledAttitude(a.time_s[ok], ypr[ok], interpolation="linear", band_rad_s=band,
                               reason=f"joined linearly: the samples' variance lies above half their Nyquist frequency "
                                      f"({fast}), where a smoothing spline would cut into the motion")
    return SampledAttitude(a.time_s[ok], ypr[ok], band_rad_s=band)
