"""Joint calibration: ONE maximum-likelihood NLP for the attitude models, the lever arms, the
installation angles or heading misalignment and the moving bed of one run or of a survey
(several runs of one boat at one site), solved by IPOPT from many starts.

The model (:mod:`.measurement_model`): per run, the sensor-frame attitude model (bias and
damped modes per axis, yaw trend; modes chosen by BIC in an attitude-only pre-fit) or the
sensor's samples, and the navigation velocity of G as a piecewise-linear curve; shared, the
lever-arm block of the chosen formulation (:mod:`.formulations`), the installation angles
(vessel-frame sensor; a sensor inside the head cannot see them,
``docs/notes-on-the-paper.md``) or the heading misalignment of a head sensor against a
moving reference (with the compass's one-cycle deviation where the headings span enough),
and the bed velocity under the bottom track. The objective is half the sum of squared
noise-weighted residuals of every channel the runs hold: attitude samples, bottom-track
radial velocities (shallow Eq. 52 or deep Eqs. 65-70, chosen from the round-trip time),
slant ranges, reference velocity (with its lever arm, erratum 6). Noise levels per run and
channel group start from independent estimates and are re-estimated from the fit.

One run cannot tell a constant compass error from a moving bed when its course hardly
changes: the result says so in words (``confounded``) and the misalignment's standard error
carries it; runs in several directions, calibrated together, separate them. Standard errors
are Newey-West sandwiches over time bins (:mod:`.hac`): residuals of real data are coloured.
"""

from __future__ import annotations

import dataclasses
import time

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.stats import qmc

from ...cases.case import Case, check_distinct_names
from ...cases.identity import identity_of, instrument_difference, site_differences, site_of
from ...models.motion import AttitudeParams, evaluate_attitude
from ...models.rotations import euler_matrix
from ...solvers.cluster import SERIAL
from ...solvers.multistart import MultistartResult, build_solver, expand_problem, multistart
from ..attitude_fit import AttitudeFit, autocorrelation, fit_attitude
from ..statistics.hac import at_least_white, ping_bins, sandwich
from ..knots import knot_times, ping_knots
from .. import model_cache
from ..measurement_model import ANGLE_NAMES, ModelSpec, SurveyModel, default_threads
from ..run_setup import RunSetup, choose_navigation, course_offset_rad, heading_span
from ..statistics.normal_equations import (SCORING_MAX_UNKNOWNS, VCE_RTOL, group_levels, largest_move, redundancy,
                                           scored_levels)
from ..statistics.uncertainty import uncertainty, uncertainty_eliminating
from .config import CalibrationConfig
from .moving_bed_decision import bed_direction, mean_flow, moving_bed_test
from .result import CalibrationResult, RunResult

MIN_PINGS = 3  # a velocity curve and a residual need a few pings
MIN_SAMPLES_PER_PERIOD = 4  # attitude samples per motion period below which no motion model is identifiable
# attitude pre-fit residual (heading, pitch, roll) above which the motion model does not follow the sensor:
# several times a compass's / an inclinometer's noise (the paper's pool: 0.5 / 0.17 deg)
MAX_MODEL_RESIDUAL_RAD = tuple(float(np.deg2rad(d)) for d in (2.0, 1.0, 1.0))
MIN_RESIDUAL_LAG1 = 0.5  # |lag-1 autocorrelation| above which a residual is motion left unfollowed, not sensor noise
DECLINATION_SPAN_RAD = np.radians(1.0)  # runs' declinations farther apart than a survey's site spreads them
DEEP_TIMING_FRACTION = 0.01  # deep model when the round trip exceeds 1% of the motion period
ASSEMBLED_MIN_NODES = 400_000  # expanded-graph size above which the Jacobian is assembled per row
# the symbolic Jacobian costs about its expanded nodes times its forward directions (the colours of its pattern: a
# motion model's parameters reach every row): above this product it is assembled (and compiled) too. Measured with
# 24 starts unless said (2026-12-02; `estimators.calibration.problem.symbolic_jacobian_cost`): a 62-s window of winriver02
# (123 pings, the motion model in deep water: 343k nodes x 47 colours, 16e6; its symbolic Jacobian 69 ms an
# evaluation against 3 ms assembled, 4 starts 157 s -> 24 s), the next window (219 pings, 7e6) 14.6 -> 1.8 s,
# RiverPro_test01 (3.6e6) 6.6, 5.2 -> 3.4, 3.1 s (4.8 s with an empty cache), the simulated river_survey (2.7e6)
# 3.3, 3.2 -> 2.4, 2.4 s; pool_m1 (57 pings, 1.9e6) loses, 3.7 -> 6.2 s
ASSEMBLED_MIN_COST = 2_300_000
# pings (all runs) from which --compile auto compiles the per-ping models (and so assembles the Jacobian): 8 starts
# warm, 501 pool_m0 pings 2.1 -> 0.8 s, deep_ship (601) 30.7 -> 9.4 s; winriver02 (830, 24 starts) 19.4 -> 6.3 s,
# 10.9 s with an empty cache (its six models compiled once per machine); below, winriver01 (261) gains 15.8 -> 10.1 s
# but RiverPro (272, 171 unknowns) loses 2.5 -> 2.9 s, and unit-sized runs would pay the compiler first. A shorter
# problem is compiled too where it is assembled (ASSEMBLED_MIN_NODES), since the assembled path evaluates its per-row
# Jacobians interpreted at about 130 us a ping: winriver01 (261 pings, 406002 nodes, 24 starts, solved twice for the
# moving-bed test) 30.9 s interpreted, 7.8 s compiled (27.5 s compiling into an empty cache); symbolic 34.8 s
COMPILE_MIN_PINGS = 500
# the noise levels are re-estimated from the fit, each time with a refit, until none moves by more than VCE_RTOL
# (their fixed point: one step left winriver01's reference level 35 % above it and its yaw SE 1.47 deg, 1.13 at
# it; starting levels within VCE_RTOL of it are not refitted), at most VCE_MAX_ITERATIONS times; the result's
# message says how many and whether they settled. A random
# walk's (Helmert) levels crawl there, the beams' and the reference's trading the velocity between them
# (winriver02: 9 % a round after three, 2.9 % after ten), so it keeps VCE_WALK_ITERATIONS and says it has not settled,
# unless the problem is small enough for Fisher-scoring steps (SCORING_MAX_UNKNOWNS), which settle in a few
VCE_MAX_ITERATIONS = 10
VCE_WALK_ITERATIONS = 3
# IPOPT's initial barrier for the refit after the noise levels, which starts at the solution: at 0.1 (a
# cold start's) four of its seven iterations at 10^5 pings only walked the barrier down, the objective
# unchanged to 1e-8; at 1e-3 it takes four, the same optimum to 1e-6 of the unknowns' scale
REFIT_MU_INIT = 1e-3
MIN_HEADING_SPAN = 0.1  # heading_span above which the one-cycle compass deviation is estimated (0.5: all round)
# symbolic problems whose graphs a process keeps (:mod:`..model_cache`): the largest (a symbolic Jacobian's cost near
# ASSEMBLED_MIN_COST) hold about 75 MB each (pool_m1 windows of 26-70 pings: 5-75 MB a graph, 2026-12-03); enough for
# a case calibrated again, its moving-bed test's second problem, and batch jobs of one shape
KEPT_GRAPHS = 4
CONFOUNDED_R2 = 0.9  # share of a yaw's variance explained by the bed's: the two are not told apart


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
    excess = _beyond_sensor_noise(fit)
    if excess.any():
        excess &= np.abs(attitude_residual_lag1(case, fit)) > MIN_RESIDUAL_LAG1
    if excess.any():
        left = ", ".join(f"{n} {np.rad2deg(v):.2f} deg" for n, v, e in zip(("heading", "pitch", "roll"), fit.sigmas, excess) if e)
        return "samples", (f"the damped-mode model leaves {left} of coloured residual: turns or irregular motion it "
                           "cannot follow")
    return "model", "the damped-mode model follows the attitude samples"


