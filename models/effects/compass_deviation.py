"""Heading error of a magnetic compass: A + B sin psi + C cos psi (one-cycle deviation)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import Effect, Parameter

DEG = np.deg2rad(1.0)


class CompassDeviation(Effect):
    name = "compass_deviation"
    description = "heading reads psi + A + B sin psi + C cos psi"
    parameters = (
        Parameter("A_rad", 0.02, -0.5, 0.5, draw=(1.0 * DEG, 4.0 * DEG)),
        Parameter("B_rad", 0.02, -0.5, 0.5, draw=(1.5 * DEG, 4.0 * DEG)),
        Parameter("C_rad", 0.02, -0.5, 0.5, draw=(1.5 * DEG, 4.0 * DEG)),
    )
    needs_reference = True
    nests = ("compass_offset",)  # B = C = 0

    def wrap_attitude_sensor(self, read, params):
        def deviated(t):
            ypr = read(t).copy()
            psi = ypr[:, 0]
            ypr[:, 0] = psi + params["A_rad"] + params["B_rad"] * np.sin(psi) + params["C_rad"] * np.cos(psi)
            return ypr
        return deviated

    def heading_correction(self, psi, params):
        psi = np.asarray(psi, dtype=float)
        return -(params["A_rad"] + params["B_rad"] * np.sin(psi) + params["C_rad"] * np.cos(psi))

    def heading_reading(self, psi, th):
        return psi + th[0] + th[1] * ca.sin(psi) + th[2] * ca.cos(psi)

    def sampled_heading_correction(self, psi, th):
        return -(th[0] + th[1] * ca.sin(psi) + th[2] * ca.cos(psi))  # first order in the deviation
