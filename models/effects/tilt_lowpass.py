"""The inclinometer low-pass filters pitch and roll: first order, time constant tau.

Simulated by filtering the exact angles on a fine grid; modelled exactly for the
damped-mode attitude model, whose modes pass a first-order filter as the same modes
with the complex gain 1 / (1 + tau s), s = -decay + i omega (bias and trend: gain 1).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.signal import lfilter, lfilter_zi

from .base import Effect, Parameter

GRID_STEP_S = 0.005


class TiltLowpass(Effect):
    name = "tilt_lowpass"
    description = "pitch and roll read through a first-order low-pass of time constant tau_s"
    parameters = (Parameter("tau_s", 0.05, 0.0, 5.0, draw=(0.12, 0.4), signed=False),)
    needs_rotation = True

    def wrap_attitude_sensor(self, read, params):
        tau = params["tau_s"]

        def filtered(t):
            t = np.asarray(t, dtype=float)
            grid = np.arange(t.min() - 10 * tau, t.max() + GRID_STEP_S, GRID_STEP_S)
            raw = read(grid)
            a = 1 - np.exp(-GRID_STEP_S / tau)
            out = read(t).copy()
            for j in (1, 2):
                x = raw[:, j]
                y, _ = lfilter([a], [1, a - 1], x, zi=lfilter_zi([a], [1, a - 1]) * x[0])
                out[:, j] = np.interp(t, grid, y)
            return out
        return filtered

    def initial(self, ctx):
        return np.array([0.05])

    def tilt_attitude_params(self, p_att, layout, th):
        s = layout.slices()
        tau = th[0]
        parts = [p_att[i] for i in range(layout.size)]
        for axis in ("roll", "pitch"):
            base = s[f"{axis}_cs"].start
            for k in range(layout.n_modes):
                w, v = p_att[s["modes"].start + 2 * k], p_att[s["modes"].start + 2 * k + 1]
                c, sn = p_att[base + 2 * k], p_att[base + 2 * k + 1]
                a, b = 1 - tau * v, tau * w
                den = a**2 + b**2
                parts[base + 2 * k] = (c * a - sn * b) / den
                parts[base + 2 * k + 1] = (c * b + sn * a) / den
        return ca.vertcat(*parts)

    def sampled_tilt(self, tilt, tilt_rate, th, lead: float = 0.0):
        # inverse of tau dy/dt + y = x; the rows' samples hold it for tau = lead already (with the
        # rate's own correction tau y'', which this first-order step lacks: a fixed point in the diagnosis)
        return tilt + (th[0] - lead) * tilt_rate

    def extra_starts(self):
        return [{"tilt_lowpass.tau_s": 0.3}]
