"""The diagnosis model: the calibration's measurement model of one or several runs
(:class:`~adcpdyn.estimators.measurement_model.SurveyModel`, the same builder) plus any
effects of the catalog, one NLP.

The base is what the calibration estimates, not the paper's plainest model: per run its
attitude (the motion model with free decays, or the sensor's samples where no model
follows) and its navigation (piecewise-linear, following the reference: speed changes are
the base's); shared, the lever arms (head centre P, ``minimal`` formulation), the
installation angles (vessel-frame sensor against a moving reference) or the heading
misalignment (sensor in the head). With a calibration, every calibrated platform quantity is
pinned at its value (:class:`Pins`) and its noise levels start the fit. Every effect adds its
unknowns through the hooks of :class:`adcpdyn.models.effects.base.Effect`, on the motion model
or on the sensor's samples. Residuals are kept unweighted per channel; the objective weights
them by noise levels per (run, channel group) passed as parameters, so noise can be
re-estimated without rebuilding; the recorded numbers and the unknowns' scales are parameters too, so
another run of the same shape takes the graph built before (:mod:`..model_cache`).
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import threading
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...solvers.multistart import SolverOptions, build_solver, multistart
from ..attitude_fit import periodogram_peak
from ..knots import hat_basis
from ..measurement_model import VELOCITY_NAME, EffectTerm, ModelSpec, SurveyModel, channel_slices
from ..statistics.normal_equations import as_sparse, log_det_normal
from .. import model_cache

# The per-ping models as machine code from the per-machine cache (:mod:`...solvers.compiled`) at any
# size: a diagnosis refits tens of NLPs, so even a 261-ping file gains (winriver01, random-walk base:
# 34.8 s interpreted, 24.7 s compiling into an empty cache, 20-21 s with it warm; same numbers to ~1e-8).
GAP_COMPILE_MIN_PINGS = 0
# candidate models are built in threads and share their per-ping models' compiled Functions (solvers/compiled.py),
# whose derivatives CasADi derives on first use and keeps: one model's symbolic build at a time, the solves in parallel
_BUILD_LOCK = threading.RLock()
BOUND_TOL = 1e-5  # an unknown this close to a bound, relative to its range (or its scale where larger), is held by it


def group_of(channel: str) -> str:
    return channel.split("/")[-1].split("_")[0]


def noise_key(channel: str) -> str:
    """The noise level's name of a channel: its group, prefixed by the run with several runs."""
    run, _, local = channel.rpartition("/")
    return f"{run}/{local.split('_')[0]}" if run else local.split("_")[0]


@dataclass(frozen=True)
class Pins:
    """Unknowns held at given values (a calibration's platform quantities), by name."""

    values: dict = field(default_factory=dict)
    source: str = ""


@dataclass
class DiagnosisBase:
    """What every model of one diagnosis shares: the runs, the base's model spec, the pins
    and the starting noise levels per (run, group); ``noise_moved``: the largest relative move of a
    noise level at the last of a random walk's re-estimations (None on knots); ``held``: effect
    unknowns held at the runs' own values (found on them before, e.g. by their calibration), in
    every model that carries them."""

    runs: list
    spec: ModelSpec
    pins: Pins
    sigma0: dict
    notes: list = field(default_factory=list)
    noise_moved: float | None = None
    held: dict = field(default_factory=dict)

    @property
    def sampled(self) -> bool:
        return any(r.attitude_source == "samples" for r in self.runs)

    def at_delays(self, **delays: float) -> "DiagnosisBase":
        """Every run at other current estimates of its delays (:meth:`.run_setup.RunSetup.at_delays`)."""
        return dataclasses.replace(self, runs=[r.at_delays(**delays) for r in self.runs])


def free_jacobian(fit) -> tuple:
    """The fit's weighted-residual Jacobian (scipy sparse) on its free unknowns, and their columns."""
    J = as_sparse(fit.jacobian)
    free = getattr(fit, "free", None)
    cols = np.flatnonzero(free) if free is not None else np.arange(J.shape[1])
    return J[:, cols], cols