def irregular_attitude(fit: AttitudeFit) -> bool:
    """Whether the damped-mode model leaves more than the sensors' noise (``MAX_MODEL_RESIDUAL_RAD``)
    on some axis, coloured or white: motion irregular at the ping scale (a small boat's yaw
    aliased by its samples) or a sensor far noisier than a compass. Either way the model does
    not vouch for a smooth course (:func:`~adcpdyn.estimators.run_setup.choose_navigation`)."""
    return bool(_beyond_sensor_noise(fit).any())


def _beyond_sensor_noise(fit: AttitudeFit) -> np.ndarray:
    """Per axis (heading, pitch, roll), whether the pre-fit's residual exceeds ``MAX_MODEL_RESIDUAL_RAD``."""
    return np.asarray(fit.sigmas) > np.asarray(MAX_MODEL_RESIDUAL_RAD)


LONE_BEST_MIN_STARTS = 4  # from this many starts, a best that only one of them reached is said to be unconfirmed


def lone_best(ms: MultistartResult) -> str | None:
    """The warning for a multistart whose best objective only one start reached while the others
    ended at other local solutions: nothing confirms it is the global one (a short window's motion model,
    a landscape of many minima), so more starts may find a better one."""
    n = len(ms.starts)
    if n < LONE_BEST_MIN_STARTS or ms.n_groups < 2 or round(ms.fraction_at_best * n) != 1:
        return None
    return (f"multistart: only 1 of {n} starts reached the best objective, the others ended at {ms.n_groups - 1} "
            "other local solution(s): a better one may lie where no start went; rerun with more starts (--starts) or "
            "another seed (--seed)")


def symbolic_jacobian_cost(model: SurveyModel) -> int:
    """About the operations of one evaluation of the symbolic residual Jacobian: the expanded graph's
    nodes times the forward directions its sparsity pattern needs (CasADi's column colouring)."""
    return model.assembled_nodes * ca.jacobian_sparsity(model.raw, model.x).uni_coloring().size2()


