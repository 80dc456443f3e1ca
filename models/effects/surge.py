"""The navigation speed varies within the run: speed along the heading s(t).

Injected as a sinusoidal speed change; modelled as a cubic B-spline speed with
``N_COEFFICIENTS`` coefficients spanning the run (about 3.2 s between knots on a
two-minute run; a surge the base's constant speed cannot follow).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.interpolate import BSpline

from .base import Effect, Parameter

N_COEFFICIENTS = 40


class Surge(Effect):
    name = "surge"
    description = "speed along the heading varying within the run"
    parameters = tuple(Parameter(f"speed_spline{k}_m_s", 0.05, -5.0, 5.0) for k in range(N_COEFFICIENTS))

    def draw(self, rng):
        return {"amplitude_m_s": float(rng.uniform(0.12, 0.3)), "period_s": float(rng.uniform(15.0, 40.0)),
                "phase_rad": float(rng.uniform(0, 2 * np.pi))}

    def vessel_velocity_offset(self, t, heading, params):
        s = params["amplitude_m_s"] * np.sin(2 * np.pi * np.asarray(t) / params["period_s"] + params["phase_rad"])
        return np.column_stack([s * np.cos(heading), s * np.sin(heading), np.zeros_like(s)])

    @staticmethod
    def _basis(times, ctx):
        k = 3
        inner = np.linspace(ctx.t0_s, ctx.t1_s, N_COEFFICIENTS - k + 1)
        knots = np.concatenate([[ctx.t0_s] * k, inner, [ctx.t1_s] * k])
        x = np.clip(np.asarray(times, dtype=float), ctx.t0_s, ctx.t1_s)
        return ca.DM(BSpline.design_matrix(x, knots, k).toarray())

    def vessel_velocity(self, v, ctx, th):
        s = ca.mtimes(self._basis(ctx.ping_time_s, ctx), th)
        return v + ca.repmat(s, 1, 3) * ctx.heading_dir_ping

    def reference_velocity(self, v, ctx, th):
        s = ca.mtimes(self._basis(ctx.reference_time_s, ctx), th)
        return v + ca.repmat(s, 1, 3) * ctx.heading_dir_reference
