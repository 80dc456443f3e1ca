"""The measurement model of a survey: one or several runs of one boat at one site, built once.

Calibration and diagnosis both pose their NLPs on it. Unknowns, in blocks owned by an
:class:`Unknowns` layout (names, scales, bounds, offsets):

* shared by the runs (the platform): the lever-arm block of the formulation
  (:mod:`.formulations`), the installation angles (vessel-frame sensor; a head sensor
  cannot see them), the heading correction of a head sensor against a moving reference
  (misalignment: compass error plus declination; optionally the one-cycle deviation
  B (sin psi - mean) + C (cos psi - mean), :func:`~adcpdyn.models.sensors.compass_correction`,
  with a prior on B and C so that what the headings leave open is carried, not assumed zero);
* shared by the runs of one site: the moving-bed velocity (north, east), constant or a
  piecewise-linear function of the position along the section;
* per run: the attitude model of the sensor (or none: the sensor's samples, or a model
  frozen by the two-stage method) and the navigation velocity of G as a piecewise-linear
  curve in the Earth frame.

Residual channels per run (model - measurement; heading measurement - model): attitude
samples (with a motion model), bottom-track radials (the bottom track measures the
transducer's velocity over a bed that moves: V - V_bed), slant ranges, the reference
velocity of its body point (V + dLambda/dt p, erratum 6). A head sensor's corrected heading
turns its beams into true north; navigation, reference and bed are all true-Earth.
Each channel carries its run, its rows' times and a mask (NaN data are masked, never
dropped), so noise levels, chi-square, standard errors and residual colour are per run.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..cases.case import Case
from ..models.janus import beam_to_instrument
from ..models.kinematics import centre_of_rotation_depth
from ..models.measurement import bottom_track_function
from ..models.motion import (HEADING_CORRECTION_SIZE, LOCAL_ATTITUDE_SIZE, AttitudeParams, SampledAttitude,
                             attitude_function, heading_corrected_function, local_attitude_function)
from ..models.rotations import course_difference_rad, euler_matrix
from ..models.sensors import reference_point_velocity
from .attitude_fit import AttitudeFit
from .formulations import AXES, lever_block
from .row_jacobian import RowBlock, RowJacobian

GROUPS = ("heading", "pitch", "roll", "bt", "range", "reference")
NED = ("north", "east", "down")
ATTITUDE_SOURCES = ("model", "samples", "frozen")
MOVING_BEDS = ("off", "constant", "section")
ANGLE_NAMES = ("installation_yaw", "installation_pitch", "installation_roll")
HEADING_NAMES = ("heading_misalignment", "compass_deviation_sin", "compass_deviation_cos")
BED_SCALE_M_S = 0.05
REFERENCE_MARGIN_KNOTS = 1.0  # reference samples kept up to this many knot intervals beyond the pings


def hat_basis(times, knots) -> np.ndarray:
    """Piecewise-linear interpolation weights, (len(times), len(knots)); constant beyond the ends."""
    eye = np.eye(len(knots))
    return np.column_stack([np.interp(times, knots, eye[:, k]) for k in range(len(knots))])


def bt_noise_from_error_velocity(case: Case) -> float:
    """Beam noise from the error velocity (immune to rigid motion): robust MAD estimate."""
    _, e = beam_to_instrument(case.instrument.beam_directions())
    err = case.pings.bt_radial_m_s @ e
    err = err[np.isfinite(err)]
    if err.size < 5:
        return 0.01
    mad = 1.4826 * np.median(np.abs(err - np.median(err)))
    return float(max(mad / np.linalg.norm(e), 1e-4))


def reference_noise_from_differences(time_s, velocity_m_s) -> float:
    """Reference velocity noise from first differences (white noise: sd(diff) = sqrt 2 sigma),
    robust MAD over the horizontal axes; an upper bound when the vessel accelerates."""
    v = np.asarray(velocity_m_s, dtype=float)[:, :2]
    d = np.diff(v, axis=0)
    d = d[np.all(np.isfinite(d), axis=1)].ravel()
    if d.size < 10:
        return 0.02
    return float(max(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2), 1e-3))


def initial_noise(case: Case, fit: AttitudeFit | None, with_attitude: bool) -> dict:
    """Independent noise levels to start from: attitude pre-fit residuals, the bottom track's
    error velocity, the reference's first differences, 2 cm for ranges."""
    s = {"bt": bt_noise_from_error_velocity(case), "range": 0.02}
    if with_attitude and fit is not None:
        s.update(heading=max(fit.sigmas[0], 1e-4), pitch=max(fit.sigmas[1], 1e-4), roll=max(fit.sigmas[2], 1e-4))
    ref = case.reference
    if ref is not None and ref.time_s is not None and ref.velocity_m_s is not None:
        s["reference"] = reference_noise_from_differences(ref.time_s, ref.velocity_m_s)
    return s