class CalibrationProblem:
    """The joint NLP of one run, or of several runs of one boat: built once, solved from many starts.

    ``cases``: one :class:`~adcpdyn.cases.case.Case` or a list of them (one installation and
    compass, one site); ``fit``: attitude pre-fit(s) to reuse.
    """

    def __init__(self, cases, config: CalibrationConfig | None = None, fit=None):
        config = config or CalibrationConfig()
        self.cases = [cases] if isinstance(cases, Case) else list(cases)
        if not self.cases:
            raise ValueError("cases: expected at least one case")
        for case in self.cases:
            if case.pings.n < MIN_PINGS:
                raise ValueError(f"{case.name}: /pings/time_s: expected at least {MIN_PINGS} pings to calibrate, got {case.pings.n}")
        check_distinct_names(self.cases)
        self.identity, self.identity_warnings = _one_instrument(self.cases)
        self.config = config
        self.two_stage = config.method == "two-stage"
        fits = list(fit) if isinstance(fit, (list, tuple)) else [fit] * len(self.cases)
        self.fits = [f or fit_attitude(c, max_modes=config.max_modes, fixed_modes=1 if self.two_stage else config.modes,
                                       per_axis=self.two_stage) for c, f in zip(self.cases, fits)]
        runs = []
        for case, f in zip(self.cases, self.fits):
            source, reason = ("frozen", "two-stage method") if self.two_stage else choose_attitude(case, f, config.attitude)
            navigation = choose_navigation(case, source, config.navigation, irregular_attitude(f))
            knots = ping_knots(case) if navigation == "random_walk" else knot_times(case, config.velocity_knot_interval_s)
            runs.append(RunSetup(case, f, source, choose_timing(case, f, config.timing), knots,
                                 config.use_ranges and case.pings.bt_range_m is not None, reason, navigation=navigation))
        self._set_up(runs)

    def _set_up(self, runs: list, yaw_guess: float | None = None) -> None:
        """The model, its unknowns and the NLP of the runs' decisions (``yaw_guess``: the yaw centre, else
        from the runs)."""
        config = self.config
        self.runs = runs
        self.walk = any(r.random_walk for r in runs)
        self.frame = self.cases[0].attitude.frame
        self.head_sensor = self.frame == "transducer"
        moving = any(r.moving_reference for r in runs)
        self.head_yaw = bool(self.head_sensor and not self.two_stage and moving)
        installation = "head" if self.head_sensor else ("fixed" if self.two_stage else "estimate")
        self.fixed_installation = installation != "estimate" and not self.head_yaw
        self.yaw_guess = yaw_guess if yaw_guess is not None else (
            course_offset_rad(runs) if self.head_yaw or (moving and installation == "estimate") else 0.0)
        self.moving_bed = self._moving_bed_choice(moving)
        self.heading_span = heading_span(runs)
        heading, prior = "off", None
        if self.head_yaw:
            heading = "misalignment" if config.compass_deviation == "off" else "deviation"
            prior = config.compass_deviation_prior_rad if config.compass_deviation == "auto" else None
            if config.compass_deviation == "on" and self.heading_span < MIN_HEADING_SPAN:
                raise ValueError(f"CalibrationConfig.compass_deviation: 'on' (no prior) needs headings all round the "
                                 f"compass; these runs span {self.heading_span:.3f} < {MIN_HEADING_SPAN} (use 'auto')")
        elif config.compass_deviation == "on":
            raise ValueError("CalibrationConfig.compass_deviation: 'on' needs an attitude sensor in the head (frame "
                             "'transducer') and a moving reference; these cases have neither or not both")
        v = self.cases[0].vessel
        self.lever_box = config.lever_box_m or (0.5 * v.length_m if v.length_m else 10.0)
        spec = ModelSpec(formulation=config.formulation, epsilon_rel=config.epsilon_rel, tangential=config.tangential,
                         lever_box_m=self.lever_box, installation=installation,
                         installation_bound_rad=config.installation_bound_rad,
                         nominal_installation_ypr_rad=tuple(config.nominal_installation_ypr_rad),
                         yaw_centre_rad=self.yaw_guess, heading=heading, deviation_prior_rad=prior,
                         moving_bed=self.moving_bed,
                         bed_knots=config.moving_bed_section_knots)
        compile_min = {"always": 0, "never": None}.get(config.compile, COMPILE_MIN_PINGS)
        symbolic = config.jacobian == "symbolic"  # compiled models are not expanded to SX
        # the recorded numbers are parameters of the graph: a symbolic problem of a shape built before is taken
        # from the kept graphs (:mod:`..model_cache`); an assembled one has them as constants
        self.model = model = SurveyModel(runs, spec, compile_min_pings=None if symbolic else compile_min,
                                         data_parameters=True)
        costly = config.jacobian == "auto" and not model.compiled and (
            model.assembled_nodes > ASSEMBLED_MIN_NODES or symbolic_jacobian_cost(model) > ASSEMBLED_MIN_COST)
        if config.compile == "auto" and costly:  # assembled anyway: its per-row Jacobians compiled
            self.model = model = SurveyModel(runs, spec, compile_min_pings=0, data_parameters=True)
        u = model.unknowns
        self.names, self.scale, self.lbx, self.ubx = list(u.names), u.scale, u.lower, u.upper
        self.data = model.data_values
        # single-run views (tests, benchmarks, the CLI print)
        self.case, self.fit, self.timing, self.knots = self.cases[0], self.fits[0], runs[0].timing, runs[0].knots
        self.sampled = runs[0].attitude_source == "samples"
        self.attitude_source = "samples" if self.sampled else "model"
        # compiled models are evaluated by the assembled Jacobian (jacobian 'symbolic' compiles nothing)
        self.assembled = config.jacobian == "assembled" or model.compiled or costly
        self.threads = default_threads(config.workers, config.n_starts) if self.assembled else 1
        self.solver_options = dataclasses.replace(config.solver, expand=False) if self.assembled else config.solver
        self.lbg, self.ubg = model.lbg, model.ubg
        self.sigma = model.initial_sigmas()
        self.graph = "assembled"
        if self.assembled:
            self._assemble()
            return
        self.shape_key = ("calibration", tuple(self.names), tuple((c.run, c.name, c.size) for c in model.channels),
                          model.data_layout, repr(dataclasses.replace(spec, yaw_centre_rad=0.0, lever_box_m=0.0)),
                          repr(self.solver_options))
        kept = model_cache.find(self.shape_key, self)
        if kept is not None:
            self._take_built(kept)
        else:
            self._build_symbolic()
            model_cache.keep(self.shape_key, self, most=KEPT_GRAPHS)

    # ------------------------------------------------------------------ the NLP
    def _assemble(self) -> None:
        """The NLP with the recorded numbers and scales as constants, its Jacobian assembled per row
        (:mod:`..row_jacobian`): p is the weights."""
        model = self.model
        z = ca.MX.sym("z", model.x.shape[0])
        weights = ca.MX.sym("w", model.raw.shape[0])
        x, data = self.scale * z, ca.DM(self.data)
        raw_z, g_z, r_z, st_z = model.put_in([model.raw, model.g, model.r, model.ypr_st], x, data)
        e_z = weights * raw_z
        self.nlp = {"x": z, "p": weights, "f": 0.5 * ca.sumsqr(e_z), "g": g_z}
        self.jacobian_fun = model.row_jacobian(z, x, data, self.threads)
        self._functions(z, weights, e_z, raw_z, ca.vec(r_z.T), st_z, g_z)

    def _build_symbolic(self) -> None:
        """The NLP over z with p = [weights; recorded numbers; scales] (:meth:`parameters`), expanded to SX
        where the options say, and its symbolic residual Jacobian: one graph for every problem of its shape."""
        model = self.model
        n_rows, n_data, n = model.raw.shape[0], self.data.size, len(self.names)
        z, p = ca.MX.sym("z", n), ca.MX.sym("p", n_rows + n_data + n)
        weights, data, scale = p[:n_rows], p[n_rows:n_rows + n_data], p[n_rows + n_data:]
        raw_z, g_z, r_z, st_z = model.put_in([model.raw, model.g, model.r, model.ypr_st], scale * z, data)
        e_z = weights * raw_z
        self.nlp, r_vec = {"x": z, "p": p, "f": 0.5 * ca.sumsqr(e_z), "g": g_z}, ca.vec(r_z.T)
        if self.solver_options.expand:
            self.nlp, e_z, ex = expand_problem(self.nlp, e_z, {"raw": raw_z, "r": r_vec, "st": st_z})
            z, p, g_z = self.nlp["x"], self.nlp["p"], self.nlp["g"]
            raw_z, r_vec, st_z = ex["raw"], ex["r"], ex["st"]
        self.jacobian_fun = ca.Function("residual_jacobian", [z, p], [ca.jacobian(e_z, z)])
        self.graph = "built"
        self._functions(z, p, e_z, raw_z, r_vec, st_z, g_z)

    def _functions(self, z, p, e_z, raw_z, r_vec, st_z, g_z) -> None:
        """The residuals, the lever arms, angles and constraints with their Jacobians, and the solver."""
        self.residual_fun = ca.Function("residuals", [z, p], [e_z, raw_z])
        self.derived_fun = ca.Function("derived", [z, p], [r_vec, st_z, ca.jacobian(r_vec, z), ca.jacobian(st_z, z), g_z,
                                                           ca.jacobian(g_z, z)])
        self._build_solver()

    def _build_solver(self, like=None) -> None:
        tic = time.perf_counter()
        self.solver = build_solver(self.nlp, self.solver_options, "calibration", residuals=self.jacobian_fun,
                                   residual_fun=self.residual_fun, like=like)
        self.build_s = time.perf_counter() - tic  # what another worker's solver costs (multistart weighs it)

    # what another problem of this graph takes (:mod:`..model_cache`): its symbols live in the NLP and Functions
    GRAPH_PARTS = ("nlp", "jacobian_fun", "residual_fun", "derived_fun", "solver")

    def graph_parts(self) -> dict:
        return {name: getattr(self, name) for name in self.GRAPH_PARTS}

    def graph_signature(self) -> tuple:
        return len(self.names), self.data.size, int(self.model.raw.shape[0])

    def probe_points(self) -> list:
        """This problem's residuals, constraints, lever arms and angles from its own graph at random unknowns
        on its recorded numbers (:func:`..model_cache.probe`)."""
        m = self.model
        return model_cache.probe(ca.Function("check", [m.x, m.data_sym], [m.raw, m.g, ca.vec(m.r.T), m.ypr_st]),
                                 lambda z: z * self.scale, self.data, self.lbx / self.scale, self.ubx / self.scale,
                                 self.parameters_at)

    def same_graph(self, parts: dict, points: list) -> bool:
        """Whether a kept problem's ``parts`` compute this problem's residuals, constraints, lever arms and
        angles at its :meth:`probe_points`."""
        def evaluate(z, p):
            r, st, _, _, g, _ = parts["derived_fun"](z, p)
            return [parts["residual_fun"](z, p)[1], g, r, st]
        return model_cache.agree_at(points, evaluate)

    def _take_built(self, kept: "model_cache.Built") -> None:
        """The NLP, Functions and Jacobian of a problem of the same graph, and a solver of its own sharing that
        problem's derivatives (one solver is never called from two threads at once)."""
        for name in ("nlp", "jacobian_fun", "residual_fun", "derived_fun"):
            setattr(self, name, kept.parts[name])
        self.graph = "kept"
        self._build_solver(kept.parts["solver"])

    def _moving_bed_choice(self, moving: bool) -> str:
        choice = self.config.moving_bed
        if choice == "auto":
            return "constant" if moving and not self.two_stage else "off"
        if choice != "off" and not moving:
            raise ValueError(f"CalibrationConfig.moving_bed: {choice!r} needs a moving reference velocity (GNSS) beside "
                             "the bottom track; no case here has one (use 'off' or 'auto')")
        return choice

    def weights(self, sigma: dict | None = None) -> np.ndarray:
        return self.model.weights(sigma or self.sigma)

    def parameters(self, sigma: dict | None = None) -> np.ndarray:
        """The NLP's parameters p at the noise levels ``sigma`` (default: the current ones): the weights,
        and for a symbolic problem the recorded numbers and the unknowns' scales after them."""
        return self.parameters_at(self.weights(sigma))

    def parameters_at(self, weights: np.ndarray) -> np.ndarray:
        return weights if self.assembled else np.concatenate([weights, self.data, self.scale])

    def channel_slices(self) -> dict:
        """Slice of each channel in the residuals: keyed by name for one run, by (run, name) for several."""
        sl = self.model.channel_slices()
        return {name: s for (_, name), s in sl.items()} if len(self.runs) == 1 else sl

    # ------------------------------------------------------------------ starts
    def start_points(self, n_starts: int, seed: int) -> np.ndarray:
        """Pre-fit start, empirical-guess start, then a Latin hypercube over the start region."""
        rng = np.random.default_rng(seed)
        angles0 = np.array([self.yaw_guess, 0.0, 0.0])
        starts = [self._x_from([f.params for f in self.fits], angles0, self._centre_guess())]
        emp = [self._empirical_params(run.case, f) for run, f in zip(self.runs, self.fits)]
        if n_starts > 1 and any(e is not None for e in emp):
            starts.append(self._x_from([e or f.params for e, f in zip(emp, self.fits)], angles0, self._centre_guess()))
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
                starts.append(self._x_from([self._jitter(f.params, row[6], row[7]) for f in self.fits], angles, centre))
        x0 = np.clip(np.array(starts), self.lbx, self.ubx)
        return x0 / self.scale

    def _centre_guess(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.1 * self.lever_box])

    @staticmethod
    def _jitter(params: AttitudeParams, u_omega: float, u_decay: float) -> AttitudeParams:
        modes = params.modes.copy()
        if modes.size:
            modes[:, 0] *= 1 + 0.01 * u_omega
            modes[:, 1] = np.clip(modes[:, 1] * (1 + 0.5 * u_decay), 0.0, 3.0)
        return dataclasses.replace(params, modes=modes)

    @staticmethod
    def _empirical_params(case: Case, fit: AttitudeFit) -> AttitudeParams | None:
        """The pre-fit with its strongest mode's frequency and decay from the hull figures (Eqs. 36-47)."""
        from ...models.empirical import motion_guess

        v = case.vessel
        p = fit.params
        if not (v.length_m and v.beam_m and v.height_m and v.mass_kg) or p.modes.size == 0:
            return None
        g = motion_guess(v.length_m, v.beam_m, v.height_m, v.mass_kg, v.draft_m, v.displaced_volume_m3)
        strongest = int(np.argmax(np.hypot(*p.roll_cs.T) + np.hypot(*p.pitch_cs.T)))
        modes = p.modes.copy()
        modes[strongest] = [g.roll_damped_rad_s, g.roll_decay_1_s]
        return dataclasses.replace(p, modes=modes)

    def _x_from(self, params: list, angles, centre) -> np.ndarray:
        angles = np.asarray(angles, dtype=float)
        return self.model.initial_x(params, angles, centre, heading_guess=float(angles[0]))

    # ------------------------------------------------------------------ solve
    def solve(self) -> CalibrationResult:
        """Solve; with ``moving_bed="auto"`` the fitted bed is tested (:mod:`.moving_bed_decision`) and,
        unless the data say it moves, dropped and the problem solved again without it."""
        result = self._solve()
        if self.moving_bed != "constant":
            return result
        turned = result.heading_misalignment_rad if self.head_yaw else 0.0  # the flow in the bed's (true) Earth frame
        flow = mean_flow(self.cases, result.installation_ypr_rad, turned)
        if self.config.moving_bed != "auto":  # a bed kept as asked: said where it moves against the flow
            if result.moving_bed_velocity_se_m_s is not None:
                way = bed_direction(result.moving_bed_velocity_m_s, result.moving_bed_velocity_se_m_s, flow)
                if way["against_flow"]:
                    result.warnings.append(
                        f"moving bed kept as asked (--moving-bed constant) moves towards {way['direction_deg']:.0f} +- "
                        f"{way['direction_se_deg']:.0f} deg, {abs(way['from_flow_deg']):.0f} deg from the flow's "
                        f"{way['flow_direction_deg']:.0f} deg, which no bed does: on these courses it stands in for a "
                        "heading error (--moving-bed auto drops it)")
            return result
        confounded = any("moving_bed_velocity" in c.get("pair", []) for c in result.confounded)
        test = moving_bed_test(result.moving_bed_velocity_m_s, result.moving_bed_velocity_se_m_s, confounded, flow)
        if test["decision"] != "moving":  # freed only when the data say it moves (QRev: a test decides)
            free = result
            result = CalibrationProblem(self.cases, dataclasses.replace(self.config, moving_bed="off"), fit=self.fits).solve()
            if test["decision"] != "fixed":
                why = "not tested by these runs" if test["decision"] == "undetermined" else "not kept"
                result.warnings.append(f"moving bed {why} ({test['reason']}): solved without one; a "
                                       "bed that does move is then carried by the heading: run a loop or stationary test, "
                                       "or calibrate transects on several courses together")
                assumed = assumed_fixed_bed(free, test["decision"])
                result.confounded += assumed
                result.warnings += [c["statement"] for c in assumed]
        result.moving_bed_test = test
        return result

    def _solve(self) -> CalibrationResult:
        cfg = self.config
        x0s = self.start_points(cfg.n_starts, cfg.seed)
        lbz, ubz = self.lbx / self.scale, self.ubx / self.scale
        screen = self._screen()
        if cfg.scheduler != SERIAL:  # the starts on a Dask cluster, each worker building the problem itself
            from .distributed import distributed_multistart

            ms = distributed_multistart(self, x0s)
        elif screen is not None:
            ms = self._screened(screen, x0s)
        else:
            ms = self._multistart(x0s)
        unsettled = None
        if cfg.estimate_noise:
            refit, rounds, moved = self._noise_fixed_point(ms, lbz, ubz)
            settled = (f"noise re-estimated {rounds} times, settled to {100 * VCE_RTOL:g} %" if moved <= VCE_RTOL else
                       f"noise re-estimated {rounds} times, NOT settled: its levels still moved {100 * moved:.1f} %")
            if moved > VCE_RTOL:
                unsettled = f"noise levels: {settled} (the standard errors scale with them)"
            if rounds == 0:  # the multistart's levels were the fixed point: its solution stands
                ms = dataclasses.replace(ms, message=ms.message + f"; noise re-estimated: its levels moved "
                                         f"{100 * moved:.2f} %, settled to {100 * VCE_RTOL:g} % without a refit")
            else:  # the per-start table stays that of the multistart; the final solve is the refit
                ms = dataclasses.replace(ms, x=refit.x, objective=refit.objective, success=refit.success,
                                         status=refit.status, iterations=refit.iterations, lam_g=refit.lam_g, g=refit.g,
                                         message=ms.message + f"; {settled}, refit: {refit.status}")
        result = self._result(ms)
        if unsettled:
            result.warnings.append(unsettled)
        lone = lone_best(ms)
        if lone:
            result.warnings.append(lone + ("; or take the beams' attitude from the sensor's samples (--attitude samples)"
                                           if self.attitude_source == "model" else ""))
        return result

    def _multistart(self, x0s: np.ndarray) -> MultistartResult:
        """Every start of ``x0s`` (scaled unknowns) on this problem, ``config.workers`` at once."""
        make = lambda: build_solver(self.nlp, self.solver_options, "calibration", residuals=self.jacobian_fun,
                                    like=self.solver, residual_fun=self.residual_fun)
        return multistart(self.solver, x0s, self.lbx / self.scale, self.ubx / self.scale, self.lbg, self.ubg,
                          self.parameters(), workers=self.config.workers, make_solver=make,
                          warm_start=self.config.solver.warm_start, build_s=self.build_s)

    def _screen(self) -> "CalibrationProblem | None":
        """This problem on every k-th ping and reference sample (:meth:`.RunSetup.thinned`, about
        ``config.screen_pings`` pings in all, the same unknowns), whose multistart picks the one start
        solved on all the data; None where every start is solved on all of it (short runs, one start, a
        velocity per ping, starts on a cluster)."""
        cfg = self.config
        n = sum(r.case.pings.n for r in self.runs)
        if cfg.screen_pings is None or cfg.n_starts < 2 or self.walk or cfg.scheduler != SERIAL or n < 2 * cfg.screen_pings:
            return None
        every = int(np.ceil(n / cfg.screen_pings))
        screen = object.__new__(type(self))
        screen.__dict__.update({k: self.__dict__[k] for k in ("identity", "identity_warnings", "two_stage", "fits")})
        screen.config = dataclasses.replace(cfg, screen_pings=None)
        runs = [r.thinned(every) for r in self.runs]
        screen.cases = [r.case for r in runs]
        screen._set_up(runs, yaw_guess=self.yaw_guess)
        if screen.names != self.names:  # pragma: no cover - thinning keeps the span, the knots and the choices
            raise RuntimeError(f"screen_pings: the thinned problem's unknowns differ ({len(screen.names)} against "
                               f"{len(self.names)})")
        screen.every = every
        return screen

    def _screened(self, screen: "CalibrationProblem", x0s: np.ndarray) -> MultistartResult:
        """The starts solved on ``screen`` (:meth:`_screen`), the best of them then on all the data; the
        per-start table is the screen's (its objectives those of the thinned rows)."""
        picked = screen._multistart(x0s * self.scale / screen.scale)
        lbz, ubz = self.lbx / self.scale, self.ubx / self.scale
        x0 = np.clip(picked.x * screen.scale / self.scale, lbz, ubz)
        # from a solution of the same unknowns, as the noise refit is: IPOPT's barrier need not walk down from a cold start's
        full = multistart(self._refit_solver(), x0[None, :], lbz, ubz, self.lbg, self.ubg, self.parameters(), progress=False)
        n, n_screen = (sum(c.pings.n for c in p.cases) for p in (self, screen))
        return dataclasses.replace(
            full, starts=picked.starts, n_groups=picked.n_groups, fraction_at_best=picked.fraction_at_best,
            best_start=picked.best_start, time_s=picked.time_s + full.time_s,
            message=f"{len(x0s)} starts screened on 1 ping in {screen.every} ({n_screen} of {n} pings): {picked.message}; "
                    f"start {picked.best_start} then solved on all of them: {full.status}")

    def _noise_fixed_point(self, ms: MultistartResult, lbz, ubz) -> tuple:
        """(refit, refits, largest relative move of a noise level at the last re-estimation): the noise levels
        re-estimated from the fit and the problem refitted from its solution until no level moves by more
        than VCE_RTOL (at most VCE_MAX_ITERATIONS refits, a large random walk's VCE_WALK_ITERATIONS), so the
        answer is the levels' fixed point, not wherever one step from the independent starting levels lands.
        Starting levels the first re-estimation moves by no more than VCE_RTOL are that fixed point already:
        no refit (10^5 pool_m0 pings: levels moved 0.19 %, the refit's four iterations 2.5 s of 8)."""
        refit, solver = ms, None
        most = VCE_WALK_ITERATIONS if self.walk and self.lbx.size > SCORING_MAX_UNKNOWNS else VCE_MAX_ITERATIONS
        for rounds in range(1, most + 1):
            new = self._noise_levels(refit.x)
            moved = largest_move(new, self.sigma)
            if moved <= VCE_RTOL:  # settled: the last fit's levels are the fixed point's (the starting ones may be)
                return refit, rounds - 1, moved
            self.sigma = new
            solver = solver or self._refit_solver()
            refit = multistart(solver, refit.x[None, :], lbz, ubz, self.lbg, self.ubg, self.parameters(), progress=False)
        return refit, most, largest_move(self._noise_levels(refit.x), self.sigma)

    def _refit_solver(self):
        """The solver of the refit from the solution: IPOPT's barrier starting at ``REFIT_MU_INIT``
        where another solver costs nothing to build (an assembled Jacobian's callbacks); the
        problem's own elsewhere."""
        options = self.solver_options
        if not self.assembled or options.method != "ipopt" or options.warm_start or options.mu_init <= REFIT_MU_INIT:
            return self.solver
        return build_solver(self.nlp, dataclasses.replace(options, mu_init=REFIT_MU_INIT), "calibration_refit",
                            residuals=self.jacobian_fun, residual_fun=self.residual_fun)

    def _noise_levels(self, z: np.ndarray) -> dict:
        """Each (run, group)'s noise level from the residuals at ``z``: on knots, the RMS with the
        degrees of freedom shared out; with a random walk, its residuals over their redundancy
        (Helmert / Foerstner variance components, the walk's intensity one of them: REML for a
        linear-Gaussian walk), since a velocity per ping takes up a share of each group that
        differs from group to group; reached by Fisher scoring where the problem has at most
        ``SCORING_MAX_UNKNOWNS`` unknowns (``normal_equations.scored_levels``), whose steps do not crawl."""
        p = self.parameters()
        raw = np.asarray(self.residual_fun(z, p)[1]).ravel()
        if not self.walk:
            return self.model.reestimate_sigmas(raw, len(z), self.sigma)
        model = self.model
        J = self.jacobian_fun(z, p)
        J = J.tocsr() if sp.issparse(J) else J.sparse()
        used = model.mask > 0
        scored = scored_levels(J, raw, model.row_sigma, used, model.sigma_keys, self.sigma)
        if scored is not None:  # a Fisher-scoring step to the same fixed point, where the dense algebra is cheap
            return scored
        r = redundancy(J, model.row_sigma, used, len(model.sigma_keys), local=model.velocity_columns())
        return group_levels(raw, model.row_sigma, used, model.sigma_keys, r, self.sigma)

    # ------------------------------------------------------------------ result
    def _result(self, ms: MultistartResult) -> CalibrationResult:
        model, u, cfg = self.model, self.model.unknowns, self.config
        w = self.parameters()
        e = np.asarray(self.residual_fun(ms.x, w)[0]).ravel()
        # an assembled one stays sparse (rows x unknowns), its J^T J from the same pass; a random walk's
        # (a velocity per ping) sparse too; on knots only J's products are needed (the information is
        # J^T J, the sandwich J @ P_Q): J stays an operator on its blocks, never formed
        information = None
        if self.assembled and not self.walk:
            J, information = self.jacobian_fun.at(ms.x, w), self.jacobian_fun.gram(ms.x, w)
        elif self.assembled:
            J, information = self.jacobian_fun.jacobian_and_gram(ms.x, w)
        else:
            J = self.jacobian_fun(ms.x, w)
            J = J.sparse().tocsr() if self.walk else np.asarray(J)
        r_flat, st, Jr, Jst, g, Jg = (np.asarray(a) for a in self.derived_fun(ms.x, w))
        eq = (self.lbg == self.ubg) if len(self.lbg) else np.zeros(0, dtype=bool)
        Lst = np.eye(3) if self.head_sensor else np.asarray(euler_matrix(*np.asarray(st).ravel()))
        context = {"beam_dirs_sensor": model.beam_dirs_t @ Lst.T, "frame": self.frame,
                   "navigation": model.velocity_columns()}
        if self.walk:  # a velocity per ping: eliminated first, nothing of size unknowns x unknowns formed
            unc = uncertainty_eliminating(J, Jg[eq] if eq.any() else None, self.names, self.scale,
                                          context["navigation"], context)
        else:
            unc = uncertainty(J, Jg[eq] if eq.any() else None, self.names, self.scale, context, information=information)
        x = ms.x * self.scale
        # Standard errors of the shared unknowns Q: Newey-West sandwich, never below white noise's.
        Q = np.concatenate([u.index(k) for k in ("heading", "installation", "lever", "moving_bed")])
        cov_Q, se_info = self._shared_covariance(J, e, unc, Q)
        se_x = unc.se_z * self.scale
        se_x[Q] = np.sqrt(np.maximum(np.diag(cov_Q), 0)) * self.scale[Q]
        se_x[Q[~np.isfinite(unc.se_z[Q])]] = np.inf
        # lever arms and angles depend on the shared unknowns only: their Jacobians' columns Q carry them
        cov_r = Jr[:, Q] @ cov_Q @ Jr[:, Q].T  # (12, 12), rows r1x, r1y, r1z, r2x, ...
        se_r = np.sqrt(np.maximum(np.diag(cov_r), 0)).reshape(4, 3)
        se_st = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Jst[:, Q], cov_Q, Jst[:, Q]), 0)) if Jst.size else np.zeros(3)
        r_s = r_flat.reshape(4, 3)
        se_r[~unc.determined_mask(Jr).reshape(4, 3)] = np.inf
        # held by the search box, or known no better than the box: the bound, not the data, set the number
        box_held = (np.abs(r_s) >= 0.999 * self.lever_box) | (se_r > self.lever_box)
        se_r[box_held] = np.inf
        aliased = any(run.attitude_source == "samples" and samples_per_period(run.case, run.fit) < MIN_SAMPLES_PER_PERIOD
                      for run in self.runs)
        if aliased:  # the rate between samples is not measured: the tangential velocity is not known
            se_r[:] = np.inf
        viol = 0.0
        if len(self.lbg):
            g = g.ravel()
            viol = float(np.max(np.concatenate([np.maximum(self.lbg - g, 0), np.maximum(g - self.ubg, 0)])))
        warn = list(unc.warnings)
        sampled = [run.case.name for run in self.runs if run.attitude_source == "samples"]
        if sampled:
            reasons = "; ".join(sorted({run.attitude_reason for run in self.runs if run.attitude_source == "samples"}))
            joined = "; ".join(sorted({run.samples.reason for run in self.runs if run.attitude_source == "samples"}))
            warn.append(f"beams' attitude from the sensor's samples, {joined} ({reasons}); attitude_model is "
                        "the pre-fit, not used by the beams" + (f" (runs {', '.join(sampled)})" if len(self.runs) > 1 else ""))
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
            nominal = np.asarray(cfg.nominal_installation_ypr_rad, dtype=float)
            Ltb = np.asarray(euler_matrix(*nominal))
            radius = r_s @ Ltb.T
            weights = Ltb.T**2  # a component not determined (inf) spreads only where the rotation takes it
            radius_se = np.sqrt(np.where(np.isfinite(se_r), se_r, 0.0) ** 2 @ weights)
            radius_se[(~np.isfinite(se_r)).astype(float) @ (weights > 0) > 0] = np.inf
            ypr, ypr_se = nominal, np.full(3, np.inf)
            if self.head_yaw:
                i = u.index("heading")[0]
                misalignment = float(x[i])
                misalignment_se = float(se_x[i])
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
                i_angles = u.index("installation")
                span = self.ubx[i_angles] - self.lbx[i_angles]
                at_box = np.minimum(x[i_angles] - self.lbx[i_angles], self.ubx[i_angles] - x[i_angles]) < 1e-3 * span
                if at_box.any():
                    ypr_se[at_box] = np.inf
                    warn.append(f"installation angle(s) {', '.join(np.array(ANGLE_NAMES)[at_box])} held by the search box "
                                f"(+-{np.rad2deg(cfg.installation_bound_rad):g} deg around "
                                f"({np.rad2deg(self.yaw_guess):+.2f}, 0, 0) deg): not determined, reported as null; widen "
                                "installation_bound_rad or check the attitude reference")
        bed = self._bed_estimates(x, se_x, cov_Q, Q)
        deviation = deviation_se = None
        if self.head_yaw and len(u.index("heading")) == 3:
            deviation, deviation_se = x[u.index("heading")[1:]], se_x[u.index("heading")[1:]]
        confounded = self._confounding(unc, Q)
        for c in confounded:
            warn.append(c["statement"])
        if deviation is not None and model.has_prior:
            prior = cfg.compass_deviation_prior_rad
            data_share = np.clip(1 - (deviation_se / prior) ** 2, 0, 1)
            se_info["compass_deviation"] = {
                "prior_sd_rad": prior, "heading_span": self.heading_span, "data_share": data_share.tolist(),
                "note": (f"B and C carry the prior N(0, ({np.rad2deg(prior):.2f} deg)^2); the data fix "
                         f"{100 * data_share.min():.0f}-{100 * data_share.max():.0f} % of their information (headings span "
                         f"{self.heading_span:.3f}, 0.5 = all round); what the headings leave open enters the bed's and "
                         "the misalignment's standard errors")}
        declination, declination_note, spread = self._declination()
        warn += self.identity_warnings + spread
        self._se_x = se_x
        runs = self._run_results(x, e, bed)
        first = runs[0]
        p_att = self.fits[0].params if self.runs[0].attitude_source != "model" else \
            AttitudeParams.unpack(x[u.index("attitude0")], self.runs[0].fit.params.layout)
        pooled = len(self.runs) > 1
        return CalibrationResult(
            radius_vectors_m=radius, radius_vectors_se_m=radius_se, installation_ypr_rad=ypr,
            installation_ypr_se_rad=ypr_se, installation_determined=not self.head_sensor and bool(np.all(np.isfinite(ypr_se))),
            attitude=p_att, attitude_frame=self.frame, lever_arms_sensor_m=r_s, lever_arms_sensor_se_m=se_r, lever_arms_cov_m2=cov_r,
            objective=float(ms.objective), max_constraint_violation=viol, formulation=cfg.formulation,
            timing=", ".join(dict.fromkeys(r.timing for r in self.runs)),
            noise_sigma=self._pooled_sigma() if pooled else first.noise_sigma,
            chi2_per_channel=self._pooled_chi2(e) if pooled else first.chi2_per_channel,
            multistart=ms, uncertainty=unc, x_names=list(self.names), x=x, x_se=se_x, config=cfg,
            velocity_knots_s=None if pooled else first.velocity_knots_s,
            velocity_knots_m_s=None if pooled else first.velocity_knots_m_s,
            heading_misalignment_rad=misalignment, heading_misalignment_se_rad=misalignment_se, warnings=warn,
            jacobian="assembled" if self.assembled else "symbolic", graph=self.graph,
            attitude_source=", ".join(dict.fromkeys("samples" if r.attitude_source == "samples" else "model" for r in self.runs)),
            attitude_source_reason="; ".join(dict.fromkeys(r.attitude_reason for r in self.runs)),
            moving_bed=self.moving_bed, compass_deviation_rad=deviation, compass_deviation_se_rad=deviation_se,
            compass_deviation_centre=model.heading_centre,
            magnetic_declination_rad=declination, magnetic_declination_note=declination_note,
            standard_errors=se_info, confounded=confounded, runs=runs, **bed["top"],
            instrument=self.identity, site=site_of(self.cases),
        )

    def _shared_covariance(self, J, e, unc, Q) -> tuple[np.ndarray, dict]:
        """Covariance of the shared unknowns (scaled): HAC, inflated where needed to at least
        the white-noise covariance's diagonal; and how it was formed."""
        cov_Q = unc.cov_columns(Q)
        white = cov_Q[Q]
        info = {"method": self.config.standard_errors}
        if self.config.standard_errors == "white" or Q.size == 0:
            return white, info
        sw = sandwich(J, e, cov_Q, self.model.row_run, self.model.row_time,
                      ping_bins([run.case for run in self.runs]), known=self.model.known_rows)
        d_w = np.diag(white)
        cov = at_least_white(sw.cov, d_w)
        inflation = np.sqrt(np.diag(cov) / np.where(d_w > 0, d_w, np.inf))
        info.update({"lags": sw.lags, "influence_lag1": sw.rho, "time_bins": sw.bins,
                     "inflation_over_white": {self.names[i]: float(f) for i, f in zip(Q, inflation) if np.isfinite(f) and f > 0},
                     "rule": "Newey-West (Bartlett) over each run's ping-interval time bins, Andrews AR(1) bandwidth; "
                             "each shared unknown's SE is the larger of the sandwich's and the white-noise one"})
        return cov, info

    def _bed_estimates(self, x, se_x, cov_Q, Q) -> dict:
        """Bed velocity: the shared parameters and, per run, the velocity that applies to its pings."""
        u, model = self.model.unknowns, self.model
        out = {"top": {}, "runs": [None] * len(self.runs)}
        idx = u.index("moving_bed")
        if idx.size == 0:
            return out
        pos = np.searchsorted(Q, idx)  # bed columns within Q (Q is built in order)
        values = x[idx].reshape(-1, 2)
        se = se_x[idx].reshape(-1, 2)
        C = cov_Q[np.ix_(pos, pos)] * np.outer(self.scale[idx], self.scale[idx])
        undetermined = ~np.isfinite(se_x[idx])
        for k in range(len(self.runs)):
            w = model.bed_basis(k).mean(axis=0)  # mean weight of each bed value under this run's pings
            A = np.kron(w[None, :], np.eye(2))  # (2, 2 n_bed): the run's mean bed from the parameters
            v_run = A @ values.reshape(-1)
            se_run = np.sqrt(np.maximum(np.diag(A @ C @ A.T), 0))
            se_run[np.any(undetermined[None, :] & (np.abs(A) > 0), axis=1)] = np.inf
            out["runs"][k] = (v_run, se_run)
        if values.shape[0] == 1:
            out["top"] = {"moving_bed_velocity_m_s": values[0], "moving_bed_velocity_se_m_s": se[0]}
        else:
            A = np.kron(np.full((1, values.shape[0]), 1.0 / values.shape[0]), np.eye(2))
            se_mean = np.sqrt(np.maximum(np.diag(A @ C @ A.T), 0))
            se_mean[np.any(undetermined[None, :] & (np.abs(A) > 0), axis=1)] = np.inf
            out["top"] = {"moving_bed_velocity_m_s": values.mean(axis=0), "moving_bed_velocity_se_m_s": se_mean,
                          "moving_bed_knots_m_s": values, "moving_bed_knots_se_m_s": se}
        return out

    def _confounding(self, unc, Q) -> list:
        """Pairs the data cannot separate, in words: a yaw (heading misalignment or installation yaw)
        whose variance is mostly shared with the moving bed's (one course, or opposite courses)."""
        u = self.model.unknowns
        bed = u.index("moving_bed")
        yaw = u.index("heading")[:1] if self.head_yaw else (u.index("installation")[:1] if not self.fixed_installation else [])
        if bed.size == 0 or len(yaw) == 0:
            return []
        name = "heading misalignment" if self.head_yaw else "installation yaw"
        courses = self._course_summary()
        i = int(yaw[0])
        if not np.isfinite(unc.se_z[i]):
            share = 1.0
        else:
            C = unc.cov_columns(np.concatenate([[i], bed]))  # every unknown with the yaw and the bed
            c_yb, C_bb = C[i, 1:], C[bed, 1:]
            share = float(c_yb @ np.linalg.pinv(C_bb) @ c_yb / C[i, 0]) if C[i, 0] > 0 else 0.0
        if share < CONFOUNDED_R2:
            return []
        statement = (f"moving bed vs {name}: {share:.0%} of the {name}'s variance is shared with the bed velocity's "
                     f"({courses}): a constant heading error and a bed moving under the bottom track turn the "
                     f"bottom-track velocity alike on one course; the {name}'s standard error carries it. Calibrate "
                     "transects in several directions together (calibrate --joint), or verify the bed is fixed (loop or "
                     "stationary test) and use --moving-bed off")
        return [{"pair": [name.replace(" ", "_"), "moving_bed_velocity"], "shared_variance": share,
                 "reason": courses, "statement": statement}]

    def _course_summary(self) -> str:
        """Each run's mean course over ground (deg), from its reference."""
        parts = []
        for run in self.runs:
            if not run.moving_reference:
                continue
            v = run.reference_velocity_m_s[:, :2]
            ok = np.all(np.isfinite(v), axis=1)
            course = np.rad2deg(np.angle(np.mean(np.exp(1j * np.arctan2(v[ok, 1], v[ok, 0]))))) % 360
            parts.append(f"{course:.0f}")
        span = "one course" if len(parts) == 1 else "courses"
        return f"{span} over ground {', '.join(parts)} deg"

    def _declination(self) -> tuple[float | None, str, list]:
        """The site's magnetic declination: given, else IGRF at each run's position and time (their
        circular mean: one site), else unknown with the reason; and a warning when the runs'
        declinations spread wider than one site's."""
        from ...cases.site import case_declination

        if self.config.magnetic_declination_rad is not None:
            return float(self.config.magnetic_declination_rad), "given (CalibrationConfig.magnetic_declination_rad)", []
        found = [case_declination(c) for c in self.cases]
        values = [v for v, _ in found if v is not None]
        if not values:
            return None, found[0][1] + "; give --declination-deg to compare the misalignment with it", []
        mean = float(np.angle(np.mean(np.exp(1j * np.array(values)))))
        spread = float(np.ptp(np.unwrap(values)))
        warn = [] if spread <= DECLINATION_SPAN_RAD else [
            f"the runs' magnetic declinations span {np.rad2deg(spread):.1f} deg (more than a survey's "
            f"{np.rad2deg(DECLINATION_SPAN_RAD):g} deg): runs of different sites or years calibrated as one"]
        lo, hi = np.rad2deg(min(values)), np.rad2deg(max(values))
        note = found[0][1] if len(values) == 1 else (
            f"IGRF-14, the mean of {len(values)} runs" + (f": {lo:+.2f} to {hi:+.2f} deg" if f"{lo:.2f}" != f"{hi:.2f}" else ""))
        return mean, note, warn

    def _run_results(self, x, e, bed) -> list:
        u, model = self.model.unknowns, self.model
        chi2 = model.chi2(e)
        slices = model.channel_slices()
        out = []
        for k, run in enumerate(self.runs):
            lag1 = {}
            for (rk, name), s in slices.items():
                if rk == k:
                    m = model.mask[s] > 0
                    lag1[name] = float(autocorrelation(e[s][m], 1)[0]) if m.sum() > 3 else None
            knots = vk = None
            if run.knots is not None:
                knots, vk = run.knots, x[u.index(f"velocity{k}")].reshape(-1, 3)
            psi = run.case.attitude.heading_rad
            psi = psi[np.isfinite(psi)]
            mean = np.angle(np.mean(np.exp(1j * psi)))
            sd = np.sqrt(-2 * np.log(max(abs(np.mean(np.exp(1j * psi))), 1e-12)))
            v_bed, se_bed = bed["runs"][k] if bed["runs"][k] is not None else (None, None)
            i_depth = u.index(f"depth_offset{k}")
            depth = (float(x[i_depth[0]]), float(self._se_x[i_depth[0]])) if i_depth.size else (None, None)
            out.append(RunResult(
                case=run.case.name, n_pings=run.case.pings.n, moving_bed_velocity_m_s=v_bed, moving_bed_velocity_se_m_s=se_bed,
                noise_sigma={g: self.sigma[(k, g)] for (rk, g) in model.sigma_keys if rk == k},
                chi2_per_channel={name: v for (rk, name), v in chi2.items() if rk == k}, residual_lag1=lag1,
                attitude_source="samples" if run.attitude_source == "samples" else "model",
                attitude_source_reason=run.attitude_reason, timing=run.timing,
                heading_deg=(float(np.rad2deg(mean) % 360), float(np.rad2deg(sd))),
                velocity_knots_s=knots, velocity_knots_m_s=vk, transducer_depth_offset_m=depth[0],
                transducer_depth_offset_se_m=depth[1], navigation=run.navigation,
                attitude_interpolation=run.samples.interpolation if run.attitude_source == "samples" else None,
                attitude=run.fit.params if run.attitude_source != "model" else
                AttitudeParams.unpack(x[u.index(f"attitude{k}")], run.fit.params.layout)))
        return out

    def _pooled_sigma(self) -> dict:
        """Each group's noise level over all runs (RMS weighted by valid rows)."""
        model = self.model
        out = {}
        for g in dict.fromkeys(key[1] for key in model.sigma_keys if key[1] != "prior"):
            num = den = 0.0
            for i, key in enumerate(model.sigma_keys):
                if key[1] == g:
                    n = float(np.sum(model.mask[model.row_sigma == i]))
                    num, den = num + n * self.sigma[key] ** 2, den + n
            out[g] = float(np.sqrt(num / den)) if den else None
        return out

    def _pooled_chi2(self, e) -> dict:
        out = {}
        for name in dict.fromkeys(c.name for c in self.model.channels if c.group != "prior"):
            num = den = 0.0
            for (k, n), s in self.model.channel_slices().items():
                if n == name:
                    m = self.model.mask[s] > 0
                    num, den = num + float(np.sum(e[s][m] ** 2)), den + float(m.sum())
            out[name] = num / max(den, 1.0)
        return out


