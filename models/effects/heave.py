"""The centre of rotation moves vertically: heave z(t) = C cos w t + S sin w t (down positive)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import Effect, Parameter


class Heave(Effect):
    name = "heave"
    description = "vertical oscillation of G: amplitude_m at omega_rad_s"
    parameters = (
        Parameter("omega_rad_s", 0.1, 0.2, 12.0, draw=(1.0, 1.6), signed=False),
        Parameter("cos_m", 0.05, -3.0, 3.0, draw=(0.05, 0.15)),
        Parameter("sin_m", 0.05, -3.0, 3.0, draw=(0.05, 0.15)),
    )

    def _numeric(self, t, params):
        """The model's heave (:meth:`_sym`, the one equation) evaluated on numbers: (z, dz/dt) at ``t``."""
        z, w = self._sym(np.asarray(t, dtype=float), ca.DM(self.vector(params)))
        return np.asarray(z).ravel(), np.asarray(w).ravel()

    def vessel_velocity_offset(self, t, heading, params):
        _, w = self._numeric(t, params)
        return np.column_stack([np.zeros_like(w), np.zeros_like(w), w])

    def g_position_offset(self, t, params):
        z, _ = self._numeric(t, params)
        return np.column_stack([np.zeros_like(z), np.zeros_like(z), z])

    def initial(self, ctx):
        return np.array([ctx.residual_peak("bt_vertical"), 0.0, 0.0])

    @staticmethod
    def _sym(t, th):
        """(z, dz/dt) as rows over the times ``t``: z = C cos w t + S sin w t (down positive)."""
        tau = ca.DM(t).T
        return (th[1] * ca.cos(th[0] * tau) + th[2] * ca.sin(th[0] * tau),
                th[0] * (-th[1] * ca.sin(th[0] * tau) + th[2] * ca.cos(th[0] * tau)))

    def vessel_velocity(self, v, ctx, th):
        _, w = self._sym(ctx.ping_time_s, th)
        return v + ca.horzcat(ca.MX.zeros(v.shape[0], 2), w.T)

    def reference_velocity(self, v, ctx, th):
        _, w = self._sym(ctx.reference_time_s, th)
        return v + ca.horzcat(ca.MX.zeros(v.shape[0], 2), w.T)

    def g_depth(self, g_depth, ctx, th):
        z, _ = self._sym(ctx.ping_time_s, th)
        return g_depth + z
