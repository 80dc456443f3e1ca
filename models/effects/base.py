"""What every effect of the catalog provides: simulator injection and model extension.

An effect is one physical cause of disagreement between the base model and a run.
It is *injected* by the simulator (numeric hooks on the exact physics, never the
estimator's shortcut) and *added* to the estimation model as extra unknowns
(symbolic hooks on CasADi expressions). Every hook defaults to "no change", so an
effect module overrides only the hooks it touches; adding an effect is adding a
module and listing it in :mod:`adcpdyn.models.effects`.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np


@dataclass(frozen=True)
class Parameter:
    """One unknown of an effect: name with unit, scale, bounds, and the self-test's draw range."""

    name: str
    scale: float
    lower: float
    upper: float
    draw: tuple = (0.0, 0.0)  # |value| drawn uniformly in this range, random sign when signed
    signed: bool = True


class Effect:
    """Base class: no-op hooks. Subclasses set ``name``, ``description``, ``parameters``."""

    name: str = ""
    description: str = ""
    parameters: tuple = ()
    timing: str | None = None  # "deep" when the effect is the two-way timing itself
    needs_reference: bool = False  # observable only with a moving reference velocity
    needs_rotation: bool = False
    nests: tuple = ()  # effects this one contains as a special case (its extra unknowns at zero)

    # ------------------------------------------------------------ parameters
    def _overrides(self, *hooks) -> bool:
        return any(getattr(type(self), h) is not getattr(Effect, h) for h in hooks)

    @property
    def acts_on_attitude_model(self) -> bool:
        """Whether the effect reshapes the fitted motion model (its time base, tilt, heading
        reading or modes)."""
        return self._overrides("attitude_time", "tilt_attitude_params", "heading_reading", "extra_mode")

    @property
    def acts_on_samples(self) -> bool:
        """Whether the effect can be undone on the sensor's samples (when the beams use them)."""
        return self._overrides("sampled_time", "sampled_tilt", "sampled_heading_correction")

    @property
    def needs_motion_model(self) -> bool:
        """Whether the effect only exists on a motion model (an extra mode: samples hold it already)."""
        return self.acts_on_attitude_model and not self.acts_on_samples

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def draw(self, rng: np.random.Generator) -> dict:
        """Random realistic magnitudes for the blind self-test."""
        out = {}
        for p in self.parameters:
            v = rng.uniform(*p.draw)
            out[p.name] = float(v * rng.choice([-1.0, 1.0]) if p.signed else v)
        return out

    def vector(self, params: dict) -> np.ndarray:
        missing = [n for n in self.names if n not in params]
        if missing:
            raise ValueError(f"effect {self.name}: missing parameter(s) {missing}; expected {self.names}")
        return np.array([float(params[n]) for n in self.names])

    def initial(self, ctx) -> np.ndarray:
        """Start of the refit (warm start from the base fit: the effect switched off)."""
        return np.zeros(len(self.parameters))

    def extra_starts(self) -> list[dict]:
        """Further starts ({"effect.param": value}) where the refit has more than one basin."""
        return []

    def truth_values(self, params: dict) -> dict | None:
        """The model's unknowns for injected ``params`` ({"effect.param": value}), or None
        when the simulator's parameters are not the model's (then no oracle refit exists)."""
        if set(params) != set(self.names):
            return None
        return {f"{self.name}.{n}": float(params[n]) for n in self.names}

    # ------------------------------------------------------------ simulation (numeric)
    def modify_scenario(self, scenario, params: dict):
        """The scenario whose exact physics contains the effect."""
        return scenario

    def vessel_velocity_offset(self, t, heading, params: dict):
        """Extra Earth velocity of G at times t (n,) with heading trend (n,) -> (n, 3)."""
        return None

    def g_position_offset(self, t, params: dict):
        """Extra position of G (n, 3) (only its depth matters over a flat bottom)."""
        return None

    def bottom_velocity(self, params: dict):
        """Velocity of the bottom under bottom tracking, (3,)."""
        return None

    def bottom_velocity_at(self, t, position_ne_m, params: dict):
        """Velocity of the bottom under each ping (n, 3), at transmit times t (n,) with G at
        ``position_ne_m`` (n, 2: north, east in the run's site plane); default: the constant
        :meth:`bottom_velocity`."""
        v = self.bottom_velocity(params)
        return None if v is None else np.broadcast_to(np.asarray(v, dtype=float), (np.size(t), 3))

    def heading_correction(self, psi, params: dict):
        """True minus read heading for true sensor headings psi (n,), or None when the
        effect leaves the heading reading alone (true heading = read heading + this)."""
        return None

    def wrap_attitude_sensor(self, read, params: dict):
        """``read(times) -> (n, 3) ypr`` of the sensor, wrapped by the effect."""
        return read

    def record(self, case, params: dict):
        """What the instrument writes when it differs from the physics (nominal values)."""
        return case

    # ------------------------------------------------------------ estimation (symbolic)
    # Each hook receives CasADi expressions and the effect's parameter vector th.
    def attitude_time(self, t, th):
        return t

    def tilt_attitude_params(self, p_att, layout, th):
        return p_att

    def heading_reading(self, psi, th):
        return psi

    def beam_directions(self, beam_dirs_t, beam_angle_rad, th):
        return beam_dirs_t

    def installation(self, ypr_st, th):
        return ypr_st

    def radial_scale(self, th):
        return 1.0

    def range_scale(self, th):
        """The slant ranges' factor against a depth known otherwise (a run whose depth is derived from
        its ranges takes none: the depth scales with them)."""
        return 1.0

    def vessel_velocity(self, v, ctx, th):
        """v (N, 3) navigation velocity at the ping times -> v."""
        return v

    def reference_velocity(self, v, ctx, th):
        """v (L, 3) navigation velocity at the reference times -> v."""
        return v

    def g_depth(self, g_depth, ctx, th):
        """G's depth per ping (1, N) -> (1, N)."""
        return g_depth

    def bottom_velocity_model(self, th):
        return None

    def reference_point(self, p_ref, th):
        return p_ref

    def extra_mode(self, th):
        """(omega, decay, roll (C, S), pitch (C, S)) of an extra oscillation, or None."""
        return None

    # ------------------------------------------------------------ on the sensor's samples (symbolic)
    # When the beams' attitude is the sensor's samples (interpolated linearly: angle and slope of
    # the segment about each row), an effect of the sensor is undone on them.
    def sampled_time(self, t, th):
        """The time whose reading holds the true attitude at t."""
        return t

    def sampled_tilt(self, tilt, tilt_rate, th, lead: float = 0.0):
        """True pitch and roll (2,) from the read ones and their rates (``lead``: a low-pass
        inversion already applied to the samples' rows, see :class:`SampledAttitude.params_at`)."""
        return tilt

    def sampled_heading_correction(self, psi, th):
        """Added to the read heading psi to give the true heading."""
        return 0


class MisreadsHeading(Effect):
    """An effect on the compass alone: the simulator's sensor reads :meth:`heading_reading` (the
    model's one equation, evaluated on numbers), and the true-minus-read heading follows from it."""

    def heading_read(self, psi, params: dict) -> np.ndarray:
        """The heading read for true headings psi (n,)."""
        psi = np.asarray(psi, dtype=float)
        return np.asarray(self.heading_reading(ca.DM(psi), ca.DM(self.vector(params)))).reshape(psi.shape)

    def wrap_attitude_sensor(self, read, params: dict):
        def misread(t):
            ypr = read(t).copy()
            ypr[:, 0] = self.heading_read(ypr[:, 0], params)
            return ypr
        return misread

    def heading_correction(self, psi, params: dict):
        psi = np.asarray(psi, dtype=float)
        return psi - self.heading_read(psi, params)

    def sampled_heading_correction(self, psi, th):
        return psi - self.heading_reading(psi, th)  # the error at the read heading: first order in it
