"""Per-ping bottom-track measurement model as one CasADi Function (Eqs. 49-52, 65-70).

The attitude model here is that of the *sensor frame* s: the vessel when the sensor
is aligned with it, the ADCP head when the sensor sits inside it. Lever arms r_i are
expressed in that frame and Lambda_st maps the transducer frame into it (Lambda_tb
for a vessel-frame sensor, the identity for a head sensor). Then the beams point along
Lambda_s Lambda_st b_i and the Earth tangential velocity is dLambda_s/dt r_i, whichever
frame the sensor is in, because Lambda_tb is constant.

``timing``:
* ``shallow``: V_Ti(t_T) . d_i(t_T) (Eq. 52) -- the round trip is instantaneous;
* ``deep``: receive time from the geometry at transmit (Eqs. 66-68), the two-way
  ratio (c + u(t_R)) / (c - u(t_T)) (Eq. 70) turned into a radial velocity with the
  instrument's formula (Eq. 65). The vessel velocity is taken constant over the
  ping, as the paper assumes.
* ``exact``: as ``deep``, but the travel time solved exactly with the transducer moving
  during the flight: out along the beam to the bottom spot S (distance l), back to
  where the transducer is at t_R, |T(t_R) - S| = c (t_R - t_T) - l, by fixed-point
  iteration (each gains a factor u/c ~ 1e-3; ``EXACT_TIME_ITERATIONS``), with
  T(t) = G(t_T) + V (t - t_T) + Lambda(t) r. Range = c (t_R - t_T) / 2.

Range and receive time include, to first order in u/c, the transducer moving along
the beam during the flight (the echo returns to where the transducer has gone): the
instrument's range c (t_R - t_T) / 2 is l (1 - u / c), not the l of Eq. 67, a
difference of ~1 cm in 14 m at 1 m/s that otherwise biases installation pitch.
"""

from __future__ import annotations

import casadi as ca

from .doppler import bottom_echo_ratio, radial_from_ratio, ratio_from_radial, receive_time_paper, reported_range, slant_range
from .kinematics import beam_directions_earth, tangential_velocity_paper_literal, transducer_velocity_earth
from .rotations import euler_matrix

TIMINGS = ("shallow", "deep", "exact")
EXACT_TIME_ITERATIONS = 4  # from t_R = t_T + 2 l / c: error ~ (u/c)^k of the flight time
TANGENTIALS = ("consistent", "paper_literal")


def bottom_track_function(attitude_fun: ca.Function, timing: str, tangential: str = "consistent") -> ca.Function:
    """``bt(t_T, depth, g_depth, c, v_a, p, r, ypr_st, beam_dirs_t) -> (radial (4,), range (4,))``.

    depth is the bottom depth, g_depth the depth of the centre of rotation G, both
    positive down from the surface; r is (4, 3) lever arms in the sensor frame.
    ``tangential="paper_literal"`` uses Omega r as printed in Eqs. 31/51 (frames mixed;
    for reproducing the paper only).
    """
    args = _symbols(attitude_fun)
    echo = _echo(attitude_fun, timing, tangential, *args)
    return ca.Function(f"bottom_track_{timing}_{tangential}", list(args), [echo["radial"], echo["range"]],
                       list(ARGUMENTS), ["radial", "range"])


def bottom_track_expressions(attitude_fun: ca.Function, timing: str, tangential: str, arguments: list,
                             receive_attitude=None):
    """:func:`bottom_track_function`'s radial (4,) and its receive times (4,) as expressions of
    ``arguments`` (in :data:`ARGUMENTS`' order). ``receive_attitude(i, t)``, if given, is the
    attitude at beam i's receive time t in place of ``attitude_fun(t, p)`` (e.g. an expansion
    about a time where it is already evaluated, :func:`~adcpdyn.models.motion.attitude_expansion`)."""
    echo = _echo(attitude_fun, timing, tangential, *arguments, receive_attitude=receive_attitude)
    return echo["radial"], echo["receive_time"]


