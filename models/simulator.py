"""The simulator's physics: kinematics and echoes of a scenario's run, exactly.

:func:`adcpdyn.cases.simulation.simulate` turns a scenario and a seed into a case with these.
It evaluates the same CasADi models the estimators use, but never their shortcuts:
each beam's echo is formed at its own transmit and receive times with the
transducer moving and turning during the flight, the receive time solved exactly
(fixed point of |T(t_R) - S| = c (t_R - t_T) - l), the vessel velocity taken at
both times, the true sound speed for the physics and the instrument's for the
frequency-to-velocity conversion, and attitude sampled by a sensor with its own
times, frame, noise and resolution. The modelling choices that the paper leaves
open are fields of :class:`~adcpdyn.cases.scenario.DopplerModel`.
"""

from __future__ import annotations

import numpy as np

from .doppler import receive_time_paper, slant_range
from .effects import Effect
from .janus import janus_beam_directions, janus_transducer_positions
from .kinematics import centre_of_rotation_depth, radius_vectors, transducer_state_function
from .motion import attitude_function, stack_matrices
from .navigation import Track

FIXED_POINT_ITERATIONS = 8


class Kinematics:
    """Numeric evaluation of the symbolic kinematics for one scenario."""

    def __init__(self, scenario, effects=()):
        pf, run = scenario.platform, scenario.run
        self.effects = effects
        self.params = run.motion
        self.p = run.motion.pack()
        self.attitude = attitude_function(run.motion.layout)
        self.state = transducer_state_function(self.attitude)
        self.beam_dirs_t = np.asarray(janus_beam_directions(pf.instrument.beam_angle_rad))
        self.pos_t = np.asarray(janus_transducer_positions(pf.instrument.transducer_radius_m))
        self.installation_ypr = np.asarray(pf.mounting.installation_ypr_rad, dtype=float)
        self.radius_vectors = np.asarray(
            radius_vectors(self.installation_ypr, np.asarray(pf.mounting.centre_body_m, dtype=float), self.pos_t)
        )
        trend = run.motion.yaw_trend
        t_ref = run.motion.t_ref_s
        self.heading_trend = lambda t: np.polynomial.polynomial.polyval(np.asarray(t) - t_ref, trend)
        g_depth = centre_of_rotation_depth(run.transducer_depth_m, self.radius_vectors)
        self.track = Track.integrate(run.navigation, run.t_start_s, run.t_start_s + run.duration_s, g_depth,
                                     self.heading_trend)
        self.navigation = run.navigation

    def at(self, times) -> dict[str, np.ndarray]:
        """Kinematics at times of any shape S: matrices (S,3,3), per-beam rows (S,4,3)."""
        times = np.asarray(times, dtype=float)
        flat = times.reshape(-1)
        n = flat.size
        Lam, dLam, d, v_tan, rot = self.state.map(n)(flat[None, :], self.p, self.radius_vectors,
                                                      self.installation_ypr, self.beam_dirs_t)
        beams = lambda m: np.asarray(m).reshape(4, n, 3).transpose(1, 0, 2).reshape(times.shape + (4, 3))
        mats = lambda m: stack_matrices(m, n).reshape(times.shape + (3, 3))
        v_a = self.navigation.velocity(flat, self.heading_trend)
        G = self.track.position(flat)
        for effect, params in self.effects:  # effects that move G (surge, heave)
            dv = effect.vessel_velocity_offset(flat, self.heading_trend(flat), params)
            dG = effect.g_position_offset(flat, params)
            v_a = v_a if dv is None else v_a + dv
            G = G if dG is None else G + dG
        v_a, G = v_a.reshape(times.shape + (3,)), G.reshape(times.shape + (3,))
        return {
            "Lambda": mats(Lam),
            "dLambda_dt": mats(dLam),
            "d": beams(d),
            "position": beams(rot) + G[..., None, :],
            "velocity": beams(v_tan) + v_a[..., None, :],
            "vessel_velocity": v_a,
            "G": G,
        }


def _pick_beam(per_beam: np.ndarray, beam: np.ndarray) -> np.ndarray:
    """From (..., 4, 3) rows take beam[...]'s row -> (..., 3)."""
    return np.take_along_axis(per_beam, beam[..., None, None], axis=-2)[..., 0, :]


