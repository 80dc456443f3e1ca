"""The vessel surges: a horizontal velocity oscillating at one frequency, C cos w t + S sin w t
along the heading and C' cos w t + S' sin w t across it (to starboard: the heading the beams' sensor
reads may sit off the bow by the installation, so the direction is the data's, not assumed).

Modelled only where the base has no navigation to follow it (a run held still, the pool: a
moored boat surging on a seiche or on its lines); on a run under way the base's velocity
through the reference or bottom track follows speed changes (``diagnosis.base.applicable``). The
frequency is seeded by the strongest peak of the base's horizontal bottom-track residuals.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import Effect, Parameter


class Surge(Effect):
    name = "surge"
    description = "horizontal velocity oscillating at omega_rad_s, along and across the heading"
    parameters = (
        Parameter("omega_rad_s", 0.05, 0.02, 3.0, signed=False),
        Parameter("cos_m_s", 0.05, -5.0, 5.0),
        Parameter("sin_m_s", 0.05, -5.0, 5.0),
        Parameter("across_cos_m_s", 0.05, -5.0, 5.0),
        Parameter("across_sin_m_s", 0.05, -5.0, 5.0),
    )

    def draw(self, rng):
        """A 0.12-0.3 m/s surge along the heading, period 15-40 s, random phase, in the model's parameters."""
        amplitude, period, phase = rng.uniform(0.12, 0.3), rng.uniform(15.0, 40.0), rng.uniform(0, 2 * np.pi)
        return {"omega_rad_s": float(2 * np.pi / period), "cos_m_s": float(amplitude * np.sin(phase)),
                "sin_m_s": float(amplitude * np.cos(phase)), "across_cos_m_s": 0.0, "across_sin_m_s": 0.0}

    def vessel_velocity_offset(self, t, heading, params):
        """The simulator's surge: the model's one equation (:meth:`_offset`) evaluated on numbers."""
        th = ca.DM([params["omega_rad_s"], params["cos_m_s"], params["sin_m_s"],
                    params.get("across_cos_m_s", 0.0), params.get("across_sin_m_s", 0.0)])
        heading = np.asarray(heading, dtype=float)
        heading_dir = ca.DM(np.column_stack([np.cos(heading), np.sin(heading), np.zeros_like(heading)]))
        return np.asarray(self._offset(np.asarray(t, dtype=float), heading_dir, th))

    def truth_values(self, params):
        """None: the simulator surges along the vessel's heading, the model's axes are the sensor's."""
        return None

    def extra_starts(self):
        """Slow surges (periods of 15-60 s: a boat on its lines, a seiche) whose residual peak a short
        record or a faster oscillation hides."""
        return [{"surge.omega_rad_s": w} for w in (0.1, 0.2, 0.4)]

    def initial(self, ctx):
        return np.array([ctx.residual_peak("bt_horizontal"), 0.0, 0.0, 0.0, 0.0])

    @staticmethod
    def _offset(t, heading_dir, th):
        tau = ca.DM(t)
        c, s = ca.cos(th[0] * tau), ca.sin(th[0] * tau)
        along, across = th[1] * c + th[2] * s, th[3] * c + th[4] * s
        starboard = ca.horzcat(-heading_dir[:, 1], heading_dir[:, 0], ca.DM.zeros(heading_dir.shape[0], 1))  # north, east, down
        return ca.repmat(along, 1, 3) * heading_dir + ca.repmat(across, 1, 3) * starboard

    def vessel_velocity(self, v, ctx, th):
        return v + self._offset(ctx.ping_time_s, ctx.heading_dir_ping, th)

    def reference_velocity(self, v, ctx, th):
        return v + self._offset(ctx.reference_time_s, ctx.heading_dir_reference, th)