def attitude_bounds(params: AttitudeParams, min_decay: float = 0.0, decay_scale: float = 0.05):
    """Names, scales and bounds of an attitude block (frequencies kept within -20/+25 % of the
    pre-fit's, decays in [min_decay, 3] 1/s, biases within +-90 deg)."""
    lay = params.layout
    s = lay.slices()
    scale, lo, hi = np.ones(lay.size), np.full(lay.size, -np.inf), np.full(lay.size, np.inf)
    for k, (w, _) in enumerate(params.modes):
        i = s["modes"].start + 2 * k
        scale[i], lo[i], hi[i] = 0.01 * w, 0.8 * w, 1.25 * w
        scale[i + 1], lo[i + 1], hi[i + 1] = decay_scale, min_decay, 3.0
    for axis in ("roll", "pitch", "yaw"):
        cs = getattr(params, f"{axis}_cs")
        scale[s[f"{axis}_cs"]] = np.repeat(np.maximum(np.hypot(cs[:, 0], cs[:, 1]), 1e-3), 2)
    for axis in ("roll", "pitch"):
        i = s[f"{axis}_bias"].start
        scale[i], lo[i], hi[i] = 0.01, -np.pi / 2, np.pi / 2
    scale[s["yaw_trend"]] = [1.0 if k == 0 else 0.01**k for k in range(lay.yaw_trend_order + 1)]
    return lay.names(), scale, lo, hi


class Unknowns:
    """The decision vector as named blocks: each block's symbol, names, scales and bounds,
    and where it sits (``slices[key]``)."""

    def __init__(self):
        self.symbols, self.names, self.slices = [], [], {}
        self._scale, self._lo, self._hi = [], [], []

    def add(self, key: str, names, scale, lo, hi, sym: ca.MX | None = None) -> ca.MX:
        """A block of unknowns (a new symbol, or ``sym`` when a model built it) -> its symbol."""
        n = len(names)
        sym = ca.MX.sym(key, n) if sym is None else sym
        start = len(self.names)
        self.slices[key] = slice(start, start + n)
        self.symbols.append(sym)
        self.names += list(names)
        for target, value in ((self._scale, scale), (self._lo, lo), (self._hi, hi)):
            target.extend(np.broadcast_to(np.asarray(value, dtype=float), (n,)).tolist())
        return sym

    @property
    def x(self) -> ca.MX:
        return ca.vertcat(*self.symbols) if self.symbols else ca.MX(0, 1)

    @property
    def scale(self) -> np.ndarray:
        return np.array(self._scale, dtype=float)

    @property
    def lower(self) -> np.ndarray:
        return np.array(self._lo, dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array(self._hi, dtype=float)

    def index(self, key: str) -> np.ndarray:
        s = self.slices.get(key)
        return np.arange(s.start, s.stop) if s is not None else np.zeros(0, dtype=int)


@dataclass(frozen=True)
class Channel:
    """One residual channel of one run: ``name`` as in CALIB.json (heading, bt_beam1,
    range_beam2, reference_north, ...), its rows' times and mask."""

    run: int
    name: str
    time_s: np.ndarray
    mask: np.ndarray

    @property
    def size(self) -> int:
        return int(self.time_s.size)

    @property
    def group(self) -> str:
        return self.name.split("_")[0]


@dataclass
class RunSetup:
    """The numeric decisions of one run, made before anything symbolic is built.

    ``attitude_source``: ``model`` (motion-model unknowns of this run), ``samples`` (the
    sensor's samples interpolated linearly, data) or ``frozen`` (a model fixed beforehand,
    the two-stage method). ``knots``: navigation-velocity knot times (None: stationary).
    ``reference_rows``: which reference samples enter (inside the pings' span).
    ``section_position``: position of each ping along the section in [0, 1] (section bed).
    """

    case: Case
    fit: AttitudeFit
    attitude_source: str
    timing: str
    knots: np.ndarray | None
    use_ranges: bool
    reference_rows: np.ndarray | None
    attitude_reason: str = ""
    section_position: np.ndarray | None = None
    samples: SampledAttitude | None = field(default=None, init=False)

    def __post_init__(self):
        if self.attitude_source not in ATTITUDE_SOURCES:
            raise ValueError(f"attitude_source: expected one of {list(ATTITUDE_SOURCES)}, got {self.attitude_source!r}")
        if self.attitude_source == "samples":
            a = self.case.attitude
            ypr = a.ypr()
            ok = np.all(np.isfinite(ypr), axis=1)
            self.samples = SampledAttitude(a.time_s[ok], ypr[ok])

    @property
    def moving_reference(self) -> bool:
        return self.reference_rows is not None and self.reference_rows.size > 0

    @property
    def reference_time_s(self) -> np.ndarray:
        return self.case.reference.time_s[self.reference_rows]

    @property
    def reference_velocity_m_s(self) -> np.ndarray:
        return self.case.reference.velocity_m_s[self.reference_rows]


def knot_times(case: Case, interval_s: float | None) -> np.ndarray | None:
    """Navigation knots over the pings' span (None when the vessel is known to stay put).

    Default spacing: five reference intervals (or ping intervals without a reference), at
    least 1/50 of the run. Knots cover the pings only: a reference recorded far outside
    them (a clock off by hours) cannot stretch the problem.
    """
    ref = case.reference
    if ref is not None and ref.stationary:
        return None
    t = case.pings.time_s
    duration = float(t[-1] - t[0])
    if interval_s is None:
        if ref is not None and ref.time_s is not None and ref.time_s.size > 1:
            interval_s = max(5 * float(np.median(np.diff(ref.time_s))), duration / 50)
        else:
            interval_s = max(5 * float(np.median(np.diff(t))), duration / 30)
    n_knots = max(2, int(np.ceil(duration / interval_s)) + 1)
    return np.linspace(t[0], t[-1], n_knots)


def reference_rows(case: Case, knots: np.ndarray | None) -> np.ndarray | None:
    """Indices of the reference samples inside the pings' span (plus one knot interval);
    a one-line error when a moving reference has none there."""
    ref = case.reference
    if ref is None or ref.stationary or ref.time_s is None or ref.velocity_m_s is None:
        return None
    t = case.pings.time_s
    margin = REFERENCE_MARGIN_KNOTS * (float(np.median(np.diff(knots))) if knots is not None and knots.size > 1 else 0.0)
    inside = (ref.time_s >= t[0] - margin) & (ref.time_s <= t[-1] + margin)
    usable = inside & np.any(np.isfinite(ref.velocity_m_s[:, :2]), axis=1)
    if usable.sum() < 2:
        raise ValueError(f"{case.name}: reference.time_s: expected reference samples within the pings' span "
                         f"[{t[0]:.6g}, {t[-1]:.6g}] s, got {int(usable.sum())} usable of {ref.time_s.size} "
                         f"(reference spans [{ref.time_s[0]:.6g}, {ref.time_s[-1]:.6g}] s)")
    return np.flatnonzero(inside)


def section_positions(runs: list[RunSetup]) -> None:
    """Position of every ping along the section, 0 at the bank where the first run starts and
    1 at the other, from the reference velocity integrated over each run and projected on the
    survey's mean crossing direction; sets ``run.section_position``. Each run is taken to span
    the section (a discharge transect runs bank to bank)."""
    tracks, directions = [], []
    for run in runs:
        if not run.moving_reference:
            raise ValueError(f"{run.case.name}: moving_bed 'section' needs a moving reference velocity")
        t, v = run.reference_time_s, np.nan_to_num(run.reference_velocity_m_s[:, :2])
        x = np.vstack([np.zeros(2), np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], axis=0)])
        tracks.append((t, x))
        directions.append(x[-1] - x[0])
    axis = directions[0] / max(np.linalg.norm(directions[0]), 1e-9)
    along = [np.sign(np.dot(d, axis)) or 1.0 for d in directions]
    axis = np.sum([a * d for a, d in zip(along, directions)], axis=0)
    axis = axis / max(np.linalg.norm(axis), 1e-9)
    for run, (t, x) in zip(runs, tracks):
        u = x @ axis  # every run on the same axis: a run in either direction reads 0 at the same bank
        s = (u - u.min()) / max(u.max() - u.min(), 1e-9)
        run.section_position = np.clip(np.interp(run.case.pings.time_s, t, s), 0.0, 1.0)


