"""Heading error of a magnetic compass: A + B sin psi + C cos psi (one-cycle deviation); its
constant A any angle (as :mod:`.compass_offset`), the one-cycle terms a deviation's size."""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import MisreadsHeading, Parameter

DEG = np.deg2rad(1.0)


class CompassDeviation(MisreadsHeading):
    name = "compass_deviation"
    description = "heading reads psi + A + B sin psi + C cos psi"
    parameters = (
        Parameter("A_rad", 0.02, -np.pi, np.pi, draw=(1.0 * DEG, 4.0 * DEG)),
        Parameter("B_rad", 0.02, -0.5, 0.5, draw=(1.5 * DEG, 4.0 * DEG)),
        Parameter("C_rad", 0.02, -0.5, 0.5, draw=(1.5 * DEG, 4.0 * DEG)),
    )
    needs_reference = True
    nests = ("compass_offset",)  # B = C = 0

    def heading_reading(self, psi, th):
        return psi + th[0] + th[1] * ca.sin(psi) + th[2] * ca.cos(psi)