def echo_geometry(kin: Kinematics, scenario, t_T, tx, target_depth, c_true):
    """Transmit/receive geometry and velocities of every (ping, beam[, cell]) echo.

    t_T (N,), tx = kinematics at t_T, target_depth broadcastable to (N, 4, ...).
    Returns u_tx, u_rx, e_tx, e_rx, t_R, slant range l (all (N, 4, ...)).
    """
    dm = scenario.run.doppler
    target_depth = np.asarray(target_depth, dtype=float)
    extra = target_depth.shape[2:] if target_depth.ndim > 2 else ()
    expand = lambda a: a.reshape(a.shape + (1,) * len(extra))
    pos_T = tx["position"]  # (N,4,3)
    d_T = tx["d"]
    vel_T = tx["velocity"]
    l = slant_range(target_depth, expand(pos_T[..., 2]), expand(d_T[..., 2]))  # Eqs. 67, 86
    shape = np.broadcast_shapes(l.shape, (t_T.size, 4) + extra)
    l = np.broadcast_to(l, shape)
    e_tx = np.broadcast_to(d_T.reshape(d_T.shape[:2] + (1,) * len(extra) + (3,)), shape + (3,))
    v_tx = np.broadcast_to(vel_T.reshape(vel_T.shape[:2] + (1,) * len(extra) + (3,)), shape + (3,))
    u_tx = np.sum(v_tx * e_tx, axis=-1)
    t_R = receive_time_paper(np.broadcast_to(expand(t_T[:, None] * np.ones((1, 4))), shape), l, c_true)  # Eq. 68, then exact
    if dm.timing == "instantaneous":
        return u_tx, u_tx.copy(), e_tx, e_tx.copy(), t_R, l
    spot = np.broadcast_to(pos_T.reshape(pos_T.shape[:2] + (1,) * len(extra) + (3,)), shape + (3,)) + l[..., None] * e_tx
    beam = np.broadcast_to(expand(np.arange(4)[None, :] * np.ones((t_T.size, 1), dtype=int)), shape)
    t_send = np.broadcast_to(expand(t_T[:, None] * np.ones((1, 4))), shape)
    iterations = FIXED_POINT_ITERATIONS if dm.travel_time == "exact" else 0
    for _ in range(iterations):
        rx = kin.at(t_R)
        back = np.linalg.norm(spot - _pick_beam(rx["position"], beam), axis=-1)
        t_R = t_send + (l + back) / c_true
    rx = kin.at(t_R)
    if dm.receive_direction == "beam_axis":
        e_rx = _pick_beam(rx["d"], beam)
    else:
        ray = spot - _pick_beam(rx["position"], beam)
        e_rx = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
    u_rx = np.sum(_pick_beam(rx["velocity"], beam) * e_rx, axis=-1)
    return u_tx, u_rx, e_tx, e_rx, t_R, l


def site_plane(kin: Kinematics, run):
    """G's horizontal positions (..., 3) -> (n, 2) north, east in the run's site plane
    (the site's start point at t_start_s; (0, 0) then without a site)."""
    g0 = kin.at(np.array([run.t_start_s]))["G"][0, :2]
    start = np.zeros(2) if run.site is None else np.array([run.site.start_north_m, run.site.start_east_m])
    return lambda G: np.asarray(G)[..., :2].reshape(-1, 2) - g0 + start


def heading_truth(effects, true_read, t_att) -> dict:
    """``effective_heading_misalignment_rad``: the mean over the attitude samples of true minus
    read heading (true = read + misalignment) for effects that misread the heading (compass
    deviation), with its spread; what a constant heading misalignment should recover."""
    hooks = [(e, p) for e, p in effects if type(e).heading_correction is not Effect.heading_correction]
    if not hooks:
        return {}
    psi = true_read(t_att)[:, 0]
    correction = np.sum([e.heading_correction(psi, p) for e, p in hooks], axis=0)
    return {"effective_heading_misalignment_rad": repr(float(np.mean(correction))),
            "heading_correction_sd_rad": repr(float(np.std(correction)))}
