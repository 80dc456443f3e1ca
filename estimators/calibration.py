"""Joint calibration: ONE maximum-likelihood NLP for the attitude model, the lever arms
and the installation angles, solved by IPOPT from many starts.

Unknowns (scaled to order one): the sensor-frame attitude model (bias and damped modes
per axis, yaw trend and couplings; number of modes chosen by BIC in an attitude-only
pre-fit), the installation angles (vessel-frame sensor only: a sensor inside the head
cannot see them, ``../shared/notes-on-the-paper.md``), the lever-arm block of the
chosen formulation (:mod:`.formulations`), and the navigation velocity of G as a
piecewise-linear curve when the vessel moves. The objective is half the sum of
squared noise-weighted residuals of every channel the case holds: attitude samples,
bottom-track radial velocities (shallow Eq. 52 or deep Eqs. 65-70, chosen from the
round-trip time), slant ranges, reference velocity (with its lever arm, erratum 6).
Omega(t) and the beam directions come from the same symbolic attitude model.
Noise levels start from independent estimates (attitude pre-fit residuals, the
error velocity for bottom track) and are re-estimated from the fit's residuals.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from dataclasses import asdict, dataclass, field

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.stats import qmc

from ..cases.case import Case
from ..models.janus import beam_to_instrument
from ..models.measurement import bottom_track_function
from ..models.motion import (LOCAL_ATTITUDE_SIZE, AttitudeLayout, AttitudeParams, SampledAttitude,
                             attitude_function, evaluate_attitude, local_attitude_function)
from ..models.rotations import course_difference_rad, euler_matrix
from ..models.sensors import reference_point_velocity
from ..solvers.multistart import MultistartResult, SolverOptions, build_solver, expand_problem, multistart
from .attitude_fit import AttitudeFit, autocorrelation, fit_attitude
from .formulations import AXES, FORMULATIONS, lever_block
from .row_jacobian import RowBlock, RowJacobian
from .uncertainty import Uncertainty, uncertainty

TIMINGS = ("auto", "shallow", "deep", "exact")
ATTITUDES = ("auto", "model", "samples")
MIN_SAMPLES_PER_PERIOD = 4  # attitude samples per motion period below which no motion model is identifiable
# attitude pre-fit residual (heading, pitch, roll) above which the motion model does not follow the sensor:
# several times a compass's / an inclinometer's noise (the paper's pool: 0.5 / 0.17 deg)
MAX_MODEL_RESIDUAL_RAD = tuple(float(np.deg2rad(d)) for d in (2.0, 1.0, 1.0))
MIN_RESIDUAL_LAG1 = 0.5  # |lag-1 autocorrelation| above which a residual is motion left unfollowed, not sensor noise
METHODS = ("joint", "two-stage")
TANGENTIALS = ("consistent", "paper_literal")
DEEP_TIMING_FRACTION = 0.01  # deep model when the round trip exceeds 1% of the motion period
JACOBIANS = ("auto", "symbolic", "assembled")
ASSEMBLED_MIN_NODES = 400_000  # expanded-graph size above which the Jacobian is assembled per row
ANGLE_NAMES = ("installation_yaw", "installation_pitch", "installation_roll")


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of a joint calibration.

    Parameters
    ----------
    formulation : str
        Lever-arm formulation, one of ``paper``, ``exact``, ``minimal``, ``free``.
    n_starts : int
        Multistart size (the attitude pre-fit, the empirical guess and a Latin
        hypercube design over the start region fill it).
    seed : int
        Seed of the start design.
    timing : str
        ``auto`` (deep when the round trip exceeds 1% of the motion period), ``shallow``,
        ``deep`` or ``exact`` (deep with the travel time solved for the moving transducer).
    max_modes : int
        Most damped modes per axis tried by the pre-fit's information criterion.
    modes : int, optional
        Exactly this many modes per axis (the paper uses 1).
    estimate_noise : bool
        Re-estimate each channel's noise from the residuals and solve again.
    velocity_knot_interval_s : float, optional
        Spacing of the navigation-velocity knots (default: from the data rates).
    lever_box_m : float, optional
        Bound on every lever-arm coordinate (default: half the vessel length, else 10 m).
    installation_bound_rad : float
        Bound on each installation angle (vessel-frame sensors).
    nominal_installation_ypr_rad : tuple
        Installation angles used where the data cannot give them (head sensor).
    epsilon_rel : float
        ``paper`` formulation: relaxation of the Janus conditions.
    use_ranges : bool
        Include slant ranges when the case has them.
    method : str
        ``joint`` (everything in one NLP) or ``two-stage`` (the paper: a one-mode fit of
        each attitude axis, then the lever arms with that attitude frozen and the
        installation angles at their nominal values).
    tangential : str
        ``consistent`` (dLambda/dt r) or ``paper_literal`` (Omega r as printed).
    workers : int
        Threads solving starts at once.
    attitude : str
        Attitude of the beams: ``model`` (the damped-mode model fitted jointly, the paper's
        method), ``samples`` (the sensor's samples interpolated linearly, fixed; for runs no
        motion model follows: attitude sampled below the motion, long records with turns) or
        ``auto`` (samples when the pre-fit leaves residuals above ``MAX_MODEL_RESIDUAL_RAD``
        that are coloured, |lag-1 autocorrelation| > ``MIN_RESIDUAL_LAG1``: motion the model
        does not follow, not a noisy sensor).
        With samples, lever arms are reported only when the samples resolve the motion
        (at least ``MIN_SAMPLES_PER_PERIOD`` per period of the pre-fit's dominant mode).
    jacobian : str
        Residual Jacobian (Gauss-Newton Hessian, standard errors): ``symbolic`` (the whole
        problem expanded to SX and differentiated by CasADi), ``assembled`` (per-row
        Jacobians chained numerically, :mod:`.row_jacobian`; MX problem) or ``auto``
        (assembled above ``ASSEMBLED_MIN_NODES`` expanded nodes: long runs, deep water).
    solver : SolverOptions
    """

    formulation: str = "exact"
    method: str = "joint"
    tangential: str = "consistent"
    n_starts: int = 24
    seed: int = 0
    timing: str = "auto"
    max_modes: int = 3
    modes: int | None = None
    estimate_noise: bool = True
    velocity_knot_interval_s: float | None = None
    lever_box_m: float | None = None
    installation_bound_rad: float = float(np.deg2rad(15.0))
    nominal_installation_ypr_rad: tuple = (0.0, 0.0, 0.0)
    epsilon_rel: float = 0.05
    use_ranges: bool = True
    workers: int = 2
    attitude: str = "auto"
    jacobian: str = "auto"
    solver: SolverOptions = field(default_factory=SolverOptions)

    def __post_init__(self):
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"CalibrationConfig.formulation: expected one of {list(FORMULATIONS)}, got {self.formulation!r}")
        if self.timing not in TIMINGS:
            raise ValueError(f"CalibrationConfig.timing: expected one of {list(TIMINGS)}, got {self.timing!r}")
        if self.method not in METHODS:
            raise ValueError(f"CalibrationConfig.method: expected one of {list(METHODS)}, got {self.method!r}")
        if self.tangential not in TANGENTIALS:
            raise ValueError(f"CalibrationConfig.tangential: expected one of {list(TANGENTIALS)}, got {self.tangential!r}")
        if self.attitude not in ATTITUDES:
            raise ValueError(f"CalibrationConfig.attitude: expected one of {list(ATTITUDES)}, got {self.attitude!r}")
        if self.jacobian not in JACOBIANS:
            raise ValueError(f"CalibrationConfig.jacobian: expected one of {list(JACOBIANS)}, got {self.jacobian!r}")
        if int(self.n_starts) < 1:
            raise ValueError(f"CalibrationConfig.n_starts: expected >= 1, got {self.n_starts}")


