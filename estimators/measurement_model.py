"""The measurement model of a survey: one or several runs of one boat at one site, built once.

Calibration and diagnosis both pose their NLPs on it. Unknowns, in blocks owned by an
:class:`.unknowns.Unknowns` layout (names, scales, bounds, offsets):

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

import copy
import os
import re
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..cases.case import Case
from ..models.kinematics import centre_of_rotation_depth
from ..models.measurement import bottom_track_function
from ..models.motion import (HEADING_CORRECTION_SIZE, LOCAL_ATTITUDE_SIZE,
                             attitude_function, evaluate_attitude, heading_corrected_function, local_attitude_function,
                             with_extra_mode)
from ..models.rotations import euler_matrix, euler_matrix_and_rate, unskew
from ..models.sensors import compass_correction, reference_point_velocity
from ..solvers.compiled import compiled
from .formulations import AXES, lever_block
from .knots import hat_basis, hat_basis_dm, hat_basis_sparse, sparse_dm, walk_increments, window_basis_sparse
from .reference_rows import ROTATION_STEP_S, as_constants, reference_numbers
from .row_jacobian import RowBlock, RowJacobian
from .run_setup import Channel, RunSetup, heading_centre, section_positions, speed_guess
from .unknowns import Unknowns, attitude_bounds

GROUPS = ("heading", "pitch", "roll", "bt", "range", "reference", "motion", "vertical")
PRIOR_GROUPS = ("motion", "vertical")  # pseudo-observations of priors (the walk's increments, heave's levels), not data
VELOCITY_NAME = re.compile(r"V\d+_[xyz]")  # a navigation velocity unknown (V<knot>_<axis>, after any run prefix)
NED = ("north", "east", "down")
MOVING_BEDS = ("off", "constant", "section")
ANGLE_NAMES = ("installation_yaw", "installation_pitch", "installation_roll")
HEADING_NAMES = ("heading_misalignment", "compass_deviation_sin", "compass_deviation_cos")
BED_SCALE_M_S = 0.05


def channel_slices(channels: list[tuple[str, int]]) -> dict:
    """Slice of each channel in the stacked residual vector, from (name, length) in stacking order."""
    ends = np.cumsum([n for _, n in channels])
    return {ch: slice(int(end - n), int(end)) for (ch, n), end in zip(channels, ends)}


def _reference_velocity() -> ca.Function:
    v, dLam, p = ca.SX.sym("v_a", 3), ca.SX.sym("dLambda", 3, 3), ca.SX.sym("p", 3)
    return ca.Function("reference_velocity", [v, dLam, p], [reference_point_velocity(v, dLam, p)])


REFERENCE_VELOCITY = _reference_velocity()  # (v_a, dLambda/dt, body point in the sensor frame) -> its velocity


@dataclass(frozen=True)
class EffectTerm:
    """An effect of the catalog (:mod:`adcpdyn.models.effects`) in the model: shared by every run
    (``run`` None: compass, beam angles, sound speed, latency, lever arms) or one run's own
    (moving bed, heave, forced roll)."""

    effect: object
    run: int | None = None


class EffectContext:
    """The numbers of one run the effects' symbolic hooks need (times, heading directions,
    residual peaks that seed an oscillation's frequency)."""

    def __init__(self, run: RunSetup, peaks: dict | None = None):
        case = run.case
        self.case = case
        self.ping_time_s = case.pings.time_s
        self.reference_time_s = run.reference_time_s if run.moving_reference else None
        times = [self.ping_time_s] + ([self.reference_time_s] if self.reference_time_s is not None else [])
        self.t0_s = float(min(t[0] for t in times))
        self.t1_s = float(max(t[-1] for t in times))
        self.peaks = peaks or {}
        psi = lambda t: (run.samples.heading_at(t) if run.samples is not None
                         else evaluate_attitude(run.fit.params, t)["ypr"][:, 0])
        unit = lambda a: ca.DM(np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)]))
        self.heading_dir_ping = unit(psi(self.ping_time_s))
        self.heading_dir_reference = unit(psi(self.reference_time_s)) if self.reference_time_s is not None else None
        self.reference_slope = None  # the reference point's velocity slope at the rows' times, set by the model
        self.reference_shift_s = run.reference_shift_s  # the delay the rows are taken about

    def residual_peak(self, key: str) -> float:
        return float(self.peaks.get(key, 1.0))


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
    min_decay_1_s: float = 0.0  # lower bound of the modes' decay (the diagnosis's base: free decays only)


