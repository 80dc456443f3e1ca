"""The bottom moves under bottom tracking (bed load): BT measures the transducer velocity
relative to the moving bed, the reference does not."""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import Effect, Parameter


class MovingBed(Effect):
    name = "moving_bed"
    description = "the bottom moves horizontally at velocity_north/east_m_s"
    parameters = (
        Parameter("velocity_north_m_s", 0.02, -3.0, 3.0),
        Parameter("velocity_east_m_s", 0.02, -3.0, 3.0),
    )
    needs_reference = True

    def draw(self, rng):
        speed, direction = rng.uniform(0.06, 0.25), rng.uniform(0, 2 * np.pi)
        return {"velocity_north_m_s": float(speed * np.cos(direction)), "velocity_east_m_s": float(speed * np.sin(direction))}

    def bottom_velocity(self, params):
        return np.array([params["velocity_north_m_s"], params["velocity_east_m_s"], 0.0])

    def bottom_velocity_model(self, th):
        return ca.vertcat(th[0], th[1], 0)