@dataclass(frozen=True)
class ModelSpec:
    """What the survey model contains (decided from the configuration and the data).

    ``installation``: ``estimate`` (vessel-frame sensor; box of +-``installation_bound_rad``
    about (``yaw_centre_rad``, 0, 0)), ``fixed`` (at ``nominal_installation_ypr_rad``) or
    ``head`` (sensor in the head: beams in the head frame, angles unseen).
    ``heading``: ``off``, ``misalignment`` or ``deviation`` (misalignment plus B, C); with
    ``deviation_prior_rad`` the deviation terms get a Gaussian prior N(0, prior^2) each (two
    pseudo-residual rows): what the headings do not fix comes from the prior, and its
    uncertainty reaches what it is confounded with (the bed, on two opposite courses).
    """

    formulation: str = "exact"
    epsilon_rel: float = 0.05
    tangential: str = "consistent"
    lever_box_m: float = 10.0
    installation: str = "estimate"
    installation_bound_rad: float = float(np.deg2rad(15.0))
    nominal_installation_ypr_rad: tuple = (0.0, 0.0, 0.0)
    yaw_centre_rad: float = 0.0
    heading: str = "off"
    deviation_prior_rad: float | None = None
    moving_bed: str = "off"
    bed_knots: int = 3


class SurveyModel:
    """Residuals of every run as one MX vector over the unknowns; see the module docstring.

    Attributes used by the NLPs: ``unknowns`` (:class:`Unknowns`), ``x``, ``raw`` (unweighted
    residuals, model - measurement, 0 where masked), ``channels``, ``mask``, ``g``/``lbg``/``ubg``
    (lever-arm constraints), ``r`` (4x3 lever arms in the sensor frame), ``ypr_st`` (angles as
    reported), ``heading`` (h), ``bed`` (bed parameters (n, 2)), ``assembled_nodes``.
    """

    def __init__(self, runs: list[RunSetup], spec: ModelSpec):
        if not runs:
            raise ValueError("runs: expected at least one run")
        self.runs, self.spec = runs, spec
        first = runs[0].case
        self.frame = first.attitude.frame
        self.head_sensor = self.frame == "transducer"
        for run in runs[1:]:
            if run.case.attitude.frame != self.frame:
                raise ValueError(f"{run.case.name}: attitude.frame: expected {self.frame!r} as in {first.name} "
                                 f"(one boat, one installation), got {run.case.attitude.frame!r}")
        self.beam_dirs_t = first.instrument.beam_directions()
        self.pos_t = first.instrument.transducer_positions()
        u = self.unknowns = Unknowns()
        self.attitude_syms: list = []
        for k, run in enumerate(runs):  # per-run attitude first: their blocks lead the vector, as before
            if run.attitude_source == "model":
                names, scale, lo, hi = attitude_bounds(run.fit.params)
                prefix = f"run{k + 1}/" if len(runs) > 1 else ""
                self.attitude_syms.append(u.add(f"attitude{k}", [prefix + n for n in names], scale, lo, hi))
            elif run.attitude_source == "frozen":
                self.attitude_syms.append(ca.MX(ca.DM(run.fit.params.pack())))
            else:
                self.attitude_syms.append(ca.MX(0, 1))
        # ---- shared unknowns: heading correction or installation angles, lever arms, bed
        self.heading = None
        if spec.heading != "off":
            names = HEADING_NAMES if spec.heading == "deviation" else HEADING_NAMES[:1]
            c = spec.yaw_centre_rad
            lo, hi = [c - np.pi, -0.3, -0.3][: len(names)], [c + np.pi, 0.3, 0.3][: len(names)]
            h = u.add("heading", names, [0.02, 0.01, 0.01][: len(names)], lo, hi)
            self.heading = ca.vertcat(h, ca.MX.zeros(HEADING_CORRECTION_SIZE - len(names)))
        if spec.installation == "estimate":
            b = spec.installation_bound_rad
            centre = np.array([spec.yaw_centre_rad, 0.0, 0.0])
            self.ypr_st = u.add("installation", ANGLE_NAMES, 0.02, centre - b, centre + b)
            self.ypr_beams = self.ypr_st
        elif spec.installation == "fixed":
            self.ypr_st = self.ypr_beams = ca.MX(ca.DM(np.asarray(spec.nominal_installation_ypr_rad, dtype=float)))
        else:  # head sensor: the beams in the head frame; a heading misalignment is reported as the yaw
            self.ypr_beams = ca.MX(ca.DM.zeros(3))
            self.ypr_st = ca.vertcat(self.heading[0], ca.MX.zeros(2)) if self.heading is not None else self.ypr_beams
        Lst = euler_matrix(self.ypr_beams[0], self.ypr_beams[1], self.ypr_beams[2])
        self.lever = lever_block(spec.formulation, Lst, self.pos_t, spec.epsilon_rel)
        box = spec.lever_box_m
        u.add("lever", self.lever.names, box / 5, -box, box, sym=self.lever.x)
        self.r, self.g, self.lbg, self.ubg = self.lever.r, self.lever.g, self.lever.lbg, self.lever.ubg
        self.bed = None
        if spec.moving_bed != "off":
            n_bed = 1 if spec.moving_bed == "constant" else max(2, int(spec.bed_knots))
            if spec.moving_bed == "section":
                section_positions(runs)
            names = [f"moving_bed_{a}" for a in NED[:2]] if n_bed == 1 else \
                [f"moving_bed{j + 1}_{a}" for j in range(n_bed) for a in NED[:2]]
            self.bed = ca.reshape(u.add("moving_bed", names, BED_SCALE_M_S, -3.0, 3.0), 2, n_bed).T  # (n_bed, 2)
        # ---- per-run navigation knots (last: the assembled Jacobian finds them by block)
        self.knot_syms = []
        for k, run in enumerate(runs):
            if run.knots is None:
                self.knot_syms.append(None)
                continue
            K = run.knots.size
            speed = max(_speed_guess(run), 0.05)
            prefix = f"run{k + 1}/" if len(runs) > 1 else ""
            vk = u.add(f"velocity{k}", [f"{prefix}V{j}_{a}" for j in range(K) for a in AXES], speed, -20.0, 20.0)
            self.knot_syms.append(ca.reshape(vk, 3, K).T)
        self.x = u.x
        # the deviation is written about the survey's mean heading, so h[0] is the mean correction over it
        self.heading_centre = heading_centre(runs) if spec.heading == "deviation" else (0.0, 0.0)
        self.attitude_sensor = [self._attitude_function(run, False) for run in runs]  # the sensor's readings
        self.attitude_true = [self._attitude_function(run, True) for run in runs]  # heading corrected: the beams'
        self._build_residuals()

    # ------------------------------------------------------------------ residuals
    def _attitude_function(self, run: RunSetup, corrected: bool) -> ca.Function:
        base = local_attitude_function() if run.attitude_source == "samples" else attitude_function(run.fit.params.layout)
        return heading_corrected_function(base, *self.heading_centre) if corrected and self.heading is not None else base

    def _p_rows(self, k: int, times) -> ca.MX:
        """Attitude parameters for rows at ``times`` (columns), with the heading correction appended."""
        run = self.runs[k]
        if run.attitude_source == "samples":
            p = ca.MX(ca.DM(run.samples.params_at(times)))
            return ca.vertcat(p, ca.repmat(self.heading, 1, len(times))) if self.heading is not None else p
        p = self.attitude_syms[k]
        return ca.vertcat(p, self.heading) if self.heading is not None else p

    def bed_at(self, k: int, n: int):
        """Moving-bed velocity (n, 3) under run k's pings (zeros without a bed model)."""
        if self.bed is None:
            return None
        if self.bed.shape[0] == 1:
            return ca.repmat(ca.horzcat(self.bed, ca.MX.zeros(1, 1)), n, 1)
        H = ca.DM(hat_basis(self.runs[k].section_position, np.linspace(0, 1, self.bed.shape[0])))
        return ca.horzcat(ca.mtimes(H, self.bed), ca.MX.zeros(n, 1))

    def bed_basis(self, k: int) -> np.ndarray:
        """(N, n_bed) weights of the bed parameters under run k's pings."""
        n_bed = 0 if self.bed is None else self.bed.shape[0]
        N = self.runs[k].case.pings.n
        if n_bed <= 1:
            return np.ones((N, n_bed))
        return hat_basis(self.runs[k].section_position, np.linspace(0, 1, n_bed))

    def _build_residuals(self):
        models, channels = [], []
        self.bt_functions, self.g_depth = [], []
        n_nodes = 0
        for k, run in enumerate(self.runs):
            case, pings = run.case, run.case.pings
            N = pings.n
            att, att_c = self.attitude_sensor[k], self.attitude_true[k]
            if run.attitude_source == "model":  # the sensor's own readings: uncorrected model
                a = case.attitude
                M = a.time_s.size
                ypr_model = att.map(M)(ca.DM(a.time_s).T, self.attitude_syms[k])[0]
                ypr_meas = a.ypr()
                dpsi = np.nan_to_num(ypr_meas[:, 0]) - ca.transpose(ypr_model[0, :])
                models += [ca.atan2(ca.sin(dpsi), ca.cos(dpsi)), ca.transpose(ypr_model[1, :]) - np.nan_to_num(ypr_meas[:, 1]),
                           ca.transpose(ypr_model[2, :]) - np.nan_to_num(ypr_meas[:, 2])]
                channels += [Channel(k, n, a.time_s, np.isfinite(ypr_meas[:, j]).astype(float))
                             for j, n in enumerate(("heading", "pitch", "roll"))]
                n_nodes += att.n_instructions() * M
            bt_fun = bottom_track_function(att_c, run.timing, self.spec.tangential)
            self.bt_functions.append(bt_fun)
            depth = case.environment.depth_at_pings(N)
            g_depth = centre_of_rotation_depth(case.environment.transducer_depth_m, self.r)
            self.g_depth.append(g_depth)
            V = self.knot_syms[k]
            v_ping = ca.mtimes(ca.DM(hat_basis(pings.time_s, run.knots)), V) if V is not None else ca.MX(ca.DM.zeros(N, 3))
            bed = self.bed_at(k, N)
            v_bt = v_ping - bed if bed is not None else v_ping
            radial, rng = bt_fun.map(N)(ca.DM(pings.time_s).T, ca.DM(depth).T, g_depth, case.instrument.sound_speed_m_s,
                                        v_bt.T, self._p_rows(k, pings.time_s), self.r, self.ypr_beams,
                                        ca.DM(self.beam_dirs_t))
            n_nodes += bt_fun.n_instructions() * N
            bt = pings.bt_radial_m_s
            for i in range(4):
                models.append(ca.transpose(radial[i, :]) - np.nan_to_num(bt[:, i]))
                channels.append(Channel(k, f"bt_beam{i + 1}", pings.time_s, np.isfinite(bt[:, i]).astype(float)))
            if run.use_ranges:
                for i in range(4):
                    models.append(ca.transpose(rng[i, :]) - np.nan_to_num(pings.bt_range_m[:, i]))
                    channels.append(Channel(k, f"range_beam{i + 1}", pings.time_s,
                                            np.isfinite(pings.bt_range_m[:, i]).astype(float)))
            if run.moving_reference:
                t_ref, v_meas = run.reference_time_s, run.reference_velocity_m_s
                L = t_ref.size
                dLam = att_c.map(L)(ca.DM(t_ref).T, self._p_rows(k, t_ref))[2]
                v_model = ca.mtimes(ca.DM(hat_basis(t_ref, run.knots)), V)
                v_ref = self.reference_function(case).map(L)(v_model.T, dLam)
                for j in range(3):
                    models.append(ca.transpose(v_ref[j, :]) - np.nan_to_num(v_meas[:, j]))
                    channels.append(Channel(k, f"reference_{NED[j]}", t_ref, np.isfinite(v_meas[:, j]).astype(float)))
                n_nodes += att_c.n_instructions() * L
        if self.has_prior:  # N(0, prior^2) on B and C: a pseudo-run of its own, outside the runs' time bins
            models.append(self.heading[1:3])
            channels.append(Channel(len(self.runs), "prior_compass_deviation", np.zeros(2), np.ones(2)))
        self.raw = ca.vertcat(*models)
        self.channels = channels
        self.sigma_keys = list(dict.fromkeys((c.run, c.group) for c in channels))  # (run, group), in order
        self.row_sigma = np.concatenate([np.full(c.size, self.sigma_keys.index((c.run, c.group))) for c in channels])
        self.mask = np.concatenate([c.mask for c in channels])
        self.row_run = np.concatenate([np.full(c.size, c.run) for c in channels])
        self.row_time = np.concatenate([c.time_s for c in channels])
        self.assembled_nodes = n_nodes

    def reference_point_sensor(self, case: Case) -> np.ndarray:
        """The reference's body point in the sensor frame (head sensor: turned by the nominal Lambda_tb)."""
        p = np.asarray(case.reference.point_body_m, dtype=float)
        if self.head_sensor:
            p = np.asarray(euler_matrix(*self.spec.nominal_installation_ypr_rad)).T @ p
        return p

    def reference_function(self, case: Case) -> ca.Function:
        """``(v_a (3), dLambda/dt (3x3)) -> velocity`` of the reference's body point (true Earth)."""
        v, dLam = ca.SX.sym("v_a", 3), ca.SX.sym("dLambda", 3, 3)
        return ca.Function("reference_velocity", [v, dLam],
                           [reference_point_velocity(v, dLam, ca.DM(self.reference_point_sensor(case)))])

    @property
    def has_prior(self) -> bool:
        return self.spec.heading == "deviation" and self.spec.deviation_prior_rad is not None

    @property
    def prior_rows(self) -> np.ndarray:
        """Mask of the prior's pseudo-residual rows (their information is known, not sampled)."""
        return self.row_run == len(self.runs)

    # ------------------------------------------------------------------ bookkeeping
    def channel_slices(self) -> dict:
        """Slice of each channel in the stacked residuals, keyed by (run, name)."""
        ends = np.cumsum([c.size for c in self.channels])
        return {(c.run, c.name): slice(int(e - c.size), int(e)) for c, e in zip(self.channels, ends)}

    def initial_sigmas(self) -> dict:
        """{(run, group): noise level} from independent estimates (:func:`initial_noise`)."""
        out = {}
        for k, run in enumerate(self.runs):
            guess = initial_noise(run.case, run.fit, run.attitude_source == "model")
            for key in self.sigma_keys:
                if key[0] == k:
                    out[key] = guess.get(key[1], 0.02)
        if self.has_prior:
            out[(len(self.runs), "prior")] = float(self.spec.deviation_prior_rad)
        return out

    def weights(self, sigma: dict) -> np.ndarray:
        return self.mask / np.array([sigma[key] for key in self.sigma_keys])[self.row_sigma]

    def reestimate_sigmas(self, raw: np.ndarray, n_unknowns: int, sigma: dict) -> dict:
        """Each (run, group)'s noise level from the residuals, degrees of freedom shared out."""
        raw = np.asarray(raw, dtype=float).ravel()
        dof = max(1.0 - n_unknowns / max(float(self.mask.sum()), 1.0), 0.1)
        out = dict(sigma)
        for i, key in enumerate(self.sigma_keys):
            if key[1] == "prior":  # a prior's width is stated, not estimated
                continue
            m = (self.row_sigma == i) & (self.mask > 0)
            if m.sum() > 3:
                out[key] = float(max(np.sqrt(np.sum(raw[m] ** 2) / (m.sum() * dof)), 1e-6))
        return out

    def chi2(self, e: np.ndarray) -> dict:
        """{(run, channel): mean squared weighted residual over the channel's valid rows}."""
        out = {}
        for key, s in self.channel_slices().items():
            m = self.mask[s] > 0
            out[key] = float(np.sum(np.asarray(e)[s][m] ** 2) / max(m.sum(), 1))
        return out

    # ------------------------------------------------------------------ assembled Jacobian
    def shared_vector(self) -> tuple[ca.MX, dict]:
        """s(x): [lever arms (12), beam angles (3), heading correction (3), bed (2 n_bed), then per
        run: attitude parameters, depth of G], with each piece's indices."""
        parts, index, at = [], {}, 0

        def put(key, expr):
            nonlocal at
            parts.append(expr)
            index[key] = np.arange(at, at + expr.shape[0])
            at += expr.shape[0]

        put("r", ca.vec(self.r.T))
        put("ypr_beams", self.ypr_beams)
        put("heading", self.heading if self.heading is not None else ca.MX(0, 1))
        put("bed", ca.vec(self.bed.T) if self.bed is not None else ca.MX(0, 1))
        for k in range(len(self.runs)):
            put(f"attitude{k}", self.attitude_syms[k] if self.runs[k].attitude_source == "model" else ca.MX(0, 1))
            put(f"g_depth{k}", self.g_depth[k])
        return ca.vertcat(*parts), index

    def row_jacobian(self, z: ca.MX, subs, threads: int) -> RowJacobian:
        """The residual Jacobian assembled from per-row Jacobians (:mod:`.row_jacobian`): each run's
        attitude, bottom-track and reference rows as blocks over their share of s and their knots."""
        shared, index = self.shared_vector()
        shared_z = ca.substitute([shared], *subs)[0]
        u = self.unknowns
        n_bed = 0 if self.bed is None else self.bed.shape[0]
        has_h = self.heading is not None
        frozen = lambda run: ca.DM(run.fit.params.pack())
        blocks, offset = [], 0
        for k, run in enumerate(self.runs):
            case, pings = run.case, run.case.pings
            sampled = run.attitude_source == "samples"
            n_att = index[f"attitude{k}"].size
            n_local = LOCAL_ATTITUDE_SIZE if sampled else 0
            local = run.samples.params_at if sampled else (lambda t: np.zeros((0, np.size(t))))
            knots_cols = None if run.knots is None else u.index(f"velocity{k}").reshape(-1, 3)
            basis = (lambda t, run=run: None if run.knots is None else sp.csr_matrix(hat_basis(t, run.knots)))
            v = ca.SX.sym("v", 3)
            if run.attitude_source == "model":
                att = self.attitude_sensor[k]
                d1, s = ca.SX.sym("d", 1), ca.SX.sym("s", n_att)
                blocks.append(RowBlock(ca.Function("attitude_rows", [d1, v, s], [att(d1, s)[0]]), case.attitude.time_s[None, :],
                                       offset, sign=np.array([-1.0, 1.0, 1.0]), shared_index=index[f"attitude{k}"]))
                offset += 3 * case.attitude.time_s.size
            # bottom track: s = [attitude, r, ypr_beams, g_depth, heading, bed]
            idx = np.concatenate([index[f"attitude{k}"], index["r"], index["ypr_beams"], index[f"g_depth{k}"],
                                  index["heading"], index["bed"]])
            s = ca.SX.sym("s", idx.size)
            p_att, r = s[:n_att], ca.reshape(s[n_att:n_att + 12], 3, 4).T
            ypr_b, g_depth = s[n_att + 12:n_att + 15], s[n_att + 15]
            h = s[n_att + 16:n_att + 16 + (HEADING_CORRECTION_SIZE if has_h else 0)]
            bed = ca.reshape(s[idx.size - 2 * n_bed:], 2, n_bed).T if n_bed else None
            d2 = ca.SX.sym("d", 2 + n_local + (n_bed if n_bed > 1 else 0))
            p_row = d2[2:2 + n_local] if sampled else (p_att if run.attitude_source == "model" else frozen(run))
            if has_h:
                p_row = ca.vertcat(p_row, h)
            v_bt = v
            if bed is not None:
                weights = d2[2 + n_local:] if n_bed > 1 else ca.DM.ones(1)
                v_bt = v - ca.vertcat(ca.mtimes(bed.T, weights), 0)
            radial, rng = self.bt_functions[k](d2[0], d2[1], g_depth, case.instrument.sound_speed_m_s, v_bt, p_row, r, ypr_b,
                                               ca.DM(self.beam_dirs_t))
            out = ca.vertcat(radial, rng) if run.use_ranges else radial
            data = [pings.time_s[None, :], case.environment.depth_at_pings(pings.n)[None, :], local(pings.time_s)]
            if n_bed > 1:
                data.append(self.bed_basis(k).T)
            blocks.append(RowBlock(ca.Function("bottom_track_rows", [d2, v, s], [out]), np.vstack(data), offset,
                                   velocity_basis=basis(pings.time_s), shared_index=idx, knot_columns=knots_cols))
            offset += out.shape[0] * pings.n
            if run.moving_reference:
                t_ref = run.reference_time_s
                idx = np.concatenate([index[f"attitude{k}"], index["heading"]])
                s = ca.SX.sym("s", idx.size)
                d1 = ca.SX.sym("d", 1 + n_local)
                p_row = d1[1:] if sampled else (s[:n_att] if run.attitude_source == "model" else frozen(run))
                if has_h:
                    p_row = ca.vertcat(p_row, s[n_att:])
                dLam = self.attitude_true[k](d1[0], p_row)[2]
                vs = self.reference_function(case)(v, dLam)
                blocks.append(RowBlock(ca.Function("reference_rows", [d1, v, s], [vs]), np.vstack([t_ref[None, :], local(t_ref)]),
                                       offset, velocity_basis=basis(t_ref), shared_index=idx, knot_columns=knots_cols))
                offset += 3 * t_ref.size
        if self.has_prior:
            d, v, s = ca.SX.sym("d", 1), ca.SX.sym("v", 3), ca.SX.sym("s", 2)
            blocks.append(RowBlock(ca.Function("prior_rows", [d, v, s], [s]), np.zeros((1, 1)), offset,
                                   shared_index=index["heading"][1:3]))
            offset += 2
        if offset != self.raw.shape[0]:
            raise RuntimeError(f"assembled Jacobian: {offset} rows, residuals have {self.raw.shape[0]}")
        return RowJacobian(z, shared_z, blocks, self.raw.shape[0], None, u.scale, threads=threads)

    # ------------------------------------------------------------------ starting values
    def velocity_guess(self, k: int) -> np.ndarray:
        """Knot velocities (K, 3) from the reference (NaN-aware per axis), else from the static
        bottom-track velocity; an axis with no data starts at zero."""
        run = self.runs[k]
        if run.moving_reference:
            t, v = run.reference_time_s, run.reference_velocity_m_s
        else:
            from .asc import asc

            corr = asc(run.case)
            t, v = corr.time_s, corr.vessel_velocity_m_s
        half = np.median(np.diff(run.knots)) / 2
        out = np.zeros((run.knots.size, 3))
        for j in range(3):
            ok = np.isfinite(v[:, j])
            if ok.sum() == 0:
                continue
            for i, tk in enumerate(run.knots):
                sel = ok & (np.abs(t - tk) <= half)
                out[i, j] = np.mean(v[sel, j]) if sel.any() else np.interp(tk, t[ok], v[ok, j])
        return out