def velocity_columns(model, cols) -> np.ndarray | None:
    """Which of the unknowns ``cols`` are navigation velocities (V<j>_<axis>, per run): each row
    touches a few neighbouring ones, so their block of the normal matrix is banded."""
    names = getattr(model, "names", None)
    if names is None:
        return None
    return np.array([VELOCITY_NAME.fullmatch(names[c].split("/")[-1]) is not None for c in cols], dtype=bool)


@dataclass
class Fit:
    """One solved model: estimates, residuals per channel and the solver's account."""

    effects: list
    x: np.ndarray
    names: list
    raw: np.ndarray  # unweighted residuals, model - measurement (0 where masked)
    sigma: dict
    objective: float
    success: bool
    status: str
    iterations: int
    jacobian: object  # scipy sparse: of the weighted residuals w.r.t. the scaled unknowns
    scale: np.ndarray
    free: np.ndarray | None = None  # unknowns neither pinned nor held by an active bound
    profile_se: dict = field(default_factory=dict)  # SEs of unknowns pinned at a likelihood profile's maximum

    @property
    def values(self) -> dict:
        """The estimates by unknown name (a warm start for another model: ``GapModel.start``)."""
        return dict(zip(self.names, self.x))

    def group_rss(self, model: "GapModel") -> dict:
        out = {}
        for i, key in enumerate(model.sigma_keys):
            m = (model.row_sigma == i) & (model.mask > 0)
            out[key] = (float(np.sum(self.raw[m] ** 2)), int(m.sum()))
        return out

    def log_likelihood(self, model: "GapModel") -> float:
        """Gaussian log-likelihood with each (run, group)'s noise level profiled out; with a velocity
        per ping (random walk), marginal over those velocities (Laplace, exact for a linear-Gaussian
        walk): the joint likelihood treats them as parameters and rewards whatever lets their path
        be smoother (the prior's rows shrink), e.g. a reference delay of any fraction of a ping that
        mixes two of them; -1/2 log det of their information at the profiled levels charges it back."""
        ll, levels = 0.0, {}
        for key, (rss, n) in self.group_rss(model).items():
            if n:
                ll += -0.5 * n * (np.log(2 * np.pi * max(rss, 1e-300) / n) + 1)
                levels[key] = np.sqrt(max(rss, 1e-300) / n)
        if getattr(model, "random_walk", False) and self.jacobian is not None:
            ll -= 0.5 * self.latent_log_det(model, levels)
        return ll

    def latent_log_det(self, model: "GapModel", levels: dict) -> float:
        """log det of the per-ping velocities' information J_V^T W J_V, the rows weighted by the noise
        ``levels`` ((run, group) -> sigma) instead of the fit's own."""
        J, cols = free_jacobian(self)
        ratio = np.array([self.sigma[k] / levels.get(k, self.sigma[k]) for k in model.sigma_keys])[model.row_sigma]
        return log_det_normal(sp.diags(np.where(model.mask > 0, ratio, 0.0)) @ J[:, velocity_columns(model, cols)])

    def effect_values(self, model: "GapModel") -> dict:
        return {n: float(self.x[i]) for n, i in zip(model.effect_names, model.effect_index)}


