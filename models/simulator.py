"""Simulator: a scenario and a seed in, a case (with ``/truth``) out.

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

import json
from dataclasses import asdict

import casadi as ca
import numpy as np

from ..cases.case import Attitude, Case, Environment, Instrument, Pings, Position, Reference, Truth, Water, format_utc, parse_utc
from ..cases.scenario import Scenario
from .doppler import bottom_echo_ratio, radial_from_ratio, receive_time_paper, slant_range, water_echo_ratio
from .effects import Effect, get_effect
from .geodesy import latitude_longitude_deg
from .janus import janus_beam_directions, janus_transducer_positions
from .kinematics import centre_of_rotation_depth, radius_vectors, transducer_state_function
from .motion import attitude_function, stack_matrices
from .navigation import Track
from .sensors import ar1_noise, irregular_times, quantise, reference_point_velocity, sensed_attitude, wrap_heading

FIXED_POINT_ITERATIONS = 8


class _Kinematics:
    """Numeric evaluation of the symbolic kinematics for one scenario."""

    def __init__(self, scenario: Scenario, effects=()):
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


def _echo(kin: _Kinematics, scenario: Scenario, t_T, tx, target_depth, c_true):
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


def _site_plane(kin: _Kinematics, run):
    """G's horizontal positions (..., 3) -> (n, 2) north, east in the run's site plane
    (the site's start point at t_start_s; (0, 0) then without a site)."""
    g0 = kin.at(np.array([run.t_start_s]))["G"][0, :2]
    start = np.zeros(2) if run.site is None else np.array([run.site.start_north_m, run.site.start_east_m])
    return lambda G: np.asarray(G)[..., :2].reshape(-1, 2) - g0 + start


def _heading_truth(effects, true_read, t_att) -> dict:
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


def _position(kin: _Kinematics, run, site_ne, times, point_body_m):
    """Noise-free GNSS fixes of the reference point (antenna; G without a reference) at its
    sample times (pings without), and the run clock's UTC zero, when the run has a site."""
    if run.site is None:
        return None, None
    k = kin.at(times)
    point = k["G"] + np.einsum("nij,j->ni", k["Lambda"], np.asarray(point_body_m, dtype=float))
    ne = site_ne(point)
    lat, lon = latitude_longitude_deg(ne[:, 0], ne[:, 1], np.rad2deg(run.site.latitude_rad),
                                      np.rad2deg(run.site.longitude_rad))
    return Position(time_s=np.asarray(times, dtype=float).copy(), latitude_deg=lat, longitude_deg=lon), \
        format_utc(parse_utc(run.site.time_origin_utc))


def simulate(scenario: Scenario, seed: int = 0) -> Case:
    """Simulate one run of a scenario; the same seed gives the same case.

    The run's ``effects`` (names of :mod:`adcpdyn.models.effects` with their
    parameters) are injected into the physics and the sensors, and listed in the truth.
    """
    rng = np.random.default_rng(seed)
    effects = [(get_effect(spec["name"]), dict(spec["params"])) for spec in scenario.run.effects]
    for effect, params in effects:
        scenario = effect.modify_scenario(scenario, params)
    pf, run, noise = scenario.platform, scenario.run, scenario.run.noise
    kin = _Kinematics(scenario, effects)
    c_inst = pf.instrument.sound_speed_m_s
    c_true = run.true_sound_speed_m_s or c_inst
    t_end = run.t_start_s + run.duration_s

    # Pings: transmit times, bottom-track echoes (Eqs. 65-70), slant ranges.
    t_T = irregular_times(rng, run.t_start_s, t_end, *run.ping_interval_s)
    N = t_T.size
    tx = kin.at(t_T)
    depth = np.full(N, run.water_depth_m)
    u_tx, u_rx, e_tx, e_rx, t_R, _ = _echo(kin, scenario, t_T, tx, depth[:, None], c_true)
    site_ne = _site_plane(kin, run)
    v_bed = [b for b in (e.bottom_velocity_at(t_T, site_ne(tx["G"]), p) for e, p in effects) if b is not None]
    vb = None
    if v_bed:  # a moving bottom is a moving scatterer (Eq. 88), at G's place at transmit
        vb = np.sum(v_bed, axis=0)
        ratio = water_echo_ratio(u_tx, u_rx, np.sum(e_tx * vb[:, None, :], axis=-1),
                                 np.sum(e_rx * vb[:, None, :], axis=-1), c_true)
    else:
        ratio = bottom_echo_ratio(u_tx, u_rx, c_true)
    bt = radial_from_ratio(ratio, c_inst)
    speed = np.linalg.norm(tx["velocity"], axis=-1)
    bt = bt + ar1_noise(rng.normal(size=bt.shape), noise.bt_ar1) * np.hypot(noise.bt_m_s, noise.bt_fraction * speed)
    rng_m = c_inst * (t_R - t_T[:, None]) / 2  # the instrument's range from the round-trip time
    rng_m = rng_m + rng.normal(size=rng_m.shape) * (noise.range_m + noise.range_fraction * rng_m)
    lost = rng.random(bt.shape) < noise.bt_dropout_probability
    bt[lost] = np.nan
    rng_m[lost] = np.nan

    water = water_truth = None
    if run.water is not None:
        cells = run.water.cell_depths()
        K = cells.size
        u_tx_w, u_rx_w, e_tx_w, e_rx_w, _, _ = _echo(kin, scenario, t_T, tx, np.broadcast_to(cells, (N, 4, K)), c_true)
        v_cell = run.water.velocity(cells, run.water_depth_m)  # (K,3)
        w_tx = np.sum(v_cell * e_tx_w, axis=-1)
        w_rx = np.sum(v_cell * e_rx_w, axis=-1)
        ratio_w = water_echo_ratio(u_tx_w, u_rx_w, w_tx, w_rx, c_true)  # Eq. 88
        radial_w = radial_from_ratio(ratio_w, c_inst) + rng.normal(size=ratio_w.shape) * noise.water_m_s
        # Cells above the face or inside the side-lobe zone near the bottom are not measured.
        z_T = tx["position"][..., 2][..., None]
        usable = (cells > z_T) & (cells < run.water_depth_m - (run.water_depth_m - z_T) * (1 - np.cos(pf.instrument.beam_angle_rad)))
        radial_w[~usable] = np.nan
        water = Water(cell_depth_m=cells, radial_m_s=radial_w)
        water_truth = np.broadcast_to(v_cell, (N, K, 3)).copy()

    # Attitude sensor.
    if run.attitude_interval_s is None:
        t_att = t_T.copy()
    else:
        t_att = irregular_times(rng, run.t_start_s + rng.uniform(0, run.attitude_interval_s[0]), t_end, *run.attitude_interval_s)
    Lam_sym = ca.SX.sym("Lambda", 3, 3)
    sense = ca.Function("sense", [Lam_sym], [sensed_attitude(Lam_sym, kin.installation_ypr, pf.mounting.attitude_frame)])

    def read(times):
        lam = kin.at(times)["Lambda"]
        return np.asarray(sense.map(times.size)(lam.transpose(1, 0, 2).reshape(3, -1))).T

    true_read = read
    for effect, params in effects:  # latency, low-pass, compass deviation
        read = effect.wrap_attitude_sensor(read, params)
    ypr = read(t_att)
    ypr = ypr + rng.normal(size=ypr.shape) * np.array([noise.heading_rad, noise.tilt_rad, noise.tilt_rad])
    ypr = quantise(ypr, noise.attitude_resolution_rad)
    attitude = Attitude(t_att, wrap_heading(ypr[:, 0]), ypr[:, 1], ypr[:, 2], frame=pf.mounting.attitude_frame)
    heading_truth = _heading_truth(effects, true_read, t_att)

    # Reference velocity of a body point (GNSS antenna, video marker).
    reference = None
    p_ref = np.asarray(pf.mounting.reference_point_body_m, dtype=float)
    if run.reference_present and run.reference_stationary:
        reference = Reference(point_body_m=p_ref, stationary=True)
    elif run.reference_present:
        t_ref = irregular_times(rng, run.t_start_s, t_end, *run.reference_interval_s)
        ref_kin = kin.at(t_ref)
        v_sym, dL_sym = ca.SX.sym("v", 3), ca.SX.sym("dL", 3, 3)
        ref_fun = ca.Function("ref", [v_sym, dL_sym], [reference_point_velocity(v_sym, dL_sym, p_ref)]).map(t_ref.size)
        v_ref = np.asarray(ref_fun(ref_kin["vessel_velocity"].T, ref_kin["dLambda_dt"].transpose(1, 0, 2).reshape(3, -1))).T
        v_ref = v_ref + ar1_noise(rng.normal(size=v_ref.shape), noise.reference_ar1) * noise.reference_m_s
        reference = Reference(time_s=t_ref, velocity_m_s=v_ref, point_body_m=p_ref)

    truth = Truth(
        radius_vectors_m=kin.radius_vectors.copy(),
        installation_ypr_rad=kin.installation_ypr.copy(),
        vessel_velocity_m_s=tx["vessel_velocity"].copy(),
        water_velocity_m_s=water_truth,
        moving_bed_velocity_m_s=None if vb is None else np.array(vb, dtype=float),
        effects=[{"name": e.name, "params": p} for e, p in effects],
        extra_attrs={
            "attitude_model": json.dumps(run.motion.to_dict()),
            "doppler_model": json.dumps(asdict(run.doppler)),
            "scenario": scenario.name,
            "seed": str(seed),
            "true_sound_speed_m_s": repr(float(c_true)),
            **heading_truth,
        },
    )
    gnss = reference is not None and reference.time_s is not None
    position, time_origin = _position(kin, run, site_ne, reference.time_s if gnss else t_T, p_ref if gnss else np.zeros(3))
    case = Case(
        name=scenario.name,
        description=f"{run.description} (simulated by adcpdyn, seed {seed})".strip(),
        instrument=Instrument(
            beam_angle_rad=float(pf.instrument.beam_angle_rad),
            transducer_radius_m=float(pf.instrument.transducer_radius_m),
            frequency_hz=float(pf.instrument.frequency_hz),
            sound_speed_m_s=float(c_inst),
        ),
        environment=Environment(water_depth_m=float(run.water_depth_m), transducer_depth_m=float(run.transducer_depth_m)),
        vessel=pf.vessel,
        pings=Pings(time_s=t_T, bt_radial_m_s=bt, bt_range_m=rng_m),
        water=water,
        attitude=attitude,
        reference=reference,
        truth=truth,
        position=position,
        time_origin_utc=time_origin,
    )
    for effect, params in effects:  # what the instrument records (nominal values)
        case = effect.record(case, params)
    return case