def echo_function(attitude_fun: ca.Function, timing: str, tangential: str = "consistent") -> ca.Function:
    """The model of :func:`bottom_track_function` with each beam's echo received at a given time:
    ``echo(t_T, t_R (4,), depth, g_depth, c, v_a, p, r, ypr_st, beam_dirs_t) -> (radial (4,),
    receive_time (4,), u_tx (4,), u_rx (4,), slant_range (4,))``.

    radial is the measured radial velocity with beam i's echo received at t_R[i] (``shallow``:
    not received, Eq. 52); receive_time the model's own receive times (t_T for ``shallow``),
    with which radial is :func:`bottom_track_function`'s; u_tx, u_rx the transducer velocities
    along the beam at transmit and at t_R; slant_range the distance out to the bottom (Eq. 67).
    Separating the receive times lets a solver treat them as unknowns (the radial's dependence
    on the vessel velocity through the travel time is then explicit) and lets the closed form
    put its own receive times in (:func:`doppler_system_function`).
    """
    args = _symbols(attitude_fun)
    t_R = ca.SX.sym("t_R", 4)
    echo = _echo(attitude_fun, timing, tangential, *args, receive_at=t_R)
    names = ["radial", "receive_time", "u_tx", "u_rx", "slant_range"]
    return ca.Function(f"echo_{timing}_{tangential}", [args[0], t_R, *args[1:]], [echo[k] for k in names],
                       [ARGUMENTS[0], "t_R", *ARGUMENTS[1:]], names)


def doppler_system_function(attitude_fun: ca.Function, timing: str, tangential: str = "consistent") -> ca.Function:
    """The two-way Doppler equation multiplied out, linear in the vessel velocity (Eq. 89):
    ``system(t_T, depth, g_depth, c, radial (4,), p, r, ypr_st, beam_dirs_t) -> (A (4, 3), b (4,), t_R (4,))``
    with rows V_a . (d_R + rho d_T) = (rho - 1) c - (u_R + rho u_T), rho = f / f0 from the
    measured ``radial`` (Eq. 84) and u_T, u_R the tangential velocities along the beam.

    The echo is received at Eq. 68's time with the measured radial in the reported range
    (``deep``) or at transmit (``shallow``): what the closed-form correction can know without
    solving for V_a. A and b come from :func:`echo_function`'s along-beam velocities, so they are
    the measurement model's at those receive times, not a second derivation of it.
    """
    if timing not in ("shallow", "deep"):
        raise ValueError(f"timing: expected 'shallow' or 'deep' for the closed form, got {timing!r}")
    t_T, depth, g_depth, c, v_a, p, r, ypr_st, b_t = _symbols(attitude_fun)
    radial = ca.SX.sym("radial", 4)
    t_R = ca.SX.sym("t_R", 4)
    echo = _echo(attitude_fun, timing, tangential, t_T, depth, g_depth, c, v_a, p, r, ypr_st, b_t, receive_at=t_R)
    rho = ratio_from_radial(radial, c)
    along = echo["u_rx"] + rho * echo["u_tx"]  # affine in v_a
    A = ca.jacobian(along, v_a)
    b = (rho - 1) * c - ca.substitute(along, v_a, ca.SX.zeros(3))
    if timing == "shallow":
        at = ca.repmat(t_T, 4, 1)
    else:
        at = receive_time_paper(t_T, reported_range(echo["slant_range"], radial, c), c)  # Eq. 68
    A, b = ca.substitute([A, b], [t_R], [at])
    return ca.Function(f"doppler_system_{timing}_{tangential}", [t_T, depth, g_depth, c, radial, p, r, ypr_st, b_t],
                       [A, b, at], ["t_T", "depth", "g_depth", "c", "radial", "p", "r", "ypr_st", "beam_dirs_t"],
                       ["A", "b", "t_R"])


ARGUMENTS = ("t_T", "depth", "g_depth", "c", "v_a", "p", "r", "ypr_st", "beam_dirs_t")