def assumed_fixed_bed(free: CalibrationResult, decision: str = "undetermined") -> list:
    """The confounding of the solve with the bed free, carried into the result solved with it fixed
    (the moving-bed test could not decide, or the fitted bed moved against the flow): the yaw is then
    known to its reported SE only if the bed is still; each entry adds the yaw's SE with the bed free
    (``se_if_bed_moves_rad``), so a reader of CALIB.json sees both without parsing a warning."""
    entries = [c for c in free.confounded if "moving_bed_velocity" in c.get("pair", [])]
    if decision == "against_flow" and not entries:  # the bed's other reading, shared with the yaw or not
        yaw = "heading_misalignment" if np.isfinite(free.heading_misalignment_se_rad) else "installation_yaw"
        entries = [{"pair": [yaw, "moving_bed_velocity"], "shared_variance": None, "reason": "the bed against the flow"}]
    out = []
    for c in entries:
        heading = c["pair"][0] == "heading_misalignment"
        value = free.heading_misalignment_rad if heading else free.installation_ypr_rad[0]
        se = free.heading_misalignment_se_rad if heading else free.installation_ypr_se_rad[0]
        name = c["pair"][0].replace("_", " ")
        if decision == "against_flow":
            assumed = "bed fixed (the bed fitted beside it moved against the flow)"
            why = (f"the bed fitted beside it moved against the flow (the {name} {np.rad2deg(value):+.2f} deg there), "
                   "which no bed does; if a bed does move downstream")
        else:
            assumed = "bed fixed (the moving-bed test could not decide)"
            why = (f"the moving-bed test could not tell a moving bed from a heading error on these courses; if the bed "
                   f"moves")
        out.append({**c, "assumed": assumed, "se_if_bed_moves_rad": float(se), "value_if_bed_moves_rad": float(value),
                    "statement": (f"{name} solved with the bed fixed: {why}, the {name} is known only to +- "
                                  f"{np.rad2deg(se):.2f} deg (its SE with the bed free"
                                  + ("" if decision == "against_flow" else f", where it is {np.rad2deg(value):+.2f} deg")
                                  + "), not to its reported SE")})
    return out