@dataclass
class CalibrationResult:
    """Estimates with standard errors, the solver's own account, and what is not determined."""

    radius_vectors_m: np.ndarray
    radius_vectors_se_m: np.ndarray
    installation_ypr_rad: np.ndarray
    installation_ypr_se_rad: np.ndarray
    installation_determined: bool
    attitude: AttitudeParams
    attitude_frame: str
    lever_arms_sensor_m: np.ndarray  # lever arms in the sensor frame (head frame for a head sensor)
    lever_arms_sensor_se_m: np.ndarray
    lever_arms_cov_m2: np.ndarray  # (12, 12) covariance of the sensor-frame lever arms (observable part)
    objective: float
    max_constraint_violation: float
    formulation: str
    timing: str
    noise_sigma: dict
    chi2_per_channel: dict
    multistart: MultistartResult
    uncertainty: Uncertainty
    x_names: list
    x: np.ndarray
    x_se: np.ndarray
    config: CalibrationConfig
    velocity_knots_s: np.ndarray | None = None
    velocity_knots_m_s: np.ndarray | None = None
    # head sensor on a moving run: true heading = sensor heading + this (compass error, declination), found against the reference
    heading_misalignment_rad: float = float("nan")
    heading_misalignment_se_rad: float = float("inf")
    warnings: list = field(default_factory=list)
    jacobian: str = "symbolic"  # how the residual Jacobian was formed: symbolic or assembled per row
    attitude_source: str = "model"  # the beams' attitude: the fitted model or the sensor's samples
    attitude_source_reason: str = ""

    @property
    def success(self) -> bool:
        return bool(self.multistart.success)

    def to_dict(self) -> dict:
        ms = self.multistart
        def determined(values, se):  # a number the data do not fix is not an estimate: null
            return np.where(np.isfinite(se), values, np.nan).tolist()

        out = {
            "radius_vectors_m": determined(self.radius_vectors_m, self.radius_vectors_se_m),
            "radius_vectors_se_m": self.radius_vectors_se_m.tolist(),
            "installation_ypr_rad": determined(self.installation_ypr_rad, self.installation_ypr_se_rad),
            "installation_ypr_assumed_rad": self.installation_ypr_rad.tolist(),
            "installation_ypr_se_rad": self.installation_ypr_se_rad.tolist(),
            "installation_determined": self.installation_determined,
            "heading_misalignment_rad": (self.heading_misalignment_rad
                                         if np.isfinite(self.heading_misalignment_se_rad) else None),
            "heading_misalignment_se_rad": self.heading_misalignment_se_rad,
            "attitude_frame": self.attitude_frame,
            "attitude_model": self.attitude.to_dict(),
            "attitude_source": self.attitude_source,
            "attitude_source_reason": self.attitude_source_reason,
            "objective": self.objective,
            "max_constraint_violation": self.max_constraint_violation,
            "formulation": self.formulation,
            "timing": self.timing,
            "noise_sigma": self.noise_sigma,
            "chi2_per_channel": self.chi2_per_channel,
            "solver": {
                "success": ms.success,
                "status": ms.status,
                "message": ms.message,
                "iterations": ms.iterations,
                "time_s": ms.time_s,
                "n_groups": ms.n_groups,
                "jacobian": self.jacobian,
                "fraction_at_best": ms.fraction_at_best,
                "best_start": ms.best_start,
                "options": asdict(self.config.solver),
            },
            "starts": [s.to_dict() for s in ms.starts],
            "unobservable": self.uncertainty.unobservable,
            "parameters": {n: {"value": float(v) if np.isfinite(s) else None, "se": float(s)}
                           for n, v, s in zip(self.x_names, self.x, self.x_se)},
            "warnings": self.warnings,
            "config": {k: v for k, v in asdict(self.config).items() if k != "solver"},
        }
        if self.attitude_frame == "transducer" and np.isfinite(self.heading_misalignment_se_rad):
            # A head sensor's installation yaw against the reference is its heading misalignment: the
            # angle from the bottom-track course to the GNSS course (Qiao et al.'s Eq. 5 yaw); the
            # installation pitch and roll stay undetermined.
            out["installation_ypr_rad"][0] = self.heading_misalignment_rad
            out["installation_ypr_se_rad"][0] = self.heading_misalignment_se_rad
            out["installation_yaw_is"] = "heading_misalignment (head sensor: course of bottom track -> course of the reference)"
        if self.attitude_frame == "transducer":
            out["radius_vectors_head_m"] = determined(self.lever_arms_sensor_m, self.lever_arms_sensor_se_m)
            out["radius_vectors_head_se_m"] = self.lever_arms_sensor_se_m.tolist()
        if self.velocity_knots_s is not None:
            out["velocity_model"] = {"knot_times_s": self.velocity_knots_s.tolist(),
                                     "knot_velocities_m_s": self.velocity_knots_m_s.tolist()}
        return out

    def to_json(self, path) -> None:
        from ..cases.atomic import atomic_path

        with atomic_path(path) as tmp:
            with open(tmp, "w") as fh:
                json.dump(_jsonable(self.to_dict()), fh, indent=2)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    return obj


