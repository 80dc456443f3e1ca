"""Exact per-ping inversion of the bottom-track measurement model for all four beams.

Per ping the unknowns are the vessel velocity V (3) and the error velocity e, and the four
equations are the measurement model the calibration fits
(:func:`adcpdyn.models.measurement.bottom_track_function`, Eqs. 65-70):

    radial_i(V; t_T, depth, attitude model, r, Lambda_st) + e n_i = v_i,   i = 1..4

with n the error-velocity direction (the Janus null vector scaled so that e equals the
instrument's error velocity). Beam directions and tangential velocities at transmit and
at receive, the receive time from the geometry with the transducer moving during the
flight, and the instrument's nonlinear velocity conversion all come from that one model,
so nothing is linearised or taken from the measured radial.

The solve is one SX expression per ping: a Newton step from V = 0, e = 0, then ``steps``
chord steps (Newton with that first Jacobian kept: it differs from the Jacobian at the
solution by O(u/c) ~ 1e-3, so each step gains about three digits at a third of the
cost of a Newton step), and the final residual; mapped over pings
on threads and compiled to machine code when the run is long enough to repay the
compiler (CasADi ``jit``). Pings whose residual stays above tolerance are handed to
``casadi.rootfinder`` (Newton with a convergence test) on the same residual.
"""

from __future__ import annotations

import functools
import shutil
import tempfile
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..models.measurement import bottom_track_function
from ..models.motion import LOCAL_ATTITUDE_SIZE, AttitudeLayout, attitude_function, local_attitude_function

NEWTON_RESIDUAL_TOL = 1e-9  # m/s; pings above it go to casadi.rootfinder
CHUNK = 16384  # pings per mapped call (the map is built once per chunk size)
N_PING_INPUTS = 6  # t_T, bottom depth, four measured radial velocities


@dataclass(frozen=True)
class RootfinderOptions:
    """Settings of the exact per-ping solve.

    Parameters
    ----------
    steps : int
        Chord steps after the first Newton step; the error falls about three digits per
        step from ~1e-3 m/s.
    threads : int
        Threads evaluating the mapped solve.
    compile : str
        ``auto`` (compile with the system C compiler when there are at least
        ``compile_min_pings`` pings and a compiler is found), ``always`` or ``never``.
    compile_min_pings : int
        Below this the interpreted solve finishes before the compiler would (~5 s).
    """

    steps: int = 2
    threads: int = 2
    compile: str = "auto"
    compile_min_pings: int = 100_000

    def __post_init__(self):
        if self.compile not in ("auto", "always", "never"):
            raise ValueError(f"RootfinderOptions.compile: expected 'auto', 'always' or 'never', got {self.compile!r}")
        if self.steps < 0:
            raise ValueError(f"RootfinderOptions.steps: expected >= 0, got {self.steps}")

    def compiled(self, n_pings: int) -> bool:
        if self.compile == "never" or shutil.which("gcc") is None:
            return False
        return self.compile == "always" or n_pings >= self.compile_min_pings


@dataclass(frozen=True)
class _Model:
    """What fixes the per-ping equations besides the shared parameter vector (hashable)."""

    layout: AttitudeLayout | None  # None: the sensor's samples, per-ping attitude data in q
    timing: str
    sound_speed_m_s: float
    beam_dirs_t: tuple
    error_direction: tuple

    def n_attitude(self) -> int:
        return 0 if self.layout is None else self.layout.size

    def ping_inputs(self) -> int:
        return N_PING_INPUTS + (LOCAL_ATTITUDE_SIZE if self.layout is None else 0)

    def shared_size(self) -> int:
        return self.n_attitude() + 12 + 3 + 1  # attitude parameters, r (4x3), Lambda_st angles, depth of G


def shared_parameters(attitude_p: np.ndarray, lever_arms_m: np.ndarray, ypr_st_rad, g_depth_m: float) -> np.ndarray:
    """The parameter column shared by every ping: [attitude p, r row by row, ypr_st, depth of G]."""
    return np.concatenate([attitude_p, np.asarray(lever_arms_m, dtype=float).ravel(),
                           np.asarray(ypr_st_rad, dtype=float), [g_depth_m]])


@functools.lru_cache(maxsize=16)
def _residual(model: _Model) -> ca.Function:
    """``g(x (4), q, s) -> residual (4)`` in m/s: the measurement model minus the measured radials.

    q = [t_T, bottom depth, four radials] (+ the ping's sampled attitude when ``model.layout`` is None)."""
    sampled = model.layout is None
    bt = bottom_track_function(local_attitude_function() if sampled else attitude_function(model.layout), model.timing)
    x = ca.SX.sym("x", 4)
    q = ca.SX.sym("q", model.ping_inputs())
    s = ca.SX.sym("s", model.shared_size())
    n_att = model.n_attitude()
    r = ca.reshape(s[n_att:n_att + 12], 3, 4).T  # row-major (4, 3)
    p_att = q[N_PING_INPUTS:] if sampled else s[:n_att]
    radial, _ = bt(q[0], q[1], s[-1], model.sound_speed_m_s, x[:3], p_att, r, s[n_att + 12:n_att + 15],
                   ca.DM(np.reshape(model.beam_dirs_t, (4, 3))))
    g = radial + x[3] * ca.DM(model.error_direction) - q[2:6]
    return ca.Function("bottom_track_residual", [x, q, s], [g], ["x", "q", "s"], ["g"])