class SurveyModel:
    """Residuals of every run as one MX vector over the unknowns; see the module docstring.

    Attributes used by the NLPs: ``unknowns`` (:class:`.unknowns.Unknowns`), ``x``, ``raw`` (unweighted
    residuals, model - measurement, 0 where masked), ``channels``, ``mask``, ``g``/``lbg``/``ubg``
    (lever-arm constraints), ``r`` (4x3 lever arms in the sensor frame), ``ypr_st`` (angles as
    reported), ``heading`` (h), ``bed`` (bed parameters (n, 2)), ``assembled_nodes``.
    """

    def __init__(self, runs: list[RunSetup], spec: ModelSpec, effects=(), peaks: dict | None = None,
                 compile_min_pings: int | None = None, data_parameters: bool = False):
        if not runs:
            raise ValueError("runs: expected at least one run")
        self.runs, self.spec = runs, spec
        # the recorded numbers as parameters of the graph (``data_sym``, ``data_values``), not constants: one
        # graph, its Jacobian and solver then serve every run of the same shape (:mod:`.model_cache`)
        self.data_parameters = data_parameters
        self._data: dict = {}  # name -> (its parameter symbol, its values, column-major)
        # the per-ping models as machine code when the problem's pings (all runs') reach compile_min_pings
        self.compiled = compile_min_pings is not None and sum(r.case.pings.n for r in runs) >= compile_min_pings
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
                names, scale, lo, hi = attitude_bounds(run.fit.params, min_decay=spec.min_decay_1_s)
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
        # ---- per run: the transducer depth the slant ranges imply (the entered draft is often off by cm; with the
        # sensor in the head, H_O is defined with the vessel level and the head-frame lever arms miss its mount tilt)
        self.depth_offsets = []
        for k, run in enumerate(runs):
            prefix = f"run{k + 1}/" if len(runs) > 1 else ""
            self.depth_offsets.append(u.add(f"depth_offset{k}", [f"{prefix}transducer_depth_offset_m"], 0.05, -2.0, 2.0)
                                      if run.use_ranges else 0.0)
        # ---- effects of the catalog (the diagnosis), each with its unknowns
        self.effect_terms = []
        for i, term in enumerate(effects):
            e = term.effect
            if term.run is not None and not 0 <= term.run < len(runs):
                raise ValueError(f"effects: {e.name}: run {term.run} is not one of the {len(runs)} runs")
            if runs[term.run or 0].attitude_source == "samples" and e.needs_motion_model:
                raise ValueError(f"effect {e.name}: acts on the motion model only; the beams use the sensor's samples here")
            prefix = f"run{term.run + 1}/" if term.run is not None and len(runs) > 1 else ""
            th = (u.add(f"effect{i}", [f"{prefix}{e.name}.{p.name}" for p in e.parameters], [p.scale for p in e.parameters],
                        [p.lower for p in e.parameters], [p.upper for p in e.parameters])
                  if e.parameters else ca.MX(0, 1))
            self.effect_terms.append((term, th))
        self.contexts = [EffectContext(run, peaks) for run in runs]
        # ---- per-run navigation knots (last: the assembled Jacobian finds them by block)
        self.knot_syms = []
        for k, run in enumerate(runs):
            if run.knots is None:
                self.knot_syms.append(None)
                continue
            K = run.knots.size
            speed = max(speed_guess(run), 0.05)
            prefix = f"run{k + 1}/" if len(runs) > 1 else ""
            vk = u.add(f"velocity{k}", [f"{prefix}V{j}_{a}" for j in range(K) for a in AXES], speed, -20.0, 20.0)
            self.knot_syms.append(ca.reshape(vk, 3, K).T)
        self.x = u.x
        # the deviation is written about the survey's mean heading, so h[0] is the mean correction over it
        self.heading_centre = heading_centre(runs) if spec.heading == "deviation" else (0.0, 0.0)
        self.attitude_params, self.attitude_layouts = [], []  # per run: the motion model with the effects' extra modes
        for k, run in enumerate(runs):
            p, lay = self.attitude_syms[k], run.fit.params.layout
            for e, th in self.terms_of(k):
                extra = e.extra_mode(th)
                if extra is not None:
                    p, lay = with_extra_mode(p, lay, *extra)
            self.attitude_params.append(p)
            self.attitude_layouts.append(lay)
        self.attitude_sensor = [local_attitude_function() if run.attitude_source == "samples" else
                                attitude_function(self.attitude_layouts[k]) for k, run in enumerate(runs)]
        self.attitude_true = [self._true_attitude_function(k) for k in range(len(runs))]  # the beams'
        self._build_residuals()

    # ------------------------------------------------------------------ recorded numbers
    def _datum(self, name: str, values) -> ca.DM | ca.MX:
        """Recorded numbers in the graph (a vector is a column): a constant, or with ``data_parameters``
        a parameter of their shape, the values kept by name; a model at another reference shift gives
        its own values to the same parameter (:meth:`at_reference_shift`)."""
        v = np.asarray(values, dtype=float)
        v = v.reshape(-1, 1) if v.ndim == 1 else v
        if not self.data_parameters:
            return ca.DM(v)
        old = self._data.get(name)
        sym = old[0] if old is not None and old[0].numel() == v.size else ca.MX.sym(name, v.size)
        self._data[name] = (sym, v.ravel(order="F"))
        return ca.reshape(sym, *v.shape)

    @property
    def data_sym(self) -> ca.MX:
        """The recorded numbers' parameters, stacked (empty unless ``data_parameters``)."""
        return ca.vertcat(*[sym for sym, _ in self._data.values()]) if self._data else ca.MX(0, 1)

    @property
    def data_values(self) -> np.ndarray:
        """The recorded numbers as :attr:`data_sym` stacks them."""
        return np.concatenate([v for _, v in self._data.values()]) if self._data else np.zeros(0)

    @property
    def data_layout(self) -> tuple:
        """(name, size) of each recorded parameter, in order: part of what makes two graphs alike."""
        return tuple((name, int(sym.numel())) for name, (sym, _) in self._data.items())

    # ------------------------------------------------------------------ residuals
    def terms_of(self, k: int) -> list:
        """(effect, its unknowns) of the effects acting on run k."""
        return [(term.effect, th) for term, th in self.effect_terms if term.run is None or term.run == k]

    def _sample_terms(self, k: int) -> list:
        return [(e, th) for e, th in self.terms_of(k) if e.acts_on_samples] if self.runs[k].attitude_source == "samples" else []

    def _true_attitude_function(self, k: int) -> ca.Function:
        """The beams' attitude of run k, ``(t, p_row) -> (ypr, Lambda, dLambda_dt, Omega, omega)``: the
        motion model (heading corrected), or the sensor's samples with the heading correction and
        the sensor effects undone on them; p_row as :meth:`_p_rows` stacks it."""
        run = self.runs[k]
        if run.attitude_source != "samples":
            base = attitude_function(self.attitude_layouts[k])
            return heading_corrected_function(base, *self.heading_centre) if self.heading is not None else base
        terms = self._sample_terms(k)
        t, p = ca.SX.sym("t"), ca.SX.sym("p", LOCAL_ATTITUDE_SIZE)
        h = ca.SX.sym("h", HEADING_CORRECTION_SIZE if self.heading is not None else 0)
        ths = [ca.SX.sym(f"th{i}", th.shape[0]) for i, (_, th) in enumerate(terms)]
        tq = t
        for (e, _), th in zip(terms, ths):
            tq = e.sampled_time(tq, th)
        ypr = p[1:4] + p[4:7] * (tq - p[0])
        tilt = ypr[1:3]
        for (e, _), th in zip(terms, ths):
            tilt = e.sampled_tilt(tilt, p[5:7], th, lead=run.sample_tilt_lead_s)
        ypr_s = ca.vertcat(ypr[0], tilt)
        Lam_s, dLam_s, _ = euler_matrix_and_rate(ypr_s, ca.jacobian(ypr_s, t))
        slow = p[7]  # the deviation's argument: the slow heading, not the reading's noise (errors in variables)
        delta = compass_correction(slow, h[0], h[1], h[2], *self.heading_centre) if self.heading is not None else 0
        for (e, _), th in zip(terms, ths):
            delta = delta + e.sampled_heading_correction(slow, th)
        Rz = euler_matrix(delta, 0, 0)
        Lam, dLam = ca.mtimes(Rz, Lam_s), ca.mtimes(Rz, dLam_s)  # a heading error turns the rotation (motion.heading_corrected_function)
        Omega = ca.mtimes(dLam, Lam.T)
        P = ca.vertcat(p, h, *ths)
        return ca.Function("attitude", [t, P], [ca.vertcat(ypr_s[0] + delta, tilt), Lam, dLam, Omega, unskew(Omega)],
                           ["t", "p"], ["ypr", "Lambda", "dLambda_dt", "Omega", "omega"])

    def _p_rows(self, k: int, times, segments=None) -> ca.MX:
        """Attitude parameters of the beams' attitude (:meth:`_true_attitude_function`) for rows at
        ``times`` (columns): the model's, or each row's sample segment (``segments`` where given: the
        segments as the model takes them); then the heading correction and the sample effects' unknowns."""
        run = self.runs[k]
        extra = ([self.heading] if self.heading is not None else []) + [th for _, th in self._sample_terms(k)]
        if run.attitude_source == "samples":
            # the segment about t + shift (its own clock: a latency th then evaluates it at t + th)
            p = (self._datum(f"run{k}/segments", run.samples.params_at(np.asarray(times) + run.sample_shift_s,
                                                                        run.sample_tilt_lead_s))
                 if segments is None else segments)
            return ca.vertcat(p, *[ca.repmat(x, 1, p.shape[1]) for x in extra]) if extra else p
        return ca.vertcat(self.attitude_params[k], *extra)

    def bed_at(self, k: int, n: int):
        """Moving-bed velocity (n, 3) under run k's pings (zeros without a bed model)."""
        if self.bed is None:
            return None
        if self.bed.shape[0] == 1:
            return ca.repmat(ca.horzcat(self.bed, ca.MX.zeros(1, 1)), n, 1)
        H = hat_basis_dm(self.runs[k].section_position, np.linspace(0, 1, self.bed.shape[0]))
        return ca.horzcat(ca.mtimes(H, self.bed), ca.MX.zeros(n, 1))

    def bed_basis(self, k: int) -> np.ndarray:
        """(N, n_bed) weights of the bed parameters under run k's pings."""
        n_bed = 0 if self.bed is None else self.bed.shape[0]
        N = self.runs[k].case.pings.n
        if n_bed <= 1:
            return np.ones((N, n_bed))
        return hat_basis(self.runs[k].section_position, np.linspace(0, 1, n_bed))

    def _reference_attitude(self, k: int, data: dict, key: str, output: int, fast=lambda f: f) -> ca.MX:
        """The beams' attitude output ``output`` (2: dLambda/dt) at the reference rows' times ``key`` of
        ``data`` (:meth:`_reference_data`), 3 x 3L as the mapped attitude gives it."""
        return fast(self.attitude_true[k]).map(data[key].shape[1])(data[key], self._p_rows(k, None, data.get("segment " + key)))[output]

    def _window_difference(self, k: int, data: dict, output: int) -> ca.MX:
        """(X(b) - X(a)) / (b - a) over the reference's windows [a, b] of the beams' attitude output
        ``output`` (1: Lambda, 2: dLambda/dt), 3 x 3L as the mapped attitude gives it."""
        w = self.runs[k].reference_window_s  # its length does not shift
        ends = [self._reference_attitude(k, data, key, output) for key in ("a", "b")]
        return ca.times(ends[1] - ends[0], ca.repmat(ca.DM(np.repeat(1.0 / (w[:, 1] - w[:, 0]), 3)).T, 3, 1))

    def _shifts_reference(self, k: int) -> bool:
        return any(getattr(e, "shifts_reference", False) for e, _ in self.terms_of(k))

    def _fast(self, f: ca.Function) -> ca.Function:
        """A per-ping model as machine code where the model is compiled (the gradient's sweep too)."""
        return compiled(f, reverse=True) if self.compiled else f

    def _reference_rows(self, k: int) -> list:
        """Run k's reference rows (north, east, down: model - measurement), taken at t - its shift, the
        time each sample holds (a reference latency's current estimate)."""
        run, ctx, V = self.runs[k], self.contexts[k], self.knot_syms[k]
        L, v_meas = run.reference_time_s.size, run.reference_velocity_m_s
        numbers = reference_numbers(run, self._shifts_reference(k))
        recorded = [key for key in numbers if key in ("t", "a", "b", "t-", "t+") or key.startswith("segment ")]
        data = {**as_constants({key: v for key, v in numbers.items() if key not in recorded}),
                **{key: self._datum(f"run{k}/reference {key}", numbers[key]) for key in recorded}}
        p_ref = ca.DM(self.reference_point_sensor(run.case))
        v_model = ca.mtimes(data["basis"], V)  # the navigation there (its mean over each window)
        if run.reference_window_s is None:  # instantaneous samples
            dLam = self._reference_attitude(k, data, "t", 2, self._fast)
            if "slope" in data:  # d/dt of the antenna's velocity
                rot = [REFERENCE_VELOCITY.map(L)(ca.DM.zeros(3, L), self._reference_attitude(k, data, key, 2),
                                                 ca.repmat(p_ref, 1, L)) for key in ("t-", "t+")]
                ctx.reference_slope = ca.mtimes(data["slope"], V) + ca.transpose(rot[1] - rot[0]) / (2 * ROTATION_STEP_S)
        else:  # means over windows (differenced positions): the antenna's displacement over each window
            dLam = self._window_difference(k, data, 1)  # (Lambda(b) - Lambda(a)) / (b - a)
            if "slope" in data:  # d/dt of a window mean: (x(b) - x(a)) / (b - a)
                rot = REFERENCE_VELOCITY.map(L)(ca.DM.zeros(3, L), self._window_difference(k, data, 2),
                                                ca.repmat(p_ref, 1, L))
                ctx.reference_slope = ca.mtimes(data["slope"], V) + ca.transpose(rot)
        for e, th in self.terms_of(k):
            v_model, p_ref = e.reference_velocity(v_model, ctx, th), e.reference_point(p_ref, th)
        v_ref = self._fast(REFERENCE_VELOCITY).map(L)(v_model.T, dLam, ca.repmat(p_ref, 1, L))
        return [ca.transpose(v_ref[j, :]) - self._datum(f"run{k}/reference_{NED[j]}", np.nan_to_num(v_meas[:, j]))
                for j in range(3)]

    def at_reference_shift(self, runs: list[RunSetup]) -> "SurveyModel":
        """This model with ``runs`` (these runs at other reference shifts): the reference rows rebuilt,
        everything else (unknowns, channels, the other rows' expressions) shared."""
        other = copy.copy(self)
        other.runs = list(runs)
        other.contexts = [copy.copy(c) for c in self.contexts]
        other.raw_parts = list(self.raw_parts)
        other._data = dict(self._data)  # the same parameters; the shifted rows give their own values
        for k, run in enumerate(other.runs):
            other.contexts[k].reference_shift_s = run.reference_shift_s
            if run.moving_reference:
                i = self.reference_part(k)
                other.raw_parts[i:i + 3] = other._reference_rows(k)
        other.raw = ca.vertcat(*other.raw_parts)
        return other

    def reference_part(self, k: int) -> int:
        """Index of run k's first reference row channel (north) in ``channels`` and ``raw_parts``."""
        return next(i for i, c in enumerate(self.channels) if c.run == k and c.name == "reference_north")

    def _build_residuals(self):
        models, channels = [], []
        self.bt_functions, self.g_depth = [], []
        n_nodes = 0
        for k, run in enumerate(self.runs):
            case, pings = run.case, run.case.pings
            N = pings.n
            att, att_c = self.attitude_sensor[k], self.attitude_true[k]
            terms, ctx = self.terms_of(k), self.contexts[k]
            fast = self._fast
            if run.attitude_source == "model":  # the sensor's own readings of the motion model (and its faults)
                a = case.attitude
                M = a.time_s.size
                t_att = ca.DM(a.time_s).T
                p_full, p_tilt = self.attitude_params[k], self.attitude_params[k]
                for e, th in terms:
                    t_att, p_tilt = e.attitude_time(t_att, th), e.tilt_attitude_params(p_tilt, self.attitude_layouts[k], th)
                sensor = fast(att).map(M)
                ypr_model = sensor(t_att, p_full)[0]
                tilt_model = sensor(t_att, p_tilt)[0] if p_tilt is not p_full else ypr_model
                psi = ca.transpose(ypr_model[0, :])
                for e, th in terms:
                    psi = e.heading_reading(psi, th)
                ypr_meas = a.ypr()
                meas = [self._datum(f"run{k}/{n}", np.nan_to_num(ypr_meas[:, j])) for j, n in enumerate(("heading", "pitch", "roll"))]
                dpsi = meas[0] - psi
                models += [ca.atan2(ca.sin(dpsi), ca.cos(dpsi)), ca.transpose(tilt_model[1, :]) - meas[1],
                           ca.transpose(tilt_model[2, :]) - meas[2]]
                channels += [Channel(k, n, a.time_s, np.isfinite(ypr_meas[:, j]).astype(float))
                             for j, n in enumerate(("heading", "pitch", "roll"))]
                n_nodes += att.n_instructions() * M
            timing = "deep" if any(e.timing == "deep" for e, _ in terms) and run.timing == "shallow" else run.timing
            bt_fun = bottom_track_function(att_c, timing, self.spec.tangential)
            self.bt_functions.append(bt_fun)
            depth = case.environment.depth_at_pings(N)
            g_depth = centre_of_rotation_depth(case.environment.transducer_depth_m + self.depth_offsets[k], self.r)
            self.g_depth.append(g_depth)
            V = self.knot_syms[k]
            v_ping = ca.mtimes(hat_basis_dm(pings.time_s, run.knots), V) if V is not None else ca.MX(ca.DM.zeros(N, 3))
            g_rows, beams, ypr_beams = ca.repmat(g_depth, 1, N), ca.DM(self.beam_dirs_t), self.ypr_beams
            g_level, depth_rows = g_rows, self._datum(f"run{k}/depth", np.asarray(depth, dtype=float)[None, :])
            radial_scale = range_scale = 1.0
            for e, th in terms:
                v_ping, g_rows = e.vessel_velocity(v_ping, ctx, th), e.g_depth(g_rows, ctx, th)
                beams = e.beam_directions(beams, case.instrument.beam_angle_rad, th)
                ypr_beams = e.installation(ypr_beams, th)
                radial_scale = radial_scale * e.radial_scale(th)
                if not run.depth_from_ranges:  # else the depth derived from the ranges scales with them: the ratio stays
                    range_scale = range_scale * e.range_scale(th)
            if run.depth_from_ranges and g_rows is not g_level:  # a depth derived from the ranges moved with the transducer
                depth_rows = depth_rows + (g_rows - g_level)
            bed = self.bed_at(k, N)
            beds = [b for b in (e.bottom_velocity_model(th) for e, th in terms) if b is not None]
            if beds:
                extra_bed = ca.repmat(sum(beds[1:], beds[0]).T, N, 1)
                bed = extra_bed if bed is None else bed + extra_bed
            v_bt = v_ping - bed if bed is not None else v_ping
            radial, rng = fast(bt_fun).map(N)(ca.DM(pings.time_s).T, depth_rows, g_rows, case.instrument.sound_speed_m_s,
                                        v_bt.T, self._p_rows(k, pings.time_s), self.r, ypr_beams, beams)
            radial, rng = radial * radial_scale, rng * range_scale
            n_nodes += bt_fun.n_instructions() * N
            bt = pings.bt_radial_m_s
            covered = run.covered(pings.time_s)
            for i in range(4):
                models.append(ca.transpose(radial[i, :]) - self._datum(f"run{k}/bt_beam{i + 1}", np.nan_to_num(bt[:, i])))
                channels.append(Channel(k, f"bt_beam{i + 1}", pings.time_s, (np.isfinite(bt[:, i]) & covered).astype(float)))
            if run.use_ranges:
                for i in range(4):
                    models.append(ca.transpose(rng[i, :]) - self._datum(f"run{k}/range_beam{i + 1}",
                                                                        np.nan_to_num(pings.bt_range_m[:, i])))
                    channels.append(Channel(k, f"range_beam{i + 1}", pings.time_s,
                                            (np.isfinite(pings.bt_range_m[:, i]) & covered).astype(float)))
            if run.moving_reference:
                t_ref, v_meas = run.reference_time_s, run.reference_velocity_m_s
                L = t_ref.size
                models += self._reference_rows(k)
                covered = run.covered(t_ref)
                channels += [Channel(k, f"reference_{NED[j]}", t_ref, (np.isfinite(v_meas[:, j]) & covered).astype(float))
                             for j in range(3)]
                n_nodes += att_c.n_instructions() * L
            if run.random_walk:  # the priors: horizontal increments over sqrt(dt), vertical levels
                t_mid = 0.5 * (run.knots[1:] + run.knots[:-1])
                dV = ca.mtimes(sparse_dm(walk_increments(run.knots)), V[:, :2])
                for j in range(2):
                    models.append(dV[:, j])
                    channels.append(Channel(k, f"motion_{NED[j]}", t_mid, np.ones(t_mid.size)))
                models.append(V[:, 2])  # a floating boat's vertical velocity: zero-mean heave, not a walk
                channels.append(Channel(k, "vertical_down", run.knots, np.ones(run.knots.size)))
        if self.has_prior:  # N(0, prior^2) on B and C: a pseudo-run of its own, outside the runs' time bins
            models.append(self.heading[1:3])
            channels.append(Channel(len(self.runs), "prior_compass_deviation", np.zeros(2), np.ones(2)))
        self.raw_parts = models  # one expression per channel
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


    @property
    def has_prior(self) -> bool:
        return self.spec.heading == "deviation" and self.spec.deviation_prior_rad is not None

    @property
    def prior_rows(self) -> np.ndarray:
        """Mask of the prior's pseudo-residual rows (their information is known, not sampled)."""
        return self.row_run == len(self.runs)

    @property
    def known_rows(self) -> np.ndarray:
        """Rows whose information is known, not sampled: the compass prior's and the random walk's
        pseudo-observations (its increments, the vertical velocity's levels)."""
        walk = [i for i, key in enumerate(self.sigma_keys) if key[1] in PRIOR_GROUPS]
        return self.prior_rows | np.isin(self.row_sigma, walk)

    def velocity_columns(self) -> np.ndarray:
        """Mask of the unknowns that are navigation velocities (each row touches a few neighbours)."""
        return np.array([VELOCITY_NAME.fullmatch(n.split("/")[-1]) is not None for n in self.unknowns.names], dtype=bool)

    # ------------------------------------------------------------------ bookkeeping
    def channel_slices(self) -> dict:
        """Slice of each channel in the stacked residuals, keyed by (run, name)."""
        ends = np.cumsum([c.size for c in self.channels])
        return {(c.run, c.name): slice(int(e - c.size), int(e)) for c, e in zip(self.channels, ends)}

    def initial_sigmas(self) -> dict:
        """{(run, group): noise level} from independent estimates (:func:`.noise_guess.initial_noise`)."""
        out = {}
        for k, run in enumerate(self.runs):
            guess = run.noise_guess()
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

    def put_in(self, exprs: list, x, data=None) -> list:
        """``exprs`` with the unknowns ``x`` (and the recorded numbers ``data``) put in for ``self.x`` (and
        ``self.data_sym``). Recorded numbers given as constants (a DM: an assembled calibration's 10^6 of
        them) go in by a call of a Function per expression, of the numbers only where it has symbols besides
        x (so that its derivatives reach no other expression, nor 10^6 numbers' Jacobian): casadi.substitute,
        which copies the graph, took 0.47 s on 10^5 pings' residuals, the Function and its call 3 ms.
        Symbolic ones (an NLP's parameters, differentiated and expanded afterwards) by substitute: through
        call nodes a diagnosis of diag_boat took 22.2 s, 7.5 s by substitute. Any other symbol stays free."""
        if not isinstance(data, ca.DM):
            syms, values = ([self.x], [x]) if data is None else ([self.x, self.data_sym], [x, data])
            return ca.substitute(list(exprs), syms, values)
        out = []
        for e in exprs:
            f = ca.Function("put_in", [self.x], [e], {"allow_free": True})
            if not f.has_free():
                out.append(f.call([x])[0])
            else:
                f = ca.Function("put_in", [self.x, self.data_sym], [e], {"allow_free": True})
                out.append(f.call([x, data])[0])
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

    def row_jacobian(self, z: ca.MX, x: ca.MX, data, threads: int) -> RowJacobian:
        """The residual Jacobian assembled from per-row Jacobians (:mod:`.row_jacobian`): each run's
        attitude, bottom-track and reference rows as blocks over their share of s and their knots; s in z through
        ``x`` (the unknowns in z) and ``data`` (the recorded numbers)."""
        if self.effect_terms:
            raise ValueError("jacobian: 'assembled' is for calibrations; a model with effects uses the symbolic one")
        shared, index = self.shared_vector()
        shared_z = self.put_in([shared], x, data)[0]
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
            basis = (lambda t, run=run: None if run.knots is None else hat_basis_sparse(t, run.knots))
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
                w = run.reference_window_s
                ends = 1 if w is None else 2  # an instantaneous sample, or a window's two ends
                d1 = ca.SX.sym("d", ends * (1 + n_local))

                def p_at(j):
                    p_row = d1[ends + j * n_local:ends + (j + 1) * n_local] if sampled else (
                        s[:n_att] if run.attitude_source == "model" else frozen(run))
                    return ca.vertcat(p_row, s[n_att:]) if has_h else p_row

                if w is None:
                    dLam = self.attitude_true[k](d1[0], p_at(0))[2]
                    data, velocity_basis = np.vstack([t_ref[None, :], local(t_ref)]), basis(t_ref)
                else:  # the mean over the window: (Lambda(b) - Lambda(a)) / (b - a) and the window mean of V
                    dLam = (self.attitude_true[k](d1[1], p_at(1))[1] - self.attitude_true[k](d1[0], p_at(0))[1]) / (d1[1] - d1[0])
                    data = np.vstack([w.T, local(w[:, 0]), local(w[:, 1])])
                    velocity_basis = window_basis_sparse(w, run.knots)
                vs = REFERENCE_VELOCITY(v, dLam, ca.DM(self.reference_point_sensor(case)))
                blocks.append(RowBlock(ca.Function("reference_rows", [d1, v, s], [vs]), data,
                                       offset, velocity_basis=velocity_basis, shared_index=idx, knot_columns=knots_cols))
                offset += 3 * t_ref.size
            if run.random_walk:  # the priors, linear in the velocities: increments over sqrt(dt), vertical levels
                for fun, basis_k in self._walk_rows(run.knots):
                    blocks.append(RowBlock(fun, np.zeros((1, basis_k.shape[0])), offset, velocity_basis=basis_k,
                                           shared_index=np.zeros(0, dtype=int), knot_columns=knots_cols))
                    offset += fun.size1_out(0) * basis_k.shape[0]
        if self.has_prior:
            d, v, s = ca.SX.sym("d", 1), ca.SX.sym("v", 3), ca.SX.sym("s", 2)
            blocks.append(RowBlock(ca.Function("prior_rows", [d, v, s], [s]), np.zeros((1, 1)), offset,
                                   shared_index=index["heading"][1:3]))
            offset += 2
        if offset != self.raw.shape[0]:
            raise RuntimeError(f"assembled Jacobian: {offset} rows, residuals have {self.raw.shape[0]}")
        return RowJacobian(z, shared_z, blocks, self.raw.shape[0], None, u.scale, threads=threads,
                           compile=self.compiled)

    @staticmethod
    def _walk_rows(knots: np.ndarray) -> list:
        """The random-walk prior's rows as (per-row Function of the velocity, velocity basis over the
        knots): the horizontal increments (V_j+1 - V_j) / sqrt(dt) (north rows, then east), and
        each knot's vertical velocity, in :meth:`_build_residuals`' order."""
        d, v, s = ca.SX.sym("d", 1), ca.SX.sym("v", 3), ca.SX.sym("s", 0)
        return [(ca.Function("walk_increment_rows", [d, v, s], [v[:2]]), walk_increments(knots)),
                (ca.Function("walk_vertical_rows", [d, v, s], [v[2]]), sp.identity(knots.size, format="csr"))]

    # ------------------------------------------------------------------ starting values
    def initial_x(self, params: list, angles, centre, heading_guess: float = 0.0) -> np.ndarray:
        """A start: each run's attitude model (``params``, per run), the installation ``angles``
        (when estimated) or the heading misalignment ``heading_guess``, the lever arms of a head
        centred at ``centre``, a still bed, each run's knot velocities from its reference."""
        u = self.unknowns
        x = np.zeros(len(u.names))
        for k, (run, p) in enumerate(zip(self.runs, params)):
            if run.attitude_source == "model":
                x[u.index(f"attitude{k}")] = p.pack()
            if run.knots is not None:
                x[u.index(f"velocity{k}")] = self.velocity_guess(k).reshape(-1)
        angles = np.asarray(angles, dtype=float)
        if self.heading is not None:
            x[u.index("heading")[0]] = heading_guess
        if self.spec.installation == "estimate":
            x[u.index("installation")] = angles
        elif self.spec.installation == "fixed":
            angles = np.asarray(self.spec.nominal_installation_ypr_rad, dtype=float)
        Lst = np.asarray(euler_matrix(*angles)) if not self.head_sensor else np.eye(3)
        x[u.index("lever")] = self.lever.initial(centre, Lst, self.pos_t)
        return x

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
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
        for j in range(3):
            ok = np.isfinite(v[:, j])
            if ok.sum() == 0:
                continue
            tj, vj = t[ok], v[ok, j]
            lo = np.searchsorted(tj, run.knots - half, "left")  # the samples within half a spacing of each knot
            hi = np.searchsorted(tj, run.knots + half, "right")
            sums = np.concatenate([[0.0], np.cumsum(vj)])
            inside = hi > lo
            out[:, j] = np.interp(run.knots, tj, vj)
            out[inside, j] = (sums[hi] - sums[lo])[inside] / (hi - lo)[inside]
        return out


def default_threads(workers: int, n_starts: int) -> int:
    """Cores the multistart's workers leave free, for the per-row Jacobians of long runs."""
    return max(1, (os.cpu_count() or 1) // max(1, min(workers, n_starts)))