class GapModel:
    """The base model of :class:`DiagnosisBase` plus effects as one NLP over z = x / scale."""

    def __init__(self, base: DiagnosisBase, effects=(), peaks: dict | None = None, solver: SolverOptions | None = None):
        with _BUILD_LOCK:
            self._build(base, effects, peaks, solver)

    def _build(self, base: DiagnosisBase, effects, peaks, solver):
        self.base = base
        self.effects = [t if isinstance(t, EffectTerm) else EffectTerm(t) for t in effects]
        self.model = model = SurveyModel(base.runs, base.spec, self.effects, peaks, compile_min_pings=GAP_COMPILE_MIN_PINGS,
                                         data_parameters=True)
        u = model.unknowns
        self.names, self.scale = list(u.names), u.scale
        self.lbx, self.ubx = u.lower, u.upper
        # calibrated quantities where the calibration put them, the runs' own effects where this model carries them:
        # held, constants of the graph (:meth:`_calibrated_constants`)
        held = {**base.pins.values, **{n: v for n, v in base.held.items() if n in self.names}}
        self.constant = np.zeros(len(self.names), dtype=bool)
        for name, value in held.items():
            i = self.names.index(name)
            self.lbx[i] = self.ubx[i] = value
            self.constant[i] = True
        self.effect_index = np.concatenate([u.index(f"effect{i}") for i in range(len(self.effects))] or [np.zeros(0, int)])
        self.effect_index = [int(i) for i in self.effect_index]
        self.effect_names = [self.names[i] for i in self.effect_index]
        self.base_index = [i for i in range(len(self.names)) if i not in set(self.effect_index)]
        self.channels = [(self.channel_name(c), c.size) for c in model.channels if c.group != "prior"]
        n_data = sum(n for _, n in self.channels)
        self.mask, self.times, self.row_run = model.mask, model.row_time, model.row_run
        self.sigma_keys, self.row_sigma = model.sigma_keys, model.row_sigma
        self.random_walk = any(r.random_walk for r in base.runs)  # a velocity per ping somewhere
        self.groups_present = list(dict.fromkeys(k[1] for k in self.sigma_keys))
        if model.raw.shape[0] != n_data:
            raise ValueError("diagnosis: the base carries no prior (its heading deviation is pinned or absent)")

        x = model.x
        self.data = model.data_values  # the recorded numbers, the NLP's parameters after the weights
        self.solver_options = solver or SolverOptions(tol=1e-8, max_iter=300, hessian="gauss-newton", expand=False)
        self.lbg, self.ubg = model.lbg, model.ubg
        self.shape_key = (tuple(self.names), tuple(self.channels), model.data_layout, repr(self.solver_options),
                          tuple((t.effect.name, t.run) for t in self.effects))
        self._take_or_assemble(new_symbols=True)
        # the fitted navigation per run (corrected velocities, where-regressors)
        self._nav = [None if V is None else ca.Function("nav", [x], [V]) for V in model.knot_syms]

    def _take_or_assemble(self, new_symbols: bool) -> None:
        """The graph built before on another run of this shape (:mod:`..model_cache`), else built here (over
        new symbols, or this model's own at another reference shift) and kept."""
        kept = model_cache.find(self.shape_key, self)
        if kept is not None:
            self._take_built(kept)
            return
        if new_symbols:
            self._z = z = ca.MX.sym("z", len(self.names))
            n_rows, n_data = self.model.raw.shape[0], self.data.size
            self._p = ca.MX.sym("p", n_rows + n_data + len(self.names))  # the weights, the recorded numbers, the scales
            self._w, self._d = self._p[:n_rows], self._p[n_rows:n_rows + n_data]
            self._x_of_z = self._calibrated_constants(z, self._p[n_rows + n_data:])
            self._groups = {}  # (first, end) part -> residuals and Jacobian of parts a model at another reference shift shares
        self._assemble()
        model_cache.keep(self.shape_key, self)

    # what another model of this graph takes (:mod:`..model_cache`): symbols, graph, Functions and the solver
    # whose derivatives a new solver shares; never the runs or their numbers
    GRAPH_PARTS = ("_z", "_x_of_z", "_p", "_w", "_d", "_groups", "residual_fun", "jacobian_fun", "raw_fun",
                   "constraint_fun", "weighted_fun", "nlp", "solver")

    def graph_parts(self) -> dict:
        return {name: getattr(self, name) for name in self.GRAPH_PARTS}

    def graph_signature(self) -> tuple:
        return self.scale.size, self.data.size, self.constant.tobytes()

    def probe_points(self) -> list:
        """This model's residuals and constraints from its own graph at random unknowns (pins at theirs) on
        its recorded numbers (:func:`..model_cache.probe`)."""
        sm = self.model
        return model_cache.probe(ca.Function("check", [sm.x, sm.data_sym], [sm.raw, sm.g]),
                                 lambda z: np.where(self.constant, self.lbx, z * self.scale), self.data,
                                 self.lbx / self.scale, self.ubx / self.scale, self.parameters_at)

    def same_graph(self, parts: dict, points: list) -> bool:
        """Whether a kept graph's ``parts`` compute this model's residuals and constraints at its
        :meth:`probe_points`."""
        return model_cache.agree_at(points, lambda z, p: [parts["raw_fun"](z, p), parts["constraint_fun"](z)])

    def _take_built(self, kept: "model_cache.Built") -> None:
        """The symbols, graph and Jacobian of a model of the same graph (:mod:`..model_cache`), and a solver of
        its own that shares that model's derivatives (one solver is never called from two threads at once)."""
        for name, value in kept.parts.items():
            if name != "solver":
                setattr(self, name, value)
        self.solver = build_solver(self.nlp, self.solver_options, "diagnosis", residuals=self.jacobian_fun,
                                   residual_fun=self.weighted_fun, like=kept.parts["solver"])

    def _calibrated_constants(self, z: ca.MX, scale: ca.MX) -> ca.MX:
        """x(z): scale * z (the scales a parameter: they follow the run's data, the graph does not), with the
        calibration's pinned quantities and the held effect unknowns as constants. Their columns of the
        residual Jacobian are then structurally zero (they are never free), so its colouring needs a
        direction per free shared unknown only: a 2995-ping transect's candidate Jacobian took 13 forward
        directions through the bottom-track rows, 9 of them for pins."""
        pinned = self.constant
        free = np.flatnonzero(~pinned)
        S = ca.DM(ca.Sparsity.triplet(len(self.names), len(self.names), free.tolist(), free.tolist()), 1.0)
        return ca.mtimes(S, scale * z) + ca.DM(np.where(pinned, self.lbx, 0.0))

    def _assemble(self):
        """The NLP over z, its residual Functions and solver. The residuals are differentiated in groups
        of channels: the reference rows of each run, and the stretches between them, whose
        expressions and Jacobians are kept for this model at another reference shift."""
        model, z, w = self.model, self._z, self._w
        sizes = [int(p.shape[0]) for p in model.raw_parts]
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        reference = {model.reference_part(k) + j for k, r in enumerate(model.runs) if r.moving_reference for j in range(3)}
        raw, jac = [], []
        for shifts, group in itertools.groupby(range(len(sizes)), key=reference.__contains__):
            group = list(group)  # a run's reference channels, or a stretch between them
            a, b = group[0], group[-1] + 1
            if shifts or (a, b) not in self._groups:
                parts = model.put_in(model.raw_parts[a:b], self._x_of_z, self._d)
                r = ca.vertcat(*parts)
                entry = (r, ca.jacobian(w[int(offsets[a]):int(offsets[b])] * r, z))
                if not shifts:
                    self._groups[(a, b)] = entry
            else:
                entry = self._groups[(a, b)]
            raw.append(entry[0])
            jac.append(entry[1])
        raw_z, J_z = ca.vertcat(*raw), ca.vertcat(*jac)
        e_z, p = w * raw_z, self._p
        self.residual_fun = ca.Function("residuals", [z, p], [e_z, raw_z, J_z])
        self.jacobian_fun = ca.Function("residual_jacobian", [z, p], [J_z])
        self.raw_fun = ca.Function("raw_residuals", [z, p], [raw_z])
        g_z = model.put_in([model.g], self._x_of_z)[0]
        self.constraint_fun = ca.Function("constraints", [z], [g_z])
        self.nlp = {"x": z, "p": p, "f": 0.5 * ca.sumsqr(e_z), "g": g_z}
        self.weighted_fun = ca.Function("weighted_residuals", [z, p], [e_z])
        self.solver = build_solver(self.nlp, self.solver_options, "diagnosis", residuals=self.jacobian_fun,
                                   residual_fun=self.weighted_fun)

    def at_reference_shift(self, shift_s: float) -> "GapModel":
        """This model with every run's reference rows taken at t - ``shift_s`` (a reference delay's
        current estimate): those rows and the solver built again, the rest of the NLP shared."""
        with _BUILD_LOCK:
            other = copy.copy(self)
            other.base = self.base.at_delays(reference_shift_s=shift_s)
            other.model = self.model.at_reference_shift(other.base.runs)
            other.data = other.model.data_values
            if other.data.shape != self.data.shape:
                raise ValueError("at_reference_shift: the shifted reference rows changed the recorded parameters' layout")
            other.shape_key = self.shape_key + (("reference_shift_s", float(shift_s)),)
            other._take_or_assemble(new_symbols=False)
        return other

    # ------------------------------------------------------------------ names and numbers
    @property
    def sampled(self) -> bool:
        return self.base.sampled

    @property
    def n_runs(self) -> int:
        return len(self.base.runs)

    def channel_name(self, c) -> str:
        return c.name if len(self.base.runs) == 1 else f"{self.base.runs[c.run].case.name}/{c.name}"

    def channel_slices(self) -> dict:
        return channel_slices(self.channels)

    def group_index_of(self, group: str) -> np.ndarray:
        """Rows of one channel group over every run."""
        keys = [i for i, k in enumerate(self.sigma_keys) if k[1] == group]
        return np.isin(self.row_sigma, keys)

    def weights(self, sigma: dict) -> np.ndarray:
        return self.mask / np.array([sigma[k] for k in self.sigma_keys])[self.row_sigma]

    def parameters(self, sigma: dict) -> np.ndarray:
        """The NLP's parameters: the rows' weights at the noise levels ``sigma``, the recorded numbers, the
        unknowns' scales."""
        return self.parameters_at(self.weights(sigma))

    def parameters_at(self, weights: np.ndarray) -> np.ndarray:
        return np.concatenate([weights, self.data, self.scale])

    def residuals_at(self, z, weights: np.ndarray) -> tuple:
        """(weighted residuals, raw residuals, Jacobian of the weighted ones) at the scaled unknowns ``z``
        (x / scale) with the rows' ``weights``, as CasADi gives them."""
        return self.residual_fun(z, self.parameters_at(weights))

    def weighted_residuals(self, z, sigma: dict) -> np.ndarray:
        """The weighted residuals at the scaled unknowns ``z`` (x / scale), the noise levels ``sigma``."""
        return np.asarray(self.weighted_fun(z, self.parameters(sigma))).ravel()  # not their Jacobian

    def start(self, values: dict, overrides: dict | None = None) -> np.ndarray:
        """Unknowns by name from ``values`` (a previous fit's), each effect at its initial values,
        then ``overrides``."""
        x = np.array([values.get(n, 0.0) for n in self.names], dtype=float)
        for i0, (term, _) in enumerate(self.model.effect_terms):
            idx = self.model.unknowns.index(f"effect{i0}")
            if idx.size and not any(self.names[i] in values for i in idx):
                x[idx] = term.effect.initial(self.model.contexts[term.run or 0])
        for name, value in (overrides or {}).items():
            x[self.names.index(name)] = value
        return np.clip(x, self.lbx, self.ubx)

    def solve(self, x0s, sigma: dict, fixed: dict | None = None) -> Fit:
        """IPOPT from each start; ``fixed`` pins named unknowns at values (oracle refits)."""
        x0s = np.atleast_2d(np.array(x0s, dtype=float))
        lbz, ubz = self.lbx / self.scale, self.ubx / self.scale
        for name, value in (fixed or {}).items():
            i = self.names.index(name)
            if self.constant[i] and not np.isclose(value, self.lbx[i], rtol=1e-12, atol=1e-12):
                raise ValueError(f"fixed: {name} is held at {self.lbx[i]:.6g} in this model's graph, got {value:.6g}")
            lbz[i] = ubz[i] = value / self.scale[i]
            x0s[:, i] = value
        p = self.parameters(sigma)
        ms = multistart(self.solver, np.clip(x0s / self.scale, lbz, ubz), lbz, ubz, self.lbg, self.ubg, p, progress=False)
        e, raw, J = self.residual_fun(ms.x, p)
        e, raw, J = np.asarray(e), np.asarray(raw), sparse_of(J)
        z = np.asarray(ms.x).ravel()
        tol = BOUND_TOL * np.maximum(np.abs(ubz - lbz), 1.0)
        free = (z - lbz > tol) & (ubz - z > tol)
        return Fit(effects=[t.effect.name for t in self.effects], x=ms.x * self.scale, names=list(self.names),
                   raw=raw.ravel() * self.mask, sigma=dict(sigma), objective=float(ms.objective), success=bool(ms.success),
                   status=ms.status, iterations=ms.iterations, jacobian=J, scale=self.scale.copy(), free=free)

    def sigma_from(self, raw: np.ndarray, n_params: int) -> dict:
        """Noise levels per (run, group) from residuals (degrees of freedom shared out)."""
        dof = max(1.0 - n_params / max(float(self.mask.sum()), 1.0), 0.1)
        out = {}
        for i, key in enumerate(self.sigma_keys):
            m = (self.row_sigma == i) & (self.mask > 0)
            out[key] = float(max(np.sqrt(np.sum(raw[m] ** 2) / max(m.sum() * dof, 1)), 1e-6))
        return out

    # ------------------------------------------------------------------ velocities
    def nav_at(self, x, times, run: int = 0) -> np.ndarray:
        """The fitted velocity over ground of G of one run at ``times``."""
        rs = self.base.runs[run]
        if self._nav[run] is None:
            return np.zeros((np.size(times), 3))
        V = np.asarray(self._nav[run](np.asarray(x)))
        return np.column_stack([np.interp(times, rs.knots, V[:, j]) for j in range(3)])

    def corrected_velocity(self, fit: Fit, run: int = 0) -> np.ndarray:
        """Per-ping velocity over ground of G: the fitted navigation plus the least-squares velocity
        change that explains each ping's measured radials (three or four valid beams)."""
        rs = self.base.runs[run]
        t = rs.case.pings.time_s
        v = self.nav_at(fit.x, t, run)
        sl = self.channel_slices()
        prefix = "" if self.n_runs == 1 else f"{rs.case.name}/"
        miss = -np.column_stack([fit.raw[sl[f"{prefix}bt_beam{i + 1}"]] for i in range(4)])
        ok = np.isfinite(rs.case.pings.bt_radial_m_s)
        D = np.where(ok[:, :, None], self._dradial_dv(fit, run), 0.0)  # a missing beam: a zero row, no say
        v += np.einsum("nib,nb->ni", np.linalg.pinv(D), np.where(ok, miss, 0.0))  # each ping's least squares at once
        v[ok.sum(axis=1) < 3] = np.nan
        return v

    def _beam_directions(self, fit: Fit, run: int) -> np.ndarray:
        """(N, 4, 3) Earth beam directions at the ping times from the fitted attitude."""
        from ...models.motion import AttitudeParams, evaluate_attitude
        from ...models.rotations import euler_matrix

        rs = self.base.runs[run]
        t = rs.case.pings.time_s
        if rs.attitude_source == "samples":
            Lam = evaluate_attitude(rs.samples, t)["Lambda"]
        else:
            idx = self.model.unknowns.index(f"attitude{run}")
            p = AttitudeParams.unpack(fit.x[idx], rs.fit.params.layout) if idx.size else rs.fit.params
            Lam = evaluate_attitude(p, t)["Lambda"]
        ypr = [fit.x[self.names.index(n)] if n in self.names else 0.0
               for n in ("installation_yaw", "installation_pitch", "installation_roll")]
        if self.model.spec.installation == "fixed":
            ypr = self.model.spec.nominal_installation_ypr_rad
        Lst = np.asarray(euler_matrix(*ypr)) if not self.model.head_sensor else np.eye(3)
        return np.einsum("nij,jk,bk->nbi", Lam, Lst, self.model.beam_dirs_t)

    def _dradial_dv(self, fit: Fit, run: int) -> np.ndarray:
        """(N, 4, 3) d radial / d v of each ping: the bottom-track rows' Jacobian on the knots,
        taken through the interpolation weight of the ping's nearest knot."""
        rs = self.base.runs[run]
        if rs.knots is None:  # a stationary run: the beam directions (Eq. 52, first order)
            return self._beam_directions(fit, run)
        u = self.model.unknowns
        cols = u.index(f"velocity{run}").reshape(-1, 3)
        sl = self.channel_slices()
        prefix = "" if self.n_runs == 1 else f"{rs.case.name}/"
        w = self.weights(fit.sigma)
        H = hat_basis(rs.case.pings.time_s, rs.knots)
        denom = np.sum(H * H, axis=1)
        denom = np.where(denom > 0, denom, 1.0)
        out = np.zeros((rs.case.pings.n, 4, 3))
        for i in range(4):
            rows = np.arange(sl[f"{prefix}bt_beam{i + 1}"].start, sl[f"{prefix}bt_beam{i + 1}"].stop)
            Jb = sp.diags(1.0 / np.where(w[rows] != 0, w[rows], 1.0)) @ sp.csr_matrix(fit.jacobian)[rows]  # unweighted
            for a in range(3):
                dk = Jb[:, cols[:, a]] @ sp.diags(1.0 / self.scale[cols[:, a]])  # d radial / d V_knot
                out[:, i, a] = np.asarray(sp.csr_matrix(dk).multiply(H).sum(axis=1)).ravel() / denom
        return out


