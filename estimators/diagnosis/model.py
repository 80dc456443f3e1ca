"""The diagnosis model: the base model of a run plus any effects of the catalog, one NLP.

Base model (what the paper assumes, deliberately plain so effects show): the sensor's
attitude as freely decaying modes (decay >= ``MIN_FREE_DECAY_1_S``) with a yaw trend,
lever arms r_i = T_it + P (installation angles zero), the shallow bottom-track model
(Eq. 52), the instrument's sound speed and nominal beams, a still bottom, and the
vessel moving at a constant speed along the heading trend plus a constant drift.
When no motion model follows the sensor (real runs with turns, attitude sampled below the
motion: ``sampled=True``) the beams use the sensor's samples interpolated linearly instead
(:func:`adcpdyn.models.motion.local_attitude_function`), the attitude channels are data, not
residuals, and the navigation follows the measured heading.
Every effect adds its unknowns through the hooks of
:class:`adcpdyn.models.effects.base.Effect`. Residuals are kept unweighted per
channel; the objective weights them by per-group noise levels passed as parameters,
so noise can be re-estimated without rebuilding.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...cases.case import Case
from ...models.janus import beam_to_instrument
from ...models.measurement import bottom_track_function
from ...models.motion import (AttitudeLayout, AttitudeParams, SampledAttitude, attitude_function,
                              local_attitude_function)
from ...models.rotations import euler_matrix
from ...solvers.multistart import SolverOptions, build_solver, multistart
from ..attitude_fit import AttitudeFit, periodogram_peak
from ..calibration import channel_slices

MIN_FREE_DECAY_1_S = 0.01
GROUPS = ("heading", "pitch", "roll", "bt", "range", "reference")
AXES = ("north", "east", "down")


def group_of(channel: str) -> str:
    return channel.split("_")[0]


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
    jacobian: np.ndarray  # of the weighted residuals w.r.t. the scaled unknowns
    scale: np.ndarray
    bt_velocity_jacobian: np.ndarray | None = None  # (N, 4, 3) d radial / d v_a
    free: np.ndarray | None = None  # unknowns neither pinned nor held by an active bound

    def group_rss(self, model: "GapModel") -> dict:
        out = {}
        for g in model.groups_present:
            m = (model.group_index == GROUPS.index(g)) & (model.mask > 0)
            out[g] = (float(np.sum(self.raw[m] ** 2)), int(m.sum()))
        return out

    def log_likelihood(self, model: "GapModel") -> float:
        """Gaussian log-likelihood with each group's noise level profiled out."""
        ll = 0.0
        for rss, n in self.group_rss(model).values():
            if n:
                ll += -0.5 * n * (np.log(2 * np.pi * max(rss, 1e-300) / n) + 1)
        return ll

    def effect_values(self, model: "GapModel") -> dict:
        return {n: float(self.x[i]) for n, i in zip(model.effect_names, model.effect_index)}


class Context:
    """Numbers the effects' symbolic hooks need (times, heading directions, residual peaks)."""

    def __init__(self, case: Case, ping_time_s, reference_time_s, peaks: dict):
        self.case = case
        self.ping_time_s = ping_time_s
        self.reference_time_s = reference_time_s
        times = [ping_time_s] + ([reference_time_s] if reference_time_s is not None else [])
        self.t0_s = float(min(t[0] for t in times))
        self.t1_s = float(max(t[-1] for t in times))
        self.peaks = peaks
        self.heading_dir_ping = None
        self.heading_dir_reference = None

    def residual_peak(self, key: str) -> float:
        return float(self.peaks.get(key, 1.0))


def base_attitude(fit: AttitudeFit) -> AttitudeParams:
    """The pre-fit's modes as free decays (a steady oscillation is not a free decay)."""
    p = fit.params
    modes = p.modes.copy()
    if modes.size:
        modes[:, 1] = np.maximum(modes[:, 1], MIN_FREE_DECAY_1_S)
    return dataclasses.replace(p, modes=modes)