def _hat_basis(times, knots) -> np.ndarray:
    """Piecewise-linear interpolation weights, (len(times), len(knots))."""
    eye = np.eye(len(knots))
    return np.column_stack([np.interp(times, knots, eye[:, k]) for k in range(len(knots))])


def dominant_period_s(fit: AttitudeFit) -> float:
    p = fit.params
    if p.modes.size == 0:
        return np.inf
    amp = np.hypot(*p.roll_cs.T) + np.hypot(*p.pitch_cs.T)
    return float(2 * np.pi / p.modes[int(np.argmax(amp)), 0])


def choose_timing(case: Case, fit: AttitudeFit, requested: str = "auto") -> str:
    """Shallow or deep bottom-track model: deep when the round trip matters."""
    if requested != "auto":
        return requested
    c = case.instrument.sound_speed_m_s
    depth = np.max(case.environment.depth_at_pings(case.pings.n)) - case.environment.transducer_depth_m
    round_trip = 2 * depth / (c * np.cos(case.instrument.beam_angle_rad))
    return "deep" if round_trip > DEEP_TIMING_FRACTION * dominant_period_s(fit) else "shallow"


def samples_per_period(case: Case, fit: AttitudeFit) -> float:
    """Attitude samples per period of the pre-fit's dominant mode (inf without a mode)."""
    return dominant_period_s(fit) / float(np.median(np.diff(case.attitude.time_s)))


def attitude_residual_lag1(case: Case, fit: AttitudeFit) -> np.ndarray:
    """Lag-1 autocorrelation of the pre-fit's heading, pitch and roll residuals (0 for white noise)."""
    a = case.attitude
    r = a.ypr() - evaluate_attitude(fit.params, a.time_s)["ypr"]
    r[:, 0] = np.angle(np.exp(1j * r[:, 0]))
    return np.array([autocorrelation(r[:, j], 1)[0] for j in range(3)])


def choose_attitude(case: Case, fit: AttitudeFit, requested: str = "auto") -> tuple[str, str]:
    """``model`` or ``samples`` for the beams' attitude, and why."""
    if requested != "auto":
        return requested, "requested"
    excess = np.asarray(fit.sigmas) > np.asarray(MAX_MODEL_RESIDUAL_RAD)
    if excess.any():
        excess &= np.abs(attitude_residual_lag1(case, fit)) > MIN_RESIDUAL_LAG1
    if excess.any():
        left = ", ".join(f"{n} {np.rad2deg(v):.2f} deg" for n, v, e in zip(("heading", "pitch", "roll"), fit.sigmas, excess) if e)
        return "samples", (f"the damped-mode model leaves {left} of coloured residual: turns or irregular motion it "
                           "cannot follow")
    return "model", "the damped-mode model follows the attitude samples"


def reference_velocity_function(point_sensor_m, heading_misaligned: bool) -> ca.Function:
    """``(v_a (3), dLambda/dt (3x3), d) -> velocity`` the reference measures: its body point's
    (p in the sensor frame), turned by the heading misalignment d into the true Earth frame
    when the sensor's Earth is off (head sensor against GNSS)."""
    v, dLam, d = ca.SX.sym("v_a", 3), ca.SX.sym("dLambda", 3, 3), ca.SX.sym("d")
    velocity = reference_point_velocity(v, dLam, ca.DM(point_sensor_m))
    if heading_misaligned:
        velocity = ca.mtimes(euler_matrix(d, 0, 0), velocity)
    return ca.Function("reference_velocity", [v, dLam, d], [velocity])


def bt_noise_from_error_velocity(case: Case) -> float:
    """Beam noise from the error velocity (immune to rigid motion): robust MAD estimate."""
    B = case.instrument.beam_directions()
    _, e = beam_to_instrument(B)
    err = case.pings.bt_radial_m_s @ e
    err = err[np.isfinite(err)]
    if err.size < 5:
        return 0.01
    mad = 1.4826 * np.median(np.abs(err - np.median(err)))
    return float(max(mad / np.linalg.norm(e), 1e-4))


