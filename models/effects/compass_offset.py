"""A constant compass error since the calibration: the heading reads psi + A on every heading
(a magnetic disturbance on board, a changed declination or a sensor turned on its mount), the
offset QRev flags above 1 deg. One course determines it when the calibration fixed the heading
misalignment; with the misalignment estimated in the base it is the base's. Any angle: a wrongly
entered heading alignment or declination puts it tens of degrees off, so its bounds are the circle's."""

from __future__ import annotations

import numpy as np

from .base import MisreadsHeading, Parameter

DEG = np.deg2rad(1.0)


class CompassOffset(MisreadsHeading):
    name = "compass_offset"
    description = "heading reads psi + A (a constant compass error since the calibration)"
    parameters = (Parameter("A_rad", 0.02, -np.pi, np.pi, draw=(2.0 * DEG, 5.0 * DEG)),)
    needs_reference = True

    def heading_reading(self, psi, th):
        return psi + th[0]
