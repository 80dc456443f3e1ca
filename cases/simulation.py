"""Simulator: a scenario and a seed in, a case (with ``/truth``) out.

The physics is :mod:`adcpdyn.models.simulator`'s: it evaluates the same CasADi models the
estimators use, but never their shortcuts (each beam's echo at its own transmit and receive
times with the transducer moving and turning during the flight, the receive time solved
exactly, the vessel velocity at both times, the true sound speed for the physics and the
instrument's for the conversion, attitude sampled by a sensor with its own times, frame,
noise and resolution). Here the samples become a :class:`~adcpdyn.cases.case.Case`.
"""

from __future__ import annotations

import json
from dataclasses import asdict

import casadi as ca
import numpy as np

from ..models.doppler import radial_from_ratio, water_echo_ratio, bottom_echo_ratio
from ..models.effects import get_effect
from ..models.geodesy import latitude_longitude_deg
from ..models.sensors import ar1_noise, irregular_times, quantise, reference_point_velocity, sensed_attitude, wrap_heading
from ..models.simulator import Kinematics, echo_geometry, heading_truth as effective_heading, site_plane
from .case import Attitude, Case, Environment, Instrument, Pings, Position, Reference, Truth, Water, format_utc, parse_utc
from .scenario import Scenario


def _position(kin: Kinematics, run, site_ne, times, point_body_m):
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
    kin = Kinematics(scenario, effects)
    c_inst = pf.instrument.sound_speed_m_s
    c_true = run.true_sound_speed_m_s or c_inst
    t_end = run.t_start_s + run.duration_s

    # Pings: transmit times, bottom-track echoes (Eqs. 65-70), slant ranges.
    t_T = irregular_times(rng, run.t_start_s, t_end, *run.ping_interval_s)
    N = t_T.size
    tx = kin.at(t_T)
    depth = np.full(N, run.water_depth_m)
    u_tx, u_rx, e_tx, e_rx, t_R, _ = echo_geometry(kin, scenario, t_T, tx, depth[:, None], c_true)
    site_ne = site_plane(kin, run)
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
        u_tx_w, u_rx_w, e_tx_w, e_rx_w, _, _ = echo_geometry(kin, scenario, t_T, tx, np.broadcast_to(cells, (N, 4, K)), c_true)
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
    white = rng.normal(size=ypr.shape)
    white[:, 0] = ar1_noise(white[:, 0], noise.heading_ar1)  # a compass's error wanders (identical when 0)
    ypr = ypr + white * np.array([noise.heading_rad, noise.tilt_rad, noise.tilt_rad])
    ypr = quantise(ypr, noise.attitude_resolution_rad)
    attitude = Attitude(t_att, wrap_heading(ypr[:, 0]), ypr[:, 1], ypr[:, 2], frame=pf.mounting.attitude_frame)
    heading_truth = effective_heading(effects, true_read, t_att)

    # Reference velocity of a body point (GNSS antenna, video marker).
    reference = None
    p_ref = np.asarray(pf.mounting.reference_point_body_m, dtype=float)
    if run.reference_present and run.reference_stationary:
        reference = Reference(point_body_m=p_ref, stationary=True)
    elif run.reference_present:
        t_ref = irregular_times(rng, run.t_start_s, t_end, *run.reference_interval_s)
        ref_kin = kin.at(t_ref)
        if run.reference_from == "positions":  # fixes of the antenna, differenced: the mean velocity between two fixes
            dt = np.diff(t_ref)
            # position noise whose differences have the velocity noise level at the median interval
            fix_noise = noise.reference_m_s * float(np.median(dt)) / np.sqrt(2.0)
            antenna = ref_kin["G"] + np.einsum("nij,j->ni", ref_kin["Lambda"], p_ref)
            antenna = antenna + ar1_noise(rng.normal(size=antenna.shape), noise.reference_ar1) * fix_noise
            v_ref = np.diff(antenna, axis=0) / dt[:, None]
            window = np.column_stack([t_ref[:-1], t_ref[1:]])
            reference = Reference(time_s=window.mean(axis=1), velocity_m_s=v_ref, point_body_m=p_ref, window_s=window)
        else:
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
            make="adcpdyn simulator", model=f"{pf.name} ADCP", serial_number=pf.name,
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