class CalibrationProblem:
    """The joint NLP of one case: built once, solved from many starts."""

    def __init__(self, case: Case, config: CalibrationConfig, fit: AttitudeFit | None = None):
        self.case, self.config = case, config
        self.two_stage = config.method == "two-stage"
        self.fit = fit or fit_attitude(case, max_modes=config.max_modes, fixed_modes=1 if self.two_stage else config.modes,
                                       per_axis=self.two_stage)
        self.timing = choose_timing(case, self.fit, config.timing)
        self.attitude_source, self.attitude_reason = ("model", "two-stage method") if self.two_stage else \
            choose_attitude(case, self.fit, config.attitude)
        self.sampled = self.attitude_source == "samples"
        self.frozen_attitude = self.two_stage or self.sampled  # no attitude unknowns, no attitude channels
        self.frame = case.attitude.frame
        self.head_sensor = self.frame == "transducer"
        layout = self.fit.params.layout
        self.layout = layout
        att_fun = local_attitude_function() if self.sampled else attitude_function(layout)
        self.n_attitude = 0 if self.frozen_attitude else layout.size  # attitude unknowns
        self.attitude_fun = att_fun
        pings, N = case.pings, case.pings.n
        self.beam_dirs_t = case.instrument.beam_directions()
        self.pos_t = case.instrument.transducer_positions()
        v = case.vessel
        self.lever_box = config.lever_box_m or (0.5 * v.length_m if v.length_m else 10.0)

        # ---- decision variables, unscaled, with names, scales and bounds
        blocks, names, scale, lb, ub = [], [], [], [], []

        def add(sym, block_names, block_scale, lo, hi):
            blocks.append(sym)
            names.extend(block_names)
            scale.extend(block_scale)
            lb.extend(lo)
            ub.extend(hi)

        if self.sampled:  # the samples about each row's time: data, one column per row
            self.samples = SampledAttitude(case.attitude.time_s, case.attitude.ypr())
            p_att = ca.MX(0, 1)
        elif self.two_stage:  # stage 1 is done: the attitude model is frozen
            p_att = ca.MX(ca.DM(self.fit.params.pack()))
        else:
            p_att = ca.MX.sym("attitude", layout.size)
            att_names, att_scale, att_lo, att_hi = self._attitude_bounds(self.fit.params)
            add(p_att, att_names, att_scale, att_lo, att_hi)
        # A head sensor fixes no installation angle from the attitude, but against a moving reference its
        # heading misalignment (compass error, declination: an Earth-frame heading offset) is observable.
        ref = case.reference
        self.head_yaw = bool(self.head_sensor and not self.two_stage and ref is not None and not ref.stationary
                         and ref.velocity_m_s is not None)
        self.fixed_installation = (self.head_sensor and not self.head_yaw) or self.two_stage
        # Against a moving reference the course offset gives the yaw whatever its size (a head turned 45
        # degrees from the bow, a compass off by tens of degrees): the yaw's box is centred there.
        moving_reference = ref is not None and not ref.stationary and ref.velocity_m_s is not None
        self.yaw_guess = self._yaw_guess() if self.head_yaw or (moving_reference and not self.fixed_installation) else 0.0
        heading_offset = None
        if self.head_yaw:  # Earth-frame heading offset: true Earth = Rz(d) (the sensor's Earth); beams stay put
            heading_offset = ca.MX.sym("heading_misalignment", 1)
            add(heading_offset, ["heading_misalignment"], [0.02], [self.yaw_guess - np.pi], [self.yaw_guess + np.pi])
            ypr_st = ca.vertcat(heading_offset, ca.MX.zeros(2))  # reported with the angles; the beams use zeros
        elif self.head_sensor:
            ypr_st = ca.MX(ca.DM.zeros(3))
        elif self.two_stage:
            ypr_st = ca.MX(ca.DM(np.asarray(config.nominal_installation_ypr_rad, dtype=float)))
        else:
            ypr_st = ca.MX.sym("installation", 3)
            b = config.installation_bound_rad
            centre = np.array([self.yaw_guess, 0.0, 0.0])
            add(ypr_st, list(ANGLE_NAMES), [0.02] * 3, list(centre - b), list(centre + b))
        ypr_beams = ca.MX(ca.DM.zeros(3)) if self.head_yaw else ypr_st
        Lst = euler_matrix(ypr_beams[0], ypr_beams[1], ypr_beams[2])
        self.lever = lever_block(config.formulation, Lst, self.pos_t, config.epsilon_rel)
        nl = len(self.lever.names)
        add(self.lever.x, self.lever.names, [self.lever_box / 5] * nl, [-self.lever_box] * nl, [self.lever_box] * nl)

        # ---- navigation velocity of G
        ref = case.reference
        self.stationary = ref is not None and ref.stationary
        t0, t1 = pings.time_s[0], pings.time_s[-1]
        if ref is not None and ref.time_s is not None:
            t0, t1 = min(t0, ref.time_s[0]), max(t1, ref.time_s[-1])
        self.knots = None
        if not self.stationary:
            interval = config.velocity_knot_interval_s or self._default_knot_interval()
            n_knots = max(2, int(np.ceil((t1 - t0) / interval)) + 1)
            self.knots = np.linspace(t0, t1, n_knots)
            vk = ca.MX.sym("velocity", 3 * n_knots)
            speed = max(self._speed_guess(), 0.05)
            add(vk, [f"V{k}_{a}" for k in range(n_knots) for a in AXES], [speed] * (3 * n_knots),
                [-20.0] * (3 * n_knots), [20.0] * (3 * n_knots))
            V = ca.reshape(vk, 3, n_knots).T  # (K, 3)
            v_ping = ca.mtimes(ca.DM(_hat_basis(pings.time_s, self.knots)), V)
        else:
            V = None
            v_ping = ca.MX(ca.DM.zeros(N, 3))

        x = ca.vertcat(*blocks)
        self.names = names
        self.scale = np.array(scale, dtype=float)
        self.lbx, self.ubx = np.array(lb, dtype=float), np.array(ub, dtype=float)
        z = ca.MX.sym("z", x.shape[0])
        # ---- residual channels (weights in p so noise can be re-estimated without rebuilding)
        self.channels: list[tuple[str, int]] = []
        models, meas = [], []
        # attitude samples (stage 1 of the two-stage method has used them already)
        a = case.attitude
        M = a.time_s.size
        self.bottom_track = bottom_track_function(att_fun, self.timing, config.tangential)  # one ping
        self.use_reference = ref is not None and ref.time_s is not None and ref.velocity_m_s is not None
        n_nodes = (self.bottom_track.n_instructions() * N
                   + att_fun.n_instructions() * ((0 if self.frozen_attitude else M) + (ref.time_s.size if self.use_reference else 0)))
        self.assembled = config.jacobian == "assembled" or (config.jacobian == "auto" and n_nodes > ASSEMBLED_MIN_NODES)
        # long runs: the cores the multistart's workers leave free share the per-row Jacobians
        self.threads = max(1, (os.cpu_count() or 1) // max(1, min(config.workers, config.n_starts))) if self.assembled else 1
        if not self.frozen_attitude:
            ypr_model, *_ = att_fun.map(M)(ca.DM(a.time_s).T, p_att)
            ypr_meas = a.ypr()
            dpsi = ypr_meas[:, 0] - ca.transpose(ypr_model[0, :])
            models += [ca.atan2(ca.sin(dpsi), ca.cos(dpsi)), ca.transpose(ypr_model[1, :]) - ypr_meas[:, 1],
                       ca.transpose(ypr_model[2, :]) - ypr_meas[:, 2]]
            self.channels += [("heading", M), ("pitch", M), ("roll", M)]
        # bottom track and ranges
        bt_fun = self.bottom_track.map(N)
        depth = case.environment.depth_at_pings(N)
        g_depth = case.environment.transducer_depth_m - ca.sum1(self.lever.r[:, 2]) / 4
        p_pings = ca.DM(self.samples.params_at(pings.time_s)) if self.sampled else p_att
        radial, rng = bt_fun(ca.DM(pings.time_s).T, ca.DM(depth).T, g_depth, case.instrument.sound_speed_m_s,
                             v_ping.T, p_pings, self.lever.r, ypr_beams, ca.DM(self.beam_dirs_t))
        bt = pings.bt_radial_m_s
        self.bt_mask = np.isfinite(bt)
        for i in range(4):
            models.append(ca.transpose(radial[i, :]) - np.nan_to_num(bt[:, i]))
            self.channels.append((f"bt_beam{i + 1}", N))
        self.use_ranges = config.use_ranges and pings.bt_range_m is not None
        if self.use_ranges:
            for i in range(4):
                models.append(ca.transpose(rng[i, :]) - np.nan_to_num(pings.bt_range_m[:, i]))
                self.channels.append((f"range_beam{i + 1}", N))
        # reference velocity of a body point
        if self.use_reference:
            L = ref.time_s.size
            p_refs = ca.DM(self.samples.params_at(ref.time_s)) if self.sampled else p_att
            _, _, dLam, _, _ = att_fun.map(L)(ca.DM(ref.time_s).T, p_refs)
            p_ref = np.asarray(ref.point_body_m, dtype=float)
            if self.head_sensor:  # dLambda p = dLambda_h Lambda_tb^T p with the nominal Lambda_tb
                p_ref = np.asarray(euler_matrix(*config.nominal_installation_ypr_rad)).T @ p_ref
            self.reference_velocity = reference_velocity_function(p_ref, self.head_yaw)  # one reference sample
            v_ref_model = ca.mtimes(ca.DM(_hat_basis(ref.time_s, self.knots)), V) if V is not None else ca.MX(L, 3)
            v_sensor = self.reference_velocity.map(L)(v_ref_model.T, dLam,
                                                      heading_offset if heading_offset is not None else 0)
            for j in range(3):
                models.append(ca.transpose(v_sensor[j, :]) - np.nan_to_num(ref.velocity_m_s[:, j]))
                self.channels.append((f"reference_{AXES[j]}", L))
        raw = ca.vertcat(*models)
        self.masks = self._masks()
        self.solver_options = dataclasses.replace(config.solver, expand=False) if self.assembled else config.solver
        weights = ca.MX.sym("w", raw.shape[0])
        e = weights * raw
        self.sigma = self._initial_sigmas()
        subs = [x], [self.scale * z]
        e_z = ca.substitute([e], *subs)[0]
        raw_z = ca.substitute([raw], *subs)[0]
        g_z = ca.substitute([self.lever.g], *subs)[0]
        r_z = ca.substitute([self.lever.r], *subs)[0]
        st_z = ca.substitute([ypr_st], *subs)[0]
        mx_nlp = {"x": z, "p": weights, "f": 0.5 * ca.sumsqr(e_z), "g": g_z}
        if self.assembled:
            shared = ca.vertcat(p_att, ca.vec(self.lever.r.T), ypr_beams, g_depth,
                                heading_offset if heading_offset is not None else ca.MX(0, 1))
            self.jacobian_fun = self._row_jacobian(z, ca.substitute([shared], *subs)[0], raw.shape[0])
        if self.solver_options.expand:
            self.nlp, e_z, ex = expand_problem(mx_nlp, e_z, {"raw": raw_z, "r": ca.vec(r_z.T), "st": st_z})
            z, weights, g_z = self.nlp["x"], self.nlp["p"], self.nlp["g"]
            raw_z, r_vec, st_z = ex["raw"], ex["r"], ex["st"]
        else:
            self.nlp, r_vec = mx_nlp, ca.vec(r_z.T)
        if not self.assembled:
            self.jacobian_fun = ca.Function("residual_jacobian", [z, weights], [ca.jacobian(e_z, z)])
        self.residual_fun = ca.Function("residuals", [z, weights], [e_z, raw_z])
        self.derived_fun = ca.Function("derived", [z], [r_vec, st_z, ca.jacobian(r_vec, z),
                                                      ca.jacobian(st_z, z), g_z, ca.jacobian(g_z, z)])
        self.residuals = e_z
        self.lbg, self.ubg = self.lever.lbg, self.lever.ubg
        self.solver = build_solver(self.nlp, self.solver_options, "calibration", residuals=self.jacobian_fun)

    def _row_jacobian(self, z, shared_z, n_rows: int) -> RowJacobian:
        """The residual Jacobian assembled from per-row Jacobians (see :mod:`.row_jacobian`).

        Shared vector s = [attitude parameters, lever arms row by row, beam angles, depth of G,
        heading misalignment]; its layout here must match the one built in ``__init__``.
        """
        case, att_fun, n_att = self.case, self.attitude_fun, self.n_attitude
        n_s = shared_z.shape[0]
        n_local = LOCAL_ATTITUDE_SIZE if self.sampled else 0  # per-row attitude data after time (and depth)
        d1, d2 = ca.SX.sym("d", 1 + n_local), ca.SX.sym("d", 2 + n_local)
        v, s = ca.SX.sym("v", 3), ca.SX.sym("s", n_s)
        p_att, r = s[:n_att], ca.reshape(s[n_att:n_att + 12], 3, 4).T
        p_row1, p_row2 = (d1[1:], d2[2:]) if self.sampled else (p_att, p_att)
        local = self.samples.params_at if self.sampled else (lambda t: np.zeros((0, np.size(t))))
        ypr_beams, g_depth = s[n_att + 12:n_att + 15], s[n_att + 15]
        knots_basis = lambda t: None if self.knots is None else sp.csr_matrix(_hat_basis(t, self.knots))
        blocks, offset = [], 0
        if not self.frozen_attitude:
            a = case.attitude
            ypr = att_fun(d1, p_att)[0]
            blocks.append(RowBlock(ca.Function("attitude_rows", [d1, v, s], [ypr]), a.time_s[None, :], offset,
                                   sign=np.array([-1.0, 1.0, 1.0])))  # heading residual is measured - model
            offset += 3 * a.time_s.size
        pings = case.pings
        radial, rng = self.bottom_track(d2[0], d2[1], g_depth, case.instrument.sound_speed_m_s, v, p_row2, r, ypr_beams,
                                        ca.DM(self.beam_dirs_t))
        out = ca.vertcat(radial, rng) if self.use_ranges else radial
        data = np.vstack([pings.time_s, case.environment.depth_at_pings(pings.n), local(pings.time_s)])
        blocks.append(RowBlock(ca.Function("bottom_track_rows", [d2, v, s], [out]), data, offset,
                               velocity_basis=knots_basis(pings.time_s)))
        offset += out.shape[0] * pings.n
        if self.use_reference:
            ref = case.reference
            vs = self.reference_velocity(v, att_fun(d1[0], p_row1)[2], s[n_s - 1] if self.head_yaw else 0)
            blocks.append(RowBlock(ca.Function("reference_rows", [d1, v, s], [vs]), np.vstack([ref.time_s, local(ref.time_s)]), offset,
                                   velocity_basis=knots_basis(ref.time_s)))
            offset += 3 * ref.time_s.size
        if offset != n_rows:
            raise RuntimeError(f"assembled Jacobian: {offset} rows, residuals have {n_rows}")
        knot_cols = None
        if self.knots is not None:
            k = len(self.knots)
            knot_cols = (len(self.names) - 3 * k + np.arange(3 * k)).reshape(k, 3)
        return RowJacobian(z, shared_z, blocks, n_rows, knot_cols, self.scale, threads=self.threads)

    # ------------------------------------------------------------------ helpers
    def _attitude_bounds(self, params: AttitudeParams):
        """Names, scales and bounds of the attitude block (frequencies kept near the pre-fit's)."""
        lay = params.layout
        names = lay.names()
        s = lay.slices()
        scale = np.ones(lay.size)
        lo = np.full(lay.size, -np.inf)
        hi = np.full(lay.size, np.inf)
        for k, (w, _) in enumerate(params.modes):
            i = s["modes"].start + 2 * k
            scale[i], lo[i], hi[i] = 0.01 * w, 0.8 * w, 1.25 * w
            scale[i + 1], lo[i + 1], hi[i + 1] = 0.05, 0.0, 3.0
        for axis in ("roll", "pitch", "yaw"):
            cs = getattr(params, f"{axis}_cs")
            amp = np.maximum(np.hypot(cs[:, 0], cs[:, 1]), 1e-3)
            scale[s[f"{axis}_cs"]] = np.repeat(amp, 2)
        for axis in ("roll", "pitch"):
            i = s[f"{axis}_bias"].start
            scale[i], lo[i], hi[i] = 0.01, -np.pi / 2, np.pi / 2
        scale[s["yaw_trend"]] = [1.0 if k == 0 else 0.01**k for k in range(lay.yaw_trend_order + 1)]
        return names, scale.tolist(), lo.tolist(), hi.tolist()

    def _yaw_guess(self) -> float:
        """Course of the reference minus course of the static (ASC) bottom-track velocity, radians."""
        from .asc import asc

        ref = self.case.reference
        v = asc(self.case).vessel_velocity_m_s
        t = self.case.pings.time_s
        g = np.column_stack([np.interp(t, ref.time_s, ref.velocity_m_s[:, j]) for j in range(2)])
        ok = np.all(np.isfinite(v[:, :2]), axis=1) & np.all(np.isfinite(g), axis=1) & (np.hypot(*g.T) > 0.1)
        if ok.sum() < 3:
            return 0.0
        return float(np.angle(np.mean(np.exp(1j * course_difference_rad(g[ok], v[ok])))))

    def _default_knot_interval(self) -> float:
        ref = self.case.reference
        duration = self.case.pings.time_s[-1] - self.case.pings.time_s[0]
        if ref is not None and ref.time_s is not None and ref.time_s.size > 1:
            return max(5 * float(np.median(np.diff(ref.time_s))), duration / 50)
        return max(5 * float(np.median(np.diff(self.case.pings.time_s))), duration / 30)

    def _speed_guess(self) -> float:
        ref = self.case.reference
        if ref is not None and ref.velocity_m_s is not None:
            return float(np.nanmedian(np.linalg.norm(ref.velocity_m_s, axis=1)))
        return 0.1

    def _masks(self) -> np.ndarray:
        parts = [] if self.frozen_attitude else [np.ones(self.case.attitude.time_s.size)] * 3
        parts += [self.bt_mask[:, i].astype(float) for i in range(4)]
        if self.use_ranges:
            parts += [np.isfinite(self.case.pings.bt_range_m[:, i]).astype(float) for i in range(4)]
        if self.use_reference:
            parts += [np.all(np.isfinite(self.case.reference.velocity_m_s), axis=1).astype(float)] * 3
        return np.concatenate(parts)

    def _initial_sigmas(self) -> dict:
        s = {"bt": bt_noise_from_error_velocity(self.case)}
        if not self.frozen_attitude:
            s.update(heading=max(self.fit.sigmas[0], 1e-4), pitch=max(self.fit.sigmas[1], 1e-4),
                     roll=max(self.fit.sigmas[2], 1e-4))
        if self.use_ranges:
            s["range"] = 0.02
        if self.use_reference:
            s["reference"] = 0.02
        return s

    def channel_sigma_key(self, channel: str) -> str:
        return channel.split("_")[0]

    def weights(self, sigma: dict | None = None) -> np.ndarray:
        sigma = sigma or self.sigma
        w = np.concatenate([np.full(n, 1.0 / sigma[self.channel_sigma_key(ch)]) for ch, n in self.channels])
        return w * self.masks

    def channel_slices(self) -> dict:
        return channel_slices(self.channels)

    # ------------------------------------------------------------------ starts
    def start_points(self, n_starts: int, seed: int) -> np.ndarray:
        """Pre-fit start, empirical-guess start, then a Latin hypercube over the start region."""
        rng = np.random.default_rng(seed)
        angles0 = np.array([self.yaw_guess, 0.0, 0.0])
        base = self._x_from(self.fit.params, angles0, self._centre_guess())
        starts = [base]
        emp = self._empirical_params()
        if emp is not None and n_starts > 1:
            starts.append(self._x_from(emp, angles0, self._centre_guess()))
        n_design = n_starts - len(starts)
        if n_design > 0:
            dims = 3 + 3 + 2  # centre P, angles, frequency and decay jitter
            u = qmc.LatinHypercube(d=dims, seed=rng).random(n_design) * 2 - 1
            for row in u:
                centre = row[:3] * self.lever_box
                angles = np.zeros(3) if self.fixed_installation else row[3:6] * self.config.installation_bound_rad
                angles[0] += self.yaw_guess
                if self.head_yaw:
                    angles[1:] = 0.0
                starts.append(self._x_from(self._jitter(self.fit.params, row[6], row[7]), angles, centre))
        x0 = np.array(starts)
        x0 = np.clip(x0, self.lbx, self.ubx)
        return x0 / self.scale

    def _centre_guess(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.1 * self.lever_box])

    def _jitter(self, params: AttitudeParams, u_omega: float, u_decay: float) -> AttitudeParams:
        modes = params.modes.copy()
        if modes.size:
            modes[:, 0] *= 1 + 0.01 * u_omega
            modes[:, 1] = np.clip(modes[:, 1] * (1 + 0.5 * u_decay), 0.0, 3.0)
        return dataclasses.replace(params, modes=modes)

    def _empirical_params(self) -> AttitudeParams | None:
        """The pre-fit with its strongest mode's frequency and decay from the hull figures (Eqs. 36-47)."""
        from ..models.empirical import motion_guess

        v = self.case.vessel
        p = self.fit.params
        if not (v.length_m and v.beam_m and v.height_m and v.mass_kg) or p.modes.size == 0:
            return None
        g = motion_guess(v.length_m, v.beam_m, v.height_m, v.mass_kg, v.draft_m, v.displaced_volume_m3)
        strongest = int(np.argmax(np.hypot(*p.roll_cs.T) + np.hypot(*p.pitch_cs.T)))
        modes = p.modes.copy()
        modes[strongest] = [g.roll_damped_rad_s, g.roll_decay_1_s]
        return dataclasses.replace(p, modes=modes)

    def _x_from(self, params: AttitudeParams, angles, centre) -> np.ndarray:
        parts = [] if self.frozen_attitude else [params.pack()]
        if self.head_yaw:
            parts.append(np.asarray(angles, dtype=float)[:1])
        elif not self.fixed_installation:
            parts.append(np.asarray(angles, dtype=float))
        elif self.two_stage and not self.head_sensor:
            angles = np.asarray(self.config.nominal_installation_ypr_rad, dtype=float)
        Lst = np.asarray(euler_matrix(*angles)) if not self.head_sensor else np.eye(3)
        parts.append(self.lever.initial(centre, Lst, self.pos_t))
        if self.knots is not None:
            parts.append(self._velocity_guess().reshape(-1))
        return np.concatenate(parts)

    def _velocity_guess(self) -> np.ndarray:
        ref = self.case.reference
        if ref is not None and ref.velocity_m_s is not None:
            v = ref.velocity_m_s
            ok = np.all(np.isfinite(v), axis=1)
            half = np.median(np.diff(self.knots)) / 2
            out = []
            for tk in self.knots:
                sel = ok & (np.abs(ref.time_s - tk) <= half)
                out.append(np.mean(v[sel], axis=0) if sel.any() else np.array([np.interp(tk, ref.time_s[ok], v[ok, j]) for j in range(3)]))
            return np.array(out)
        from .asc import asc

        corr = asc(self.case)
        v = corr.vessel_velocity_m_s
        ok = np.all(np.isfinite(v), axis=1)
        return np.column_stack([np.interp(self.knots, corr.time_s[ok], v[ok, j]) for j in range(3)])

    # ------------------------------------------------------------------ solve
    def solve(self) -> CalibrationResult:
        cfg = self.config
        x0s = self.start_points(cfg.n_starts, cfg.seed)
        lbz, ubz = self.lbx / self.scale, self.ubx / self.scale
        make = lambda: build_solver(self.nlp, self.solver_options, "calibration", residuals=self.jacobian_fun,
                                    like=self.solver)
        ms = multistart(self.solver, x0s, lbz, ubz, self.lbg, self.ubg, self.weights(), workers=cfg.workers,
                        make_solver=make, warm_start=cfg.solver.warm_start)
        if cfg.estimate_noise:
            self.sigma = self._reestimate_sigmas(ms.x)
            refit = multistart(self.solver, ms.x[None, :], lbz, ubz, self.lbg, self.ubg, self.weights(), progress=False)
            # the per-start table stays that of the multistart; the final solve is the refit
            ms = MultistartResult(**{**ms.__dict__, "x": refit.x, "objective": refit.objective, "success": refit.success,
                                     "status": refit.status, "iterations": refit.iterations, "lam_g": refit.lam_g,
                                     "g": refit.g, "message": ms.message + f"; noise re-estimated, refit: {refit.status}"})
        return self._result(ms)

    def _reestimate_sigmas(self, z) -> dict:
        _, raw = self.residual_fun(z, self.weights())
        raw = np.asarray(raw).ravel()
        sl = self.channel_slices()
        n_total = float(self.masks.sum())
        dof = max(1.0 - len(z) / max(n_total, 1.0), 0.1)
        out = dict(self.sigma)
        for key in out:
            idx = np.concatenate([np.arange(s.start, s.stop) for ch, s in sl.items() if self.channel_sigma_key(ch) == key])
            m = self.masks[idx] > 0
            if m.sum() > 3:
                out[key] = float(max(np.sqrt(np.sum(raw[idx][m] ** 2) / (m.sum() * dof)), 1e-6))
        return out

    def _result(self, ms: MultistartResult) -> CalibrationResult:
        w = self.weights()
        e = np.asarray(self.residual_fun(ms.x, w)[0]).ravel()
        J = self.jacobian_fun(ms.x, w)
        J = J.toarray() if self.assembled else np.asarray(J)
        r_flat, st, Jr, Jst, g, Jg = (np.asarray(a) for a in self.derived_fun(ms.x))
        eq = (self.lbg == self.ubg) if len(self.lbg) else np.zeros(0, dtype=bool)
        Lst = np.eye(3) if self.head_sensor else np.asarray(euler_matrix(*np.asarray(st).ravel()))
        unc = uncertainty(J, Jg[eq] if eq.any() else None, self.names, self.scale,
                          {"beam_dirs_sensor": self.beam_dirs_t @ Lst.T, "frame": self.frame})
        se_x = unc.se_z * self.scale
        cov_z = unc.cov_z
        cov_r = Jr @ cov_z @ Jr.T  # (12, 12), rows r1x, r1y, r1z, r2x, ...
        se_r = np.sqrt(np.maximum(np.diag(cov_r), 0)).reshape(4, 3)
        se_st = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Jst, cov_z, Jst), 0)) if Jst.size else np.zeros(3)
        r_s = r_flat.reshape(4, 3)
        se_r[~unc.determined_mask(Jr).reshape(4, 3)] = np.inf
        # held by the search box, or known no better than the box: the bound, not the data, set the number
        box_held = (np.abs(r_s) >= 0.999 * self.lever_box) | (se_r > self.lever_box)
        se_r[box_held] = np.inf
        aliased = self.sampled and samples_per_period(self.case, self.fit) < MIN_SAMPLES_PER_PERIOD
        if aliased:  # the rate between samples is not measured: the tangential velocity is not known
            se_r[:] = np.inf
        sl = self.channel_slices()
        chi2 = {}
        for ch, s in sl.items():
            m = self.masks[s] > 0
            chi2[ch] = float(np.sum(e[s][m] ** 2) / max(m.sum(), 1))
        viol = 0.0
        if len(self.lbg):
            g = g.ravel()
            viol = float(np.max(np.concatenate([np.maximum(self.lbg - g, 0), np.maximum(g - self.ubg, 0)])))
        x = ms.x * self.scale
        p_att = self.fit.params if self.frozen_attitude else AttitudeParams.unpack(x[: self.layout.size], self.layout)
        warn = list(unc.warnings)
        if self.sampled:
            warn.append(f"beams' attitude from the sensor's samples, interpolated linearly ({self.attitude_reason}); "
                        "attitude_model is the pre-fit, not used by the beams")
        if aliased:
            warn.append("lever arms not determined: the attitude samples do not resolve the motion, so the rotation "
                        "rates between them (and the tangential velocity) are not measured; reported as null")
        if box_held.any() and not aliased:
            warn.append(f"{int(box_held.sum())} lever-arm component(s) held by the search box (+-{self.lever_box:g} m) or "
                        f"known no better than it: not determined by this run (too little rotation), reported as null")
        if not ms.success:
            warn.append(f"solver did not converge: {ms.status}")
        misalignment, misalignment_se = float("nan"), float("inf")
        if self.head_sensor:
            nominal = np.asarray(self.config.nominal_installation_ypr_rad, dtype=float)
            Ltb = np.asarray(euler_matrix(*nominal))
            radius = r_s @ Ltb.T
            radius_se = np.sqrt((se_r**2) @ (Ltb.T**2))
            ypr, ypr_se = nominal, np.full(3, np.inf)
            if self.head_yaw:
                misalignment = float(np.asarray(st).ravel()[0])
                misalignment_se = float(se_st.ravel()[0]) if unc.determined_mask(Jst[:1]).all() else np.inf
                warn.append("attitude sensor inside the ADCP head: installation angles are not determined; the heading "
                            "misalignment (an Earth-frame heading offset: compass error, declination; true heading = "
                            "sensor heading + misalignment) is found against the moving reference; the data fix the head-frame lever arms "
                            "(radius_vectors_head_m); radius_vectors_m uses the nominal angles")
                if not np.isfinite(misalignment_se):
                    warn.append("heading misalignment against the reference is not determined (too little motion over ground)")
            else:
                warn.append("attitude sensor inside the ADCP head: the data fix only the head-frame lever arms "
                            "(radius_vectors_head_m = Lambda_tb^T r); installation angles are not determined and need "
                            "another source (nominal mounting, GNSS on a moving run); radius_vectors_m uses the nominal angles")
        else:
            radius, radius_se = r_s, se_r
            ypr, ypr_se = np.asarray(st).ravel(), se_st.ravel()
            if self.fixed_installation:
                ypr_se = np.full(3, np.inf)
                warn.append("two-stage method: installation angles held at their nominal values, not estimated")
            else:
                ypr_se[~unc.determined_mask(Jst)] = np.inf
                i_angles = np.array([self.names.index(n) for n in ANGLE_NAMES])
                span = self.ubx[i_angles] - self.lbx[i_angles]
                at_box = np.minimum(x[i_angles] - self.lbx[i_angles], self.ubx[i_angles] - x[i_angles]) < 1e-3 * span
                if at_box.any():
                    ypr_se[at_box] = np.inf
                    warn.append(f"installation angle(s) {', '.join(np.array(ANGLE_NAMES)[at_box])} held by the search box "
                                f"(+-{np.rad2deg(self.config.installation_bound_rad):g} deg around "
                                f"({np.rad2deg(self.yaw_guess):+.2f}, 0, 0) deg): not determined, reported as null; widen "
                                "installation_bound_rad or check the attitude reference")
        for msg in warn:
            warnings.warn(msg, stacklevel=3)
        vk = None
        if self.knots is not None:
            k = len(self.knots)
            vk = x[-3 * k:].reshape(k, 3)
        return CalibrationResult(
            radius_vectors_m=radius, radius_vectors_se_m=radius_se, installation_ypr_rad=ypr,
            installation_ypr_se_rad=ypr_se, installation_determined=not self.head_sensor and bool(np.all(np.isfinite(ypr_se))),
            attitude=p_att, attitude_frame=self.frame, lever_arms_sensor_m=r_s, lever_arms_sensor_se_m=se_r, lever_arms_cov_m2=cov_r,
            objective=float(ms.objective), max_constraint_violation=viol, formulation=self.config.formulation,
            timing=self.timing, noise_sigma=dict(self.sigma), chi2_per_channel=chi2, multistart=ms, uncertainty=unc,
            x_names=list(self.names), x=x, x_se=se_x, config=self.config,
            velocity_knots_s=self.knots, velocity_knots_m_s=vk, heading_misalignment_rad=misalignment,
            heading_misalignment_se_rad=misalignment_se, warnings=warn,
            jacobian="assembled" if self.assembled else "symbolic", attitude_source=self.attitude_source,
            attitude_source_reason=self.attitude_reason,
        )

def channel_slices(channels: list[tuple[str, int]]) -> dict:
    """Slice of each channel in the stacked residual vector, from (name, length) in stacking order."""
    ends = np.cumsum([n for _, n in channels])
    return {ch: slice(int(end - n), int(end)) for (ch, n), end in zip(channels, ends)}


def calibrate(case: Case, config: CalibrationConfig | None = None) -> CalibrationResult:
    """Joint calibration of one case (see module docstring)."""
    return CalibrationProblem(case, config or CalibrationConfig()).solve()
