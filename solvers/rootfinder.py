"""Per-ping inversion of the bottom-track measurement model for all four beams: the closed
form and the exact root, on all pings at once.

Per ping the unknowns are the vessel velocity V (3) and the error velocity e, and the four
equations are the measurement model the calibration fits
(:func:`adcpdyn.models.measurement.bottom_track_function`, Eqs. 65-70):

    radial_i(V; t_T, depth, attitude model, r, Lambda_st) + e n_i = v_i,   i = 1..4

with n the error-velocity direction (the Janus null vector scaled so that e equals the
instrument's error velocity). Beam directions and tangential velocities at transmit and
at receive, the receive time from the geometry with the transducer moving during the
flight, and the instrument's nonlinear velocity conversion all come from that one model,
so nothing is linearised or taken from the measured radial.

The closed form (ADC) is the model multiplied out at Eq. 68's receive times
(:func:`~adcpdyn.models.measurement.doppler_system_function`, Eq. 89, linear in V) solved by
least squares with the error velocity. It is ~1e-5 m/s from the root: the error velocity's
direction and the travel time differ from the exact model's at O(u/c).

The exact solve starts there, x0 and the closed form's receive times t0, and takes one
Newton step on the model with the receive times as unknowns too: g(x, t_R) = radial(x, t_R)
+ e n - v = 0 and t_R = T(x), the model's own receive times
(:func:`~adcpdyn.models.measurement.echo_function`). At t0 the attitude is already evaluated;
eliminating the receive times leaves (g_x + g_t T_x) dx = -(g + g_t (T(x0) - t0)) (g_t
diagonal: beam i's echo depends on its own receive time), every derivative generated
symbolically from the model's Functions; the exact residual (the attitude at the new
receive times T(x1), by its Taylor polynomial about t0: ``EXPANSION_ORDER``) is evaluated at
the result. The step leaves ~1e-13 m/s in shallow
water; its error grows as the square of t0 - T(x), the closed form's receive times being
~2e-5 s off in 300 m of water, where it leaves up to ~3e-10 m/s: inside the tolerance
``NEWTON_RESIDUAL_TOL`` (1e-9 m/s, six orders below a bottom track's noise), so one step serves
(a second, which took those pings to ~1e-13, cost the exact solve a tenth of its time on
deep_ocean). Pings above the tolerance take Newton steps on arrays (the same formula at t0 = T(x):
Newton's step with its exact Jacobian); pings still above go to ``casadi.rootfinder`` (Newton
with a convergence test); pings it leaves above get NaN.

Each per-ping Function is evaluated over all pings by :class:`~adcpdyn.solvers.ping_map.PingFunction`;
the beams enter already turned into the sensor frame (shared by every ping), so no ping
evaluates the installation rotation. Per ping the exact solve evaluates the attitude five
times (transmit, the closed form's four receive times; at the result's four it is expanded
about the closed form's): its sines, cosines and exponentials are most of its cost.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..models.measurement import ARGUMENTS, bottom_track_expressions, doppler_system_function, echo_function
from ..models.motion import (LOCAL_ATTITUDE_SIZE, AttitudeLayout, attitude_expansion, attitude_function,
                             local_attitude_function)
from ..models.rotations import euler_matrix
from .ping_map import MapOptions, PingFunction

NEWTON_RESIDUAL_TOL = 1e-9  # m/s; pings above it take another Newton step while steps are left, then casadi.rootfinder
N_PING_INPUTS = 6  # t_T, bottom depth, four measured radial velocities
EXPANSION_ORDER = 2  # the attitude at the result's receive times: Taylor polynomial about the closed form's
EXPANSION_MAX_STEP_S = 2e-4  # beyond this from the closed form's receive times, the residual is evaluated without it


@dataclass(frozen=True)
class RootfinderOptions(MapOptions):
    """Settings of the exact per-ping solve (and of its evaluation, :class:`~adcpdyn.solvers.ping_map.MapOptions`).

    Parameters
    ----------
    steps : int
        Newton steps at most before ``casadi.rootfinder`` takes the pings left above
        tolerance: the first from the closed form, the others on the pings it leaves above
        tolerance. 0: the closed form's pings above tolerance go to ``casadi.rootfinder``.
    """

    steps: int = 3

    def __post_init__(self):
        super().__post_init__()
        if self.steps < 0:
            raise ValueError(f"RootfinderOptions.steps: expected >= 0, got {self.steps}")


@dataclass(frozen=True)
class _Model:
    """What fixes the per-ping equations besides the shared parameter column (hashable)."""

    layout: AttitudeLayout | None  # None: the sensor's samples, per-ping attitude data in q
    timing: str
    sound_speed_m_s: float
    error_row: tuple  # e_row . radials = error velocity
    tangential: str = "consistent"

    def n_attitude(self) -> int:
        return 0 if self.layout is None else self.layout.size

    def ping_inputs(self) -> int:
        return N_PING_INPUTS + (LOCAL_ATTITUDE_SIZE if self.layout is None else 0)

    def shared_size(self) -> int:
        return self.n_attitude() + 12 + 12 + 1  # attitude parameters, r (4x3), beams in the sensor frame (4x3), depth of G

    def attitude_function(self) -> ca.Function:
        return local_attitude_function() if self.layout is None else attitude_function(self.layout)

    def error_direction(self) -> ca.DM:
        return ca.DM(error_direction(np.asarray(self.error_row)))

    def symbols(self):
        return ca.SX.sym("q", self.ping_inputs()), ca.SX.sym("s", self.shared_size())

    def arguments(self, q, s) -> dict:
        """The model's arguments from a ping's column q = [t_T, bottom depth, four radials
        (, the ping's sampled attitude)] and the shared column s (:func:`shared_parameters`).

        The beams enter already turned into the sensor frame (Lambda_st b_i, shared by every
        ping) with ypr_st = 0: the same model, without the installation rotation evaluated per ping.
        """
        n_att = self.n_attitude()
        return {"t_T": q[0], "depth": q[1], "radial": q[2:6], "p": q[N_PING_INPUTS:] if self.layout is None else s[:n_att],
                "r": ca.reshape(s[n_att:n_att + 12], 3, 4).T, "ypr_st": ca.DM.zeros(3),
                "beam_dirs_t": ca.reshape(s[n_att + 12:n_att + 24], 3, 4).T, "g_depth": s[-1], "c": self.sound_speed_m_s}


def shared_parameters(attitude_p: np.ndarray, lever_arms_m: np.ndarray, ypr_st_rad, beam_dirs_t, g_depth_m: float) -> np.ndarray:
    """The parameter column shared by every ping: [attitude p, r row by row, Lambda_st b_i row by row, depth of G]."""
    beams_s = np.asarray(beam_dirs_t, dtype=float) @ np.asarray(euler_matrix(*np.asarray(ypr_st_rad, dtype=float))).T
    return np.concatenate([attitude_p, np.asarray(lever_arms_m, dtype=float).ravel(), beams_s.ravel(), [g_depth_m]])


def _residual_expr(model: _Model, x, q, s, receive_attitude=None):
    """The measurement model minus the measured radials (4), m/s, and the model's receive times (4);
    ``receive_attitude`` as in :func:`~adcpdyn.models.measurement.bottom_track_expressions`."""
    a = model.arguments(q, s)
    radial, receive_time = bottom_track_expressions(model.attitude_function(), model.timing, model.tangential,
                                                    _call(a, v_a=x[:3]), receive_attitude)
    return radial + x[3] * model.error_direction() - a["radial"], receive_time


def _call(a: dict, **more) -> list:
    """The model Functions' arguments in order (:data:`~adcpdyn.models.measurement.ARGUMENTS`)."""
    return [{**a, **more}[k] for k in ARGUMENTS]


def _closed_form_expr(model: _Model, q, s):
    """Eq. 89's A (4, 3), b (4,), its receive times and the four-beam least squares x = (V, e)."""
    a = model.arguments(q, s)
    system = doppler_system_function(model.attitude_function(), "shallow" if model.timing == "shallow" else "deep",
                                     model.tangential)
    A, b, t_R = system(*_call(a, v_a=a["radial"]))  # the closed form takes the measured radials where the model takes V
    V = ca.solve(ca.mtimes(A.T, A), ca.mtimes(A.T, b))
    e = ca.dot(b - ca.mtimes(A, V), ca.DM(model.error_row)) / 2  # A ~ 2 d: back to radial units
    return A, b, t_R, ca.vertcat(V, e)


@functools.lru_cache(maxsize=16)
def _residual(model: _Model) -> ca.Function:
    """``g(x (4), q, s) -> residual (4)`` in m/s (see :meth:`_Model.arguments` for q and s)."""
    x = ca.SX.sym("x", 4)
    q, s = model.symbols()
    return ca.Function("bottom_track_residual", [x, q, s], [ca.cse(_residual_expr(model, x, q, s)[0])], ["x", "q", "s"], ["g"])


@functools.lru_cache(maxsize=16)
def _closed_form(model: _Model) -> PingFunction:
    """``(q, s) -> (A row by row (12,), b (4,), x (4,))``."""
    q, s = model.symbols()
    A, b, _, x = _closed_form_expr(model, q, s)
    return PingFunction(ca.Function("bottom_track_closed_form", [q, s], ca.cse([ca.vec(A.T), b, x]), ["q", "s"],
                                    ["A", "b", "x"]))


def _linearised(model: _Model) -> ca.Function:
    """``(x, t_R, q, s) -> (g, dg/dx, dg/dt_R (diagonal), T, dT/dx)``: the residual with the echoes
    received at t_R and the model's own receive times T(x) (:func:`~adcpdyn.models.measurement.echo_function`)."""
    x, t_R = ca.SX.sym("x", 4), ca.SX.sym("t_R", 4)
    q, s = model.symbols()
    a = model.arguments(q, s)
    args = _call(a, v_a=x[:3])
    echo = echo_function(model.attitude_function(), model.timing, model.tangential)
    radial, receive_time = echo(args[0], t_R, *args[1:])[:2]
    g = radial + x[3] * model.error_direction() - a["radial"]
    return ca.Function("linearised", [x, t_R, q, s],
                       [g, ca.jacobian(g, x), ca.jacobian(g, t_R), receive_time, ca.jacobian(receive_time, x)])


def _newton_step(model: _Model, x0, t0, q, s):
    """The Newton step of g(x, t_R) = 0, t_R = T(x) from (x0, t0), the receive times eliminated:
    x0 - (g_x + g_t T_x)^-1 (g + g_t (T(x0) - t0)). With t0 = T(x0) it is Newton's step on the
    residual with its exact Jacobian, the receive times' dependence on x by the chain rule."""
    g, g_x, g_t, T, T_x = _linearised(model)(x0, t0, q, s)
    return x0 - ca.solve(g_x + ca.mtimes(g_t, T_x), g + ca.mtimes(g_t, T - t0))


@functools.lru_cache(maxsize=16)
def _exact(model: _Model) -> PingFunction:
    """``(q, s) -> (x (4,), residual (4,), step (1,))``: the closed form, one Newton step from it with
    its receive times (module docstring), the residual at the result, and the largest distance
    (s) of the result's receive times from the closed form's.

    The residual takes the attitude at the result's receive times as its second-order Taylor
    polynomial about the closed form's (:func:`~adcpdyn.models.motion.attitude_expansion`), where
    the attitude is already evaluated: a remainder below |d^3 Lambda/dt^3| step^3 / 6, 1.3e-12 per
    rad/s^3 at ``EXPANSION_MAX_STEP_S`` (the step is ~2e-5 s in 300 m of water);
    pings farther get the residual evaluated at their receive times (:func:`solve_bottom_track`).
    """
    q, s = model.symbols()
    _, _, t0, x0 = _closed_form_expr(model, q, s)
    x1 = _newton_step(model, x0, t0, q, s)
    p = model.arguments(q, s)["p"]
    about = [attitude_expansion(model.attitude_function(), t0[i], p, EXPANSION_ORDER) for i in range(4)]
    g, receive_time = _residual_expr(model, x1, q, s, lambda i, t: about[i](t))
    step = ca.mmax(ca.fabs(receive_time - t0))
    return PingFunction(ca.Function("bottom_track_exact", [q, s], ca.cse([x1, g, step]), ["q", "s"], ["x", "g", "step"]))


@functools.lru_cache(maxsize=16)
def _newton(model: _Model) -> PingFunction:
    """``(x, q, s) -> (x - J^-1 g (4,), the residual there (4,))``: Newton's step."""
    x = ca.SX.sym("x", 4)
    q, s = model.symbols()
    T = _linearised(model)(x, ca.SX.zeros(4), q, s)[3]  # the model's receive times do not depend on t_R
    x1 = _newton_step(model, x, T, q, s)
    return PingFunction(ca.Function("bottom_track_newton", [x, q, s], ca.cse([x1, _residual_expr(model, x1, q, s)[0]]),
                                    ["x", "q", "s"], ["x_next", "g"]))


@functools.lru_cache(maxsize=16)
def _residual_mapped(model: _Model) -> PingFunction:
    return PingFunction(_residual(model))


@functools.lru_cache(maxsize=16)
def _fallback(model: _Model, n: int) -> ca.Function:
    """casadi.rootfinder (Newton with a convergence test) on the same residual, mapped."""
    rf = ca.rootfinder("bottom_track_rootfinder", "newton", _residual(model), {"abstol": 1e-12, "max_iter": 30})
    return rf.map(n)


def _inputs(layout, attitude_p, lever_arms_m, ypr_st_rad, beam_dirs_t, g_depth_m, time_s, depth_m, radial_m_s,
            ping_attitude):
    """Per-ping rows q (N, k) and the shared column s."""
    columns = [np.asarray(time_s, dtype=float)[:, None], np.asarray(depth_m, dtype=float)[:, None],
               np.asarray(radial_m_s, dtype=float)]
    if layout is None:
        columns.append(np.asarray(ping_attitude, dtype=float).T)
    return np.hstack(columns), shared_parameters(np.asarray(attitude_p, dtype=float), lever_arms_m, ypr_st_rad,
                                                  beam_dirs_t, g_depth_m)


def closed_form_bottom_track(layout: AttitudeLayout | None, attitude_p, lever_arms_m, ypr_st_rad, g_depth_m: float,
                             time_s, depth_m, radial_m_s, sound_speed_m_s: float, beam_dirs_t, error_row,
                             timing: str = "deep", tangential: str = "consistent", options: MapOptions | None = None,
                             ping_attitude=None) -> dict:
    """Eq. 89 for every ping: A (N, 4, 3), b (N, 4) and the four-beam least squares V (N, 3),
    e (N,) (NaN where a radial is missing; its beam's row of A and b is NaN too).

    Arguments as :func:`solve_bottom_track`; ``timing`` ``exact`` is taken as ``deep`` (Eq. 68's
    receive time), ``tangential`` ``paper_literal`` takes Omega r for the tangential velocity.
    """
    model = _Model(layout, "shallow" if timing == "shallow" else "deep", float(sound_speed_m_s),
                   tuple(np.asarray(error_row, dtype=float).ravel()), tangential)
    q, s = _inputs(layout, attitude_p, lever_arms_m, ypr_st_rad, beam_dirs_t, g_depth_m, time_s, depth_m, radial_m_s,
                   ping_attitude)
    A, b, x = _closed_form(model)(q, s, options=options)
    return {"A": A.reshape(-1, 4, 3), "b": b, "V": x[:, :3], "e": x[:, 3]}


def solve_bottom_track(layout: AttitudeLayout | None, attitude_p, lever_arms_m, ypr_st_rad, g_depth_m: float,
                       time_s, depth_m, radial_m_s, sound_speed_m_s: float, beam_dirs_t, error_row,
                       timing: str = "deep", options: RootfinderOptions | None = None, ping_attitude=None) -> dict:
    """The exact root for pings with four beams: vessel velocity V (N, 3), error velocity e (N,),
    the final residual (N,) and how the pings converged.

    ``attitude_p`` packs the attitude model of the sensor frame (``layout`` None: the sensor's
    samples instead, ``ping_attitude`` (8, N) from :meth:`~adcpdyn.models.motion.SampledAttitude.params_at`
    at the ping times, ``attitude_p`` empty), ``lever_arms_m`` (4, 3) are in that frame and
    ``ypr_st_rad`` turns the transducer frame into it; ``g_depth_m`` is the depth of the centre
    of rotation; ``error_row`` (4,) gives the error velocity from the four radials.

    Returned counts: ``newton_pings`` that took more than the first Newton step,
    ``fallback_pings`` handed to ``casadi.rootfinder`` and ``unconverged_pings`` whose residual
    stayed above ``NEWTON_RESIDUAL_TOL`` (their V and e are NaN, their residual says by how much).
    """
    options = options or RootfinderOptions()
    model = _Model(layout, timing, float(sound_speed_m_s), tuple(np.asarray(error_row, dtype=float).ravel()))
    q, s = _inputs(layout, attitude_p, lever_arms_m, ypr_st_rad, beam_dirs_t, g_depth_m, time_s, depth_m, radial_m_s,
                   ping_attitude)
    norm = lambda g: np.max(np.abs(g), axis=1)  # NaN stays NaN (CasADi's norm_inf would drop it)
    if options.steps == 0:
        x = _closed_form(model)(q, s, options=options)[2]
        res = norm(_residual_mapped(model)(x, q, s, options=options)[0])
    else:
        x, g, step = _exact(model)(q, s, options=options)
        res = norm(g)
        far = np.flatnonzero(~(step[:, 0] <= EXPANSION_MAX_STEP_S))
        if far.size:
            res[far] = norm(_residual_mapped(model)(x[far], q[far], s, options=options)[0])
    above = lambda r, tol: ~(r <= tol)  # NaN counts as above
    more = np.flatnonzero(above(res, NEWTON_RESIDUAL_TOL)) if options.steps > 1 else np.zeros(0, dtype=int)
    todo = more
    for _ in range(options.steps - 1):
        if not todo.size:
            break
        x[todo], g = _newton(model)(x[todo], q[todo], s, options=options)
        res[todo] = norm(g)
        todo = todo[above(res[todo], NEWTON_RESIDUAL_TOL)]
    todo = np.flatnonzero(above(res, NEWTON_RESIDUAL_TOL))
    if todo.size:
        x0 = np.nan_to_num(x[todo]).T
        x[todo] = np.asarray(_fallback(model, todo.size)(x0, q[todo].T, s)).T
        res[todo] = norm(_residual_mapped(model)(x[todo], q[todo], s, options=options)[0])
    bad = above(res, NEWTON_RESIDUAL_TOL)
    x[bad] = np.nan
    return {"V": x[:, :3], "e": x[:, 3], "residual": res, "newton_pings": int(more.size),
            "fallback_pings": int(todo.size), "unconverged_pings": int(bad.sum())}


def error_direction(e_row: np.ndarray) -> np.ndarray:
    """Direction n with e_row . (e n) = e: radial residuals of pure error velocity e."""
    return e_row / np.dot(e_row, e_row)