def _speed_guess(run: RunSetup) -> float:
    if run.moving_reference:
        v = run.reference_velocity_m_s[:, :2]
        speed = np.linalg.norm(v, axis=1)
        speed = speed[np.isfinite(speed)]
        if speed.size:
            return float(np.median(speed))
    return 0.1


def course_offset_rad(runs: list[RunSetup]) -> float:
    """Course of the reference minus course of the static (ASC) bottom-track velocity over all
    runs' pings, radians (circular mean); 0 without a moving reference."""
    from .asc import asc

    diffs = []
    for run in runs:
        if not run.moving_reference:
            continue
        v = asc(run.case).vessel_velocity_m_s
        t = run.case.pings.time_s
        tr, vr = run.reference_time_s, run.reference_velocity_m_s
        ok_r = np.all(np.isfinite(vr[:, :2]), axis=1)
        if ok_r.sum() < 2:
            continue
        g = np.column_stack([np.interp(t, tr[ok_r], vr[ok_r, j]) for j in range(2)])
        ok = np.all(np.isfinite(v[:, :2]), axis=1) & (np.hypot(*g.T) > 0.1)
        if ok.any():
            diffs.append(course_difference_rad(g[ok], v[ok, :2]))
    if not diffs or np.concatenate(diffs).size < 3:
        return 0.0
    return float(np.angle(np.mean(np.exp(1j * np.concatenate(diffs)))))


def heading_centre(runs: list[RunSetup]) -> tuple[float, float]:
    """Mean sine and cosine of the sensor heading over every run's attitude samples."""
    psi = np.concatenate([r.case.attitude.heading_rad[np.isfinite(r.case.attitude.heading_rad)] for r in runs])
    return (float(np.mean(np.sin(psi))), float(np.mean(np.cos(psi)))) if psi.size else (0.0, 0.0)


def heading_span(runs: list[RunSetup]) -> float:
    """Smallest eigenvalue of the covariance of (sin psi, cos psi) over every run's attitude
    samples: 0.5 for headings all round the compass, 0 for one course or two opposite ones
    (where a one-cycle compass deviation cannot be told from a moving bed)."""
    psi = np.concatenate([r.case.attitude.heading_rad[np.isfinite(r.case.attitude.heading_rad)] for r in runs])
    if psi.size < 3:
        return 0.0
    return float(np.linalg.eigvalsh(np.cov(np.vstack([np.sin(psi), np.cos(psi)])))[0])


def default_threads(workers: int, n_starts: int) -> int:
    """Cores the multistart's workers leave free, for the per-row Jacobians of long runs."""
    return max(1, (os.cpu_count() or 1) // max(1, min(workers, n_starts)))