class GapModel:
    """Base model + effects as one NLP over scaled unknowns z = x / scale."""

    def __init__(self, case: Case, attitude: AttitudeParams, effects=(), peaks: dict | None = None,
                 solver: SolverOptions | None = None, sampled: bool = False):
        self.case, self.effects = case, list(effects)
        self.attitude0 = attitude
        self.sampled = sampled
        for e in self.effects:
            if sampled and e.acts_on_attitude_model:
                raise ValueError(f"effect {e.name}: acts on the motion model's attitude; the beams use the sensor's samples here")
        layout = attitude.layout
        pings, N = case.pings, case.pings.n
        ref = case.reference
        self.moving_reference = ref is not None and ref.time_s is not None and ref.velocity_m_s is not None
        self.stationary = ref is not None and ref.stationary
        self.head_sensor = case.attitude.frame == "transducer"
        ctx = Context(case, pings.time_s, ref.time_s if self.moving_reference else None, peaks or {})
        self.ctx = ctx
        timing = "deep" if any(e.timing == "deep" for e in self.effects) else "shallow"
        self.timing = timing

        names, scale, lo, hi = [], [], [], []

        def add(n, s, a, b):
            start = len(names)
            names.extend(n), scale.extend(s), lo.extend(a), hi.extend(b)
            return slice(start, len(names))

        # attitude block (frequencies near the pre-fit's, decays of free modes)
        s = layout.slices()
        att_scale, att_lo, att_hi = np.ones(layout.size), np.full(layout.size, -np.inf), np.full(layout.size, np.inf)
        for k, (w, _) in enumerate(attitude.modes):
            i = s["modes"].start + 2 * k
            att_scale[i], att_lo[i], att_hi[i] = 0.01 * w, 0.8 * w, 1.25 * w
            att_scale[i + 1], att_lo[i + 1], att_hi[i + 1] = 0.02, MIN_FREE_DECAY_1_S, 3.0
        for axis in ("roll", "pitch", "yaw"):
            cs = getattr(attitude, f"{axis}_cs")
            att_scale[s[f"{axis}_cs"]] = np.repeat(np.maximum(np.hypot(cs[:, 0], cs[:, 1]), 1e-3), 2)
        att_scale[s["roll_bias"]] = att_scale[s["pitch_bias"]] = 0.01
        att_scale[s["yaw_trend"]] = [1.0 if k == 0 else 0.01**k for k in range(layout.yaw_trend_order + 1)]
        p_att = add([] if sampled else layout.names(), *([[]] * 3 if sampled else [att_scale, att_lo, att_hi]))
        box = 0.5 * case.vessel.length_m if case.vessel.length_m else 10.0
        centre = add(["centre_x_m", "centre_y_m", "centre_z_m"], [0.5] * 3, [-box] * 3, [box] * 3)
        nav = None
        if not self.stationary:
            nav = add(["speed_forward_m_s", "speed_side_m_s", "drift_north_m_s", "drift_east_m_s"], [0.5] * 4, [-20.0] * 4, [20.0] * 4)
        self.n_base = len(names)
        self.effect_names, self.effect_index, th = [], [], []
        for e in self.effects:
            start = len(names)
            th.append(add([f"{e.name}.{p.name}" for p in e.parameters], [p.scale for p in e.parameters],
                          [p.lower for p in e.parameters], [p.upper for p in e.parameters]))
            self.effect_names += [f"{e.name}.{p.name}" for p in e.parameters]
            self.effect_index += list(range(start, len(names)))
        x = ca.MX.sym("x", len(names))
        p_att, centre = x[p_att], x[centre]
        nav = x[nav] if nav is not None else None
        th = [x[t] for t in th]
        self.names, self.scale = names, np.array(scale, dtype=float)
        self.lbx, self.ubx = np.array(lo, dtype=float), np.array(hi, dtype=float)

        # attitude model with an extra steady mode when an effect brings one
        p_full, lay_full = p_att, layout
        for e, t in zip(self.effects, th):
            extra = e.extra_mode(t)
            if extra is not None:
                p_full, lay_full = _append_mode(p_full, lay_full, *extra)
        att_fun = local_attitude_function() if sampled else attitude_function(lay_full)
        self.attitude_layout = lay_full
        a = case.attitude
        # per-row attitude data with the samples: their segment about each ping's / reference sample's time
        self.samples = SampledAttitude(a.time_s, a.ypr()) if sampled else None
        p_rows = (lambda times: ca.DM(self.samples.params_at(times))) if sampled else (lambda times: p_full)

        def hook(fn_name, value, *args):
            for e, t in zip(self.effects, th):
                value = getattr(e, fn_name)(value, *args, t) if args else getattr(e, fn_name)(value, t)
            return value

        trend = None if sampled else p_att[s["yaw_trend"]]

        def heading_dirs(times):
            if sampled:
                psi = ca.DM(self.samples.heading_at(times))
            else:
                tau = ca.DM(times - layout.t_ref_s)
                psi = sum(trend[k] * tau**k for k in range(layout.yaw_trend_order + 1))
            return ca.horzcat(ca.cos(psi), ca.sin(psi), ca.DM.zeros(len(times))), ca.horzcat(-ca.sin(psi), ca.cos(psi), ca.DM.zeros(len(times)))

        def nav_velocity(times):
            if nav is None:
                return ca.MX.zeros(len(times), 3)
            fwd, side = heading_dirs(times)
            drift = ca.repmat(ca.horzcat(nav[2], nav[3], 0), len(times), 1)
            return nav[0] * fwd + nav[1] * side + drift

        ctx.heading_dir_ping = heading_dirs(pings.time_s)[0]
        models, channels, times_of, self.groups = [], [], [], []

        # attitude samples (residuals of the motion model; data when the beams use the samples)
        masks = []
        if not sampled:
            M = a.time_s.size
            t_att = hook("attitude_time", ca.DM(a.time_s).T)
            ypr_model = att_fun.map(M)(t_att, p_full)[0]
            p_tilt = hook("tilt_attitude_params", p_full, lay_full)
            tilt_model = att_fun.map(M)(t_att, p_tilt)[0] if p_tilt is not p_full else ypr_model
            psi = hook("heading_reading", ca.transpose(ypr_model[0, :]))
            ypr_meas = a.ypr()
            dpsi = psi - ypr_meas[:, 0]
            models += [ca.atan2(ca.sin(dpsi), ca.cos(dpsi)), ca.transpose(tilt_model[1, :]) - ypr_meas[:, 1],
                       ca.transpose(tilt_model[2, :]) - ypr_meas[:, 2]]
            channels += [("heading", M), ("pitch", M), ("roll", M)]
            times_of += [a.time_s] * 3
            masks += [np.isfinite(ypr_meas[:, j]).astype(float) for j in range(3)]

        # bottom track and ranges
        beam_dirs_t = hook("beam_directions", ca.DM(case.instrument.beam_directions()), case.instrument.beam_angle_rad)
        ypr_st = hook("installation", ca.DM.zeros(3))
        Lst = euler_matrix(ypr_st[0], ypr_st[1], ypr_st[2])
        pos_t = case.instrument.transducer_positions()
        r = ca.mtimes(ca.DM(pos_t), Lst.T) + ca.repmat(centre.T, 4, 1)
        v_ping = hook("vessel_velocity", nav_velocity(pings.time_s), ctx)
        v_bed = [e.bottom_velocity_model(t) for e, t in zip(self.effects, th)]
        v_bed = [b for b in v_bed if b is not None]
        v_bt = v_ping - ca.repmat(sum(v_bed[1:], v_bed[0]).T, N, 1) if v_bed else v_ping
        self.v_bt_sym = v_bt
        depth = case.environment.depth_at_pings(N)
        g_depth = hook("g_depth", ca.DM.ones(1, N) * case.environment.transducer_depth_m - ca.sum1(r[:, 2]) / 4, ctx)
        bt_fun = bottom_track_function(att_fun, timing).map(N)
        v_in = ca.MX.sym("v_in", 3, N)
        radial, rng = bt_fun(ca.DM(pings.time_s).T, ca.DM(depth).T, g_depth, case.instrument.sound_speed_m_s,
                             v_in, p_rows(pings.time_s), r, ypr_st, beam_dirs_t)
        radial_scale = range_scale = 1.0
        for e, t in zip(self.effects, th):
            radial_scale, range_scale = radial_scale * e.radial_scale(t), range_scale * e.range_scale(t)
        radial_fn = ca.Function("radial_of_v", [v_in, x], [radial * radial_scale, rng])
        radial, rng = radial_fn(v_bt.T, x)
        # d radial / d v_a per ping: the per-ping velocity after correction uses it
        self._dradial_dv = ca.Function("dradial_dv", [v_in, x], [ca.jacobian(ca.vec(radial_fn(v_in, x)[0]), ca.vec(v_in))])
        self._v_bt = ca.Function("v_bt", [x], [v_bt.T])
        self.v_ground_fun = ca.Function("v_ground", [x], [v_ping])
        bt = case.pings.bt_radial_m_s
        for i in range(4):
            models.append(ca.transpose(radial[i, :]) - np.nan_to_num(bt[:, i]))
            channels.append((f"bt_beam{i + 1}", N))
            times_of.append(pings.time_s)
            masks.append(np.isfinite(bt[:, i]).astype(float))
        if pings.bt_range_m is not None:
            for i in range(4):
                models.append(ca.transpose(rng[i, :]) * range_scale - np.nan_to_num(pings.bt_range_m[:, i]))
                channels.append((f"range_beam{i + 1}", N))
                times_of.append(pings.time_s)
                masks.append(np.isfinite(pings.bt_range_m[:, i]).astype(float))
        # reference velocity of a body point
        if self.moving_reference:
            L = ref.time_s.size
            ctx.heading_dir_reference = heading_dirs(ref.time_s)[0]
            dLam = att_fun.map(L)(ca.DM(ref.time_s).T, p_rows(ref.time_s))[2]
            p_ref = hook("reference_point", ca.DM(np.asarray(ref.point_body_m, dtype=float)))
            v_ref = hook("reference_velocity", nav_velocity(ref.time_s), ctx)
            for j in range(3):
                tang = ca.mtimes(ca.reshape(dLam[j, :], 3, L).T, p_ref)
                models.append(v_ref[:, j] + tang - np.nan_to_num(ref.velocity_m_s[:, j]))
                channels.append((f"reference_{AXES[j]}", L))
                times_of.append(ref.time_s)
                masks.append(np.isfinite(ref.velocity_m_s[:, j]).astype(float))  # per axis: a NaN vertical masks only it
        self.channels = channels
        self.mask = np.concatenate(masks)
        self.times = np.concatenate(times_of)
        self.channel_index = np.concatenate([np.full(n, k) for k, (_, n) in enumerate(channels)])
        self.group_index = np.concatenate([np.full(n, GROUPS.index(group_of(c))) for c, n in channels])
        self.groups_present = [g for g in GROUPS if any(group_of(c) == g for c, _ in channels)]

        raw = ca.vertcat(*models)
        w = ca.MX.sym("w", raw.shape[0])
        z = ca.MX.sym("z", x.shape[0])
        raw_z = ca.substitute([raw], [x], [self.scale * z])[0]
        e_z = w * raw_z
        nlp = {"x": z, "p": w, "f": 0.5 * ca.sumsqr(e_z), "g": ca.MX(0, 1)}
        J_z = ca.jacobian(e_z, z)
        self.solver_options = solver or SolverOptions(tol=1e-8, max_iter=300, hessian="gauss-newton", expand=False)
        if self.solver_options.expand:  # SX evaluates faster but expanding costs seconds per model
            fun = ca.Function("gap_model", [z, w], [0.5 * ca.sumsqr(e_z), e_z, raw_z, J_z]).expand()
            z, w = ca.SX.sym("z", z.shape[0]), ca.SX.sym("w", w.shape[0])
            _, e_z, raw_z, J_z = fun(z, w)
        self.residual_fun = ca.Function("residuals", [z, w], [e_z, raw_z, J_z])
        self.jacobian_fun = ca.Function("residual_jacobian", [z, w], [J_z])
        self.nlp = {"x": z, "p": w, "f": 0.5 * ca.sumsqr(e_z), "g": ca.MX(0, 1) if isinstance(z, ca.MX) else ca.SX(0, 1)}
        self.solver = build_solver(self.nlp, self.solver_options, "diagnosis", residuals=self.jacobian_fun)

    # ------------------------------------------------------------------ numbers
    def weights(self, sigma: dict) -> np.ndarray:
        return self.mask / np.array([sigma[GROUPS[g]] for g in self.group_index])

    def x_base(self, attitude: AttitudeParams, centre, nav) -> np.ndarray:
        parts = [np.zeros(0) if self.sampled else attitude.pack(), np.asarray(centre, dtype=float)]
        if not self.stationary:
            parts.append(np.asarray(nav, dtype=float))
        return np.concatenate(parts)

    def start(self, x_base: np.ndarray, overrides: dict | None = None) -> np.ndarray:
        """Base estimates followed by each effect's initial values."""
        parts = [x_base[: self.n_base]] + [e.initial(self.ctx) for e in self.effects if e.parameters]
        x = np.concatenate(parts)
        for name, value in (overrides or {}).items():
            x[self.names.index(name)] = value
        return np.clip(x, self.lbx, self.ubx)

    def solve(self, x0s, sigma: dict, fixed: dict | None = None) -> Fit:
        """IPOPT from each start; ``fixed`` pins named unknowns at values (oracle refits)."""
        x0s = np.atleast_2d(x0s)
        lbz, ubz = self.lbx / self.scale, self.ubx / self.scale
        for name, value in (fixed or {}).items():
            i = self.names.index(name)
            lbz[i] = ubz[i] = value / self.scale[i]
            x0s[:, i] = value
        w = self.weights(sigma)
        ms = multistart(self.solver, np.clip(x0s / self.scale, lbz, ubz), lbz, ubz, [], [], w, progress=False)
        e, raw, J = (np.asarray(a) for a in self.residual_fun(ms.x, w))
        x = ms.x * self.scale
        z = np.asarray(ms.x).ravel()
        tol = 1e-5 * np.maximum(np.abs(ubz - lbz), 1.0)
        free = (z - lbz > tol) & (ubz - z > tol)
        return Fit(effects=[e_.name for e_ in self.effects], x=x, names=list(self.names), raw=raw.ravel() * self.mask,
                   sigma=dict(sigma), objective=float(ms.objective), success=bool(ms.success), status=ms.status,
                   iterations=ms.iterations, jacobian=J, scale=self.scale.copy(), free=free)

    def bt_velocity_jacobian(self, x) -> np.ndarray:
        """(N, 4, 3): d radial_i / d v_a per ping at the unknowns x (block diagonal, read sparsely)."""
        N = self.case.pings.n
        D = self._dradial_dv(self._v_bt(x), x).sparse().tocsr()  # (4N, 3N), column-major vec
        idx = np.arange(N)
        out = np.empty((N, 4, 3))
        for i in range(4):
            for j in range(3):
                out[:, i, j] = np.asarray(D[i + 4 * idx, j + 3 * idx]).ravel()
        return out

    def nav_at(self, x, times) -> np.ndarray:
        """The fitted velocity over ground of G, interpolated from the ping times to ``times``."""
        v = np.asarray(self.v_ground_fun(x))
        t = self.case.pings.time_s
        return np.column_stack([np.interp(times, t, v[:, j]) for j in range(3)])

    def corrected_velocity(self, fit: Fit) -> np.ndarray:
        """Per-ping velocity over ground of G: the fitted model plus the least-squares velocity
        change that explains each ping's measured radials (three or four valid beams)."""
        N = self.case.pings.n
        D = fit.bt_velocity_jacobian if fit.bt_velocity_jacobian is not None else self.bt_velocity_jacobian(fit.x)
        sl = self.channel_slices()
        miss = -np.column_stack([fit.raw[sl[f"bt_beam{i + 1}"]] for i in range(4)])
        ok = np.isfinite(self.case.pings.bt_radial_m_s)
        v = np.asarray(self.v_ground_fun(fit.x)).copy()
        for k in range(N):
            if ok[k].sum() >= 3:
                v[k] += np.linalg.lstsq(D[k][ok[k]], miss[k][ok[k]], rcond=None)[0]
            else:
                v[k] = np.nan
        return v

    def sigma_from(self, fit_raw: np.ndarray, n_params: int) -> dict:
        """Per-group noise levels from residuals (degrees of freedom shared out)."""
        out = {}
        n_total = float(self.mask.sum())
        dof = max(1.0 - n_params / max(n_total, 1.0), 0.1)
        for g in self.groups_present:
            m = (self.group_index == GROUPS.index(g)) & (self.mask > 0)
            out[g] = float(max(np.sqrt(np.sum(fit_raw[m] ** 2) / max(m.sum() * dof, 1)), 1e-6))
        return out

    def channel_slices(self) -> dict:
        return channel_slices(self.channels)