def calibrate(case: Case, config: CalibrationConfig | None = None) -> CalibrationResult:
    """Joint calibration of one case (see module docstring)."""
    return CalibrationProblem(case, config or CalibrationConfig()).solve()


def calibrate_runs(cases, config: CalibrationConfig | None = None) -> CalibrationResult:
    """Joint calibration of several runs of one boat at one site in one NLP: shared lever arms,
    installation angles or heading misalignment (and compass deviation), one moving bed;
    per run its attitude and navigation. ``result.runs`` holds each run's own numbers."""
    return CalibrationProblem(list(cases), config or CalibrationConfig()).solve()


def _one_instrument(cases) -> tuple:
    """The runs' instrument identity, refusing runs of different instruments in one line; and
    warnings when the runs lie farther apart than a survey reaches (sites, dates)."""
    ids = [identity_of(c) for c in cases]
    for case, other in zip(cases[1:], ids[1:]):
        why = instrument_difference(ids[0], other)
        if why:
            raise ValueError(f"cases: {cases[0].name} ({ids[0].label()}) and {case.name} ({other.label()}) are two "
                             f"instruments ({why}): a joint calibration is of one instrument on one installation")
    warnings = []
    first = site_of(cases[:1])
    for case in cases[1:]:
        far = site_differences(first, site_of([case]))
        if far:
            warnings.append(f"runs {cases[0].name} and {case.name} lie {' and '.join(far)}: one installation and "
                            "compass over both is assumed")
    return ids[0], warnings

