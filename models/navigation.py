"""Navigation of the centre of rotation G (Eqs. 10-12).

V_a(t) is either piecewise linear between knots (Earth frame) or a speed along the
heading trend plus a constant drift (curved tracks). G(t) is V_a integrated on a
fine grid; G's depth stays at its level value (no heave in the base model).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Navigation:
    """Velocity of G over a run.

    Parameters
    ----------
    knot_times_s, knot_velocities_m_s : sequences
        Piecewise-linear Earth-frame velocity of G, held constant outside the knots.
    speed_along_heading_m_s : float
        Added speed along the heading trend psi_trend(t) (0 for none).
    """

    knot_times_s: tuple = (0.0,)
    knot_velocities_m_s: tuple = ((0.0, 0.0, 0.0),)
    speed_along_heading_m_s: float = 0.0

    def __post_init__(self):
        t = np.asarray(self.knot_times_s, dtype=float)
        v = np.asarray(self.knot_velocities_m_s, dtype=float)
        if v.shape != (t.size, 3):
            raise ValueError(f"knot_velocities_m_s: expected shape ({t.size}, 3), got {v.shape}")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            raise ValueError("knot_times_s: expected strictly increasing times")

    def velocity(self, t, heading_trend=None) -> np.ndarray:
        """V_a at times t, (n, 3); heading_trend(t) is needed when speed_along_heading_m_s != 0."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        kt = np.asarray(self.knot_times_s, dtype=float)
        kv = np.asarray(self.knot_velocities_m_s, dtype=float)
        v = np.column_stack([np.interp(t, kt, kv[:, j]) for j in range(3)])
        if self.speed_along_heading_m_s:
            if heading_trend is None:
                raise ValueError("heading_trend: required when speed_along_heading_m_s is non-zero")
            psi = heading_trend(t)
            v = v + self.speed_along_heading_m_s * np.column_stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)])
        return v


@dataclass(frozen=True)
class Track:
    """Position and velocity of G sampled finely enough to interpolate exactly enough."""

    time_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray = field(repr=False)

    @classmethod
    def integrate(cls, nav: Navigation, t_start, t_end, g_depth_m, heading_trend=None, step_s=0.01):
        t = np.arange(t_start - 1.0, t_end + 2.0 + step_s, step_s)
        v = nav.velocity(t, heading_trend)
        pos = np.zeros_like(v)
        pos[1:] = np.cumsum((v[1:] + v[:-1]) / 2 * np.diff(t)[:, None], axis=0)
        pos[:, 2] = g_depth_m
        return cls(t, pos, v)

    def position(self, t) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        return np.stack([np.interp(t, self.time_s, self.position_m[:, j]) for j in range(3)], axis=-1)