def _append_mode(p, layout: AttitudeLayout, omega, decay, roll_cs, pitch_cs):
    """Flat parameters of ``layout`` plus one mode (yaw not coupled) -> (p', layout')."""
    s = layout.slices()
    seg = lambda name: p[s[name]]
    p_new = ca.vertcat(seg("modes"), omega, decay, seg("roll_bias"), seg("roll_cs"), roll_cs[0], roll_cs[1],
                       seg("pitch_bias"), seg("pitch_cs"), pitch_cs[0], pitch_cs[1], seg("yaw_trend"), seg("yaw_cs"), 0, 0)
    return p_new, AttitudeLayout(layout.n_modes + 1, layout.yaw_trend_order, layout.t_ref_s)


def initial_noise(case: Case, fit: AttitudeFit) -> dict:
    """Independent noise levels to start from (attitude pre-fit, BT error velocity)."""
    B = case.instrument.beam_directions()
    _, e = beam_to_instrument(B)
    err = case.pings.bt_radial_m_s @ e
    err = err[np.isfinite(err)]
    bt = 1.4826 * np.median(np.abs(err - np.median(err))) / np.linalg.norm(e) if err.size > 5 else 0.01
    return {"heading": max(fit.sigmas[0], 1e-4), "pitch": max(fit.sigmas[1], 1e-4), "roll": max(fit.sigmas[2], 1e-4),
            "bt": max(float(bt), 1e-4), "range": 0.05, "reference": 0.05}


def residual_peaks(case: Case, fit_raw: np.ndarray, model: GapModel) -> dict:
    """Lomb-Scargle peaks of base residuals that seed the frequency of oscillating effects."""
    sl = model.channel_slices()
    t_att = case.attitude.time_s
    t_ping = case.pings.time_s
    duration = t_ping[-1] - t_ping[0]
    lo, hi = max(4 * np.pi / duration, 0.2), 12.0
    out = {}
    if "pitch" in sl:  # attitude residuals exist only when the motion model is fitted
        tilt = np.column_stack([fit_raw[sl["pitch"]], fit_raw[sl["roll"]]])
        out["tilt"] = periodogram_peak(t_att, tilt, lo, hi)
    bt = np.column_stack([fit_raw[sl[f"bt_beam{i + 1}"]] for i in range(4)])
    out["bt_vertical"] = periodogram_peak(t_ping, bt.mean(axis=1), lo, hi)
    return out