@functools.lru_cache(maxsize=16)
def _newton(model: _Model, steps: int, compiled: bool) -> ca.Function:
    """``solve(q (6), s) -> (x (4), |residual|_inf)``: the chord iteration unrolled into one SX expression."""
    g = _residual(model)
    x = ca.SX.sym("x", 4)
    q = ca.SX.sym("q", model.ping_inputs())
    s = ca.SX.sym("s", model.shared_size())
    gj = ca.Function("residual_and_jacobian", [x, q, s], [g(x, q, s), ca.jacobian(g(x, q, s), x)])
    g0, j0 = gj(ca.SX.zeros(4), q, s)
    j0_inv = ca.inv(j0)
    xk = -ca.mtimes(j0_inv, g0)
    for _ in range(steps):
        xk = xk - ca.mtimes(j0_inv, g(xk, q, s))
    outputs = ca.cse([xk, ca.norm_inf(g(xk, q, s))])
    opts = {}
    if compiled:
        opts = {"jit": True, "compiler": "shell", "jit_temp_suffix": True,
                "jit_options": {"flags": ["-O2"], "verbose": False, "directory": tempfile.gettempdir() + "/"}}
    return ca.Function("bottom_track_newton", [q, s], outputs, ["q", "s"], ["x", "residual"], opts)


@functools.lru_cache(maxsize=16)
def _mapped(model: _Model, steps: int, compiled: bool, n: int, threads: int) -> ca.Function:
    f = _newton(model, steps, compiled)
    return f.map(n, "thread", threads) if threads > 1 else f.map(n)


@functools.lru_cache(maxsize=16)
def _fallback(model: _Model, n: int) -> ca.Function:
    """casadi.rootfinder (Newton with a convergence test) on the same residual, mapped."""
    rf = ca.rootfinder("bottom_track_rootfinder", "newton", _residual(model), {"abstol": 1e-12, "max_iter": 30})
    return rf.map(n)


def solve_bottom_track(layout: AttitudeLayout | None, attitude_p, lever_arms_m, ypr_st_rad, g_depth_m: float,
                       time_s, depth_m, radial_m_s, sound_speed_m_s: float, beam_dirs_t, error_direction,
                       timing: str = "deep", options: RootfinderOptions | None = None, ping_attitude=None):
    """Vessel velocity (N, 3), error velocity (N,), final residual (N,) and how many pings went to
    ``casadi.rootfinder``, for pings with four beams.

    ``attitude_p`` packs the attitude model of the sensor frame (``layout`` None: the sensor's
    samples instead, ``ping_attitude`` (8, N) from :meth:`~adcpdyn.models.motion.SampledAttitude.params_at`
    at the ping times, ``attitude_p`` empty), ``lever_arms_m`` (4, 3)
    are in that frame and ``ypr_st_rad`` turns the transducer frame into it; ``g_depth_m``
    is the depth of the centre of rotation. Pings whose residual stays above
    ``NEWTON_RESIDUAL_TOL`` after ``casadi.rootfinder`` get NaN (their residual says why).
    """
    options = options or RootfinderOptions()
    model = _Model(layout, timing, float(sound_speed_m_s), tuple(np.asarray(beam_dirs_t, dtype=float).ravel()),
                   tuple(np.asarray(error_direction, dtype=float).ravel()))
    q = np.vstack([np.asarray(time_s, dtype=float), np.asarray(depth_m, dtype=float),
                   np.asarray(radial_m_s, dtype=float).T] + ([] if layout is not None else [np.asarray(ping_attitude, dtype=float)]))
    s = shared_parameters(np.asarray(attitude_p, dtype=float), lever_arms_m, ypr_st_rad, g_depth_m)
    n = q.shape[1]
    size = min(n, CHUNK)
    solve = _mapped(model, options.steps, options.compiled(n), size, options.threads)
    x = np.empty((4, n))
    res = np.empty(n)
    for start in range(0, n, size):
        block = q[:, start:start + size]
        m = block.shape[1]
        padded = np.pad(block, ((0, 0), (0, size - m)), mode="edge")
        xb, rb = solve(padded, s)
        x[:, start:start + m] = np.asarray(xb)[:, :m]
        res[start:start + m] = np.asarray(rb).ravel()[:m]
    slow = np.flatnonzero(~(res <= NEWTON_RESIDUAL_TOL))  # not converged in the fixed steps (or NaN)
    if slow.size:
        x0 = np.nan_to_num(x[:, slow])
        x[:, slow] = np.asarray(_fallback(model, slow.size)(x0, q[:, slow], s))
        g = _residual(model).map(slow.size)(x[:, slow], q[:, slow], s)
        res[slow] = np.max(np.abs(np.asarray(g)), axis=0)
        bad = slow[~(res[slow] <= NEWTON_RESIDUAL_TOL)]
        x[:, bad] = np.nan
    return x[:3].T, x[3], res, int(slow.size)


def error_direction(e_row: np.ndarray) -> np.ndarray:
    """Direction n with e_row . (e n) = e: radial residuals of pure error velocity e."""
    return e_row / np.dot(e_row, e_row)