def _symbols(attitude_fun: ca.Function):
    return (ca.SX.sym("t_T"), ca.SX.sym("depth"), ca.SX.sym("g_depth"), ca.SX.sym("c"), ca.SX.sym("v_a", 3),
            ca.SX.sym("p", attitude_fun.size_in(1)), ca.SX.sym("r", 4, 3), ca.SX.sym("ypr_st", 3),
            ca.SX.sym("beam_dirs_t", 4, 3))


def _echo(attitude_fun, timing, tangential, t_T, depth, g_depth, c, v_a, p, r, ypr_st, b_t, receive_at=None,
          receive_attitude=None) -> dict:
    """The model's expressions for one ping (see :func:`bottom_track_function`), each beam's echo
    received at the model's own time or, given ``receive_at`` (4,), at that time.

    ``receive_attitude(i, t)``, if given, is the attitude (``attitude_fun``'s outputs) at beam i's
    receive time t, in place of ``attitude_fun(t, p)``: an expansion about a nearby time where it
    is already known (:func:`~adcpdyn.models.motion.attitude_expansion`)."""
    attitude_at = receive_attitude or (lambda i, t: attitude_fun(t, p))
    if timing not in TIMINGS:
        raise ValueError(f"timing: expected one of {list(TIMINGS)}, got {timing!r}")
    if tangential not in TANGENTIALS:
        raise ValueError(f"tangential: expected one of {list(TANGENTIALS)}, got {tangential!r}")
    Lst = euler_matrix(ypr_st[0], ypr_st[1], ypr_st[2])

    def state(t, attitude=None):
        _, Lam, _, Omega, omega = attitude or attitude_fun(t, p)
        d = beam_directions_earth(Lam, Lst, b_t)  # Eqs. 26-29
        if tangential == "consistent":
            v = transducer_velocity_earth(Lam, omega, r, v_a)  # Eq. 24
        else:
            v = tangential_velocity_paper_literal(Omega, r) + ca.repmat(v_a.T, 4, 1)  # Eqs. 31, 49
        z = g_depth + ca.mtimes(r, Lam[2, :].T)  # depth of each transducer (Eq. 66)
        return d, v, z, Lam

    def received(i, t):
        d_R, v_R, _, _ = state(t, attitude_at(i, t))
        return ca.dot(v_R[i, :], d_R[i, :])

    d_T, v_T, z_T, Lam_T = state(t_T)
    u_tx = ca.sum2(v_T * d_T)
    l_out = slant_range(depth, z_T, d_T[:, 2])  # Eq. 67: transmit point to the bottom spot
    l = reported_range(l_out, u_tx, c)  # the transducer moves along the beam during the flight
    out = {"u_tx": u_tx, "slant_range": l_out, "receive_time": ca.repmat(t_T, 4, 1)}
    if timing == "shallow":
        radial = u_tx  # Eq. 52 in instrument sign
        if receive_at is not None:
            out["u_rx"] = ca.vertcat(*[received(i, receive_at[i]) for i in range(4)])
    else:
        parts, ranges, times, u_rxs = [], [], [], []
        for i in range(4):
            t_R = receive_time_paper(t_T, l[i], c)  # Eq. 68
            if timing == "exact":  # positions relative to G(t_T)
                spot = ca.mtimes(Lam_T, r[i, :].T) + l_out[i] * d_T[i, :].T
                for _ in range(EXACT_TIME_ITERATIONS):
                    Lam_R = attitude_at(i, t_R)[1]
                    back = ca.norm_2(spot - (v_a * (t_R - t_T) + ca.mtimes(Lam_R, r[i, :].T)))
                    t_R = t_T + (l_out[i] + back) / c
                ranges.append(c * (t_R - t_T) / 2)
            times.append(t_R)
            u_rx = received(i, t_R if receive_at is None else receive_at[i])
            u_rxs.append(u_rx)
            parts.append(radial_from_ratio(bottom_echo_ratio(u_tx[i], u_rx, c), c))  # Eqs. 70, 65
        radial = ca.vertcat(*parts)
        if timing == "exact":
            l = ca.vertcat(*ranges)
        out.update(receive_time=ca.vertcat(*times), u_rx=ca.vertcat(*u_rxs))
    out.update(radial=radial, range=l)
    return out