def sparse_of(M: ca.DM) -> sp.csr_matrix:
    """A CasADi matrix as a scipy sparse one, its structural zeros kept out."""
    rows, cols = M.shape
    colind, row = M.sparsity().get_ccs()
    return sp.csc_matrix((np.asarray(M.nonzeros(), dtype=float), row, colind), shape=(rows, cols)).tocsr()


def residual_peaks(model: GapModel, fit: Fit) -> dict:
    """Lomb-Scargle peaks of the base's residuals that seed the frequency of oscillating effects."""
    sl = model.channel_slices()
    run = model.base.runs[0]
    t_ping = run.case.pings.time_s
    duration = t_ping[-1] - t_ping[0]
    lo, hi = max(4 * np.pi / duration, 0.2), 12.0
    out = {}
    prefix = "" if model.n_runs == 1 else f"{run.case.name}/"
    if f"{prefix}pitch" in sl:  # attitude residuals exist only when the motion model is fitted
        tilt = np.column_stack([fit.raw[sl[f"{prefix}pitch"]], fit.raw[sl[f"{prefix}roll"]]])
        out["tilt"] = periodogram_peak(run.case.attitude.time_s, tilt, lo, hi)
    bt = np.column_stack([fit.raw[sl[f"{prefix}bt_beam{i + 1}"]] for i in range(4)])
    out["bt_vertical"] = periodogram_peak(t_ping, bt.mean(axis=1), lo, hi)
    if all(r.knots is None for r in model.base.runs):  # a run held still, where a surge is a candidate
        # the beams' opposite pairs' differences: horizontal velocity, down to half a cycle over the record
        horizontal = np.column_stack([bt[:, 0] - bt[:, 1], bt[:, 2] - bt[:, 3]])
        out["bt_horizontal"] = periodogram_peak(t_ping, horizontal, np.pi / duration, hi)
    return out


