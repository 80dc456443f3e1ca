"""Non-zero installation angles (Lambda_tb) left out of the model."""

from __future__ import annotations

import dataclasses

import numpy as np

from .base import Effect, Parameter

DEG = np.deg2rad(1.0)


class InstallationMisalignment(Effect):
    name = "installation_misalignment"
    description = "installation yaw, pitch, roll of the head in the vessel"
    parameters = (
        Parameter("yaw_rad", 0.02, -0.6, 0.6, draw=(1.5 * DEG, 5.0 * DEG)),
        Parameter("pitch_rad", 0.02, -0.3, 0.3, draw=(0.5 * DEG, 2.0 * DEG)),
        Parameter("roll_rad", 0.02, -0.3, 0.3, draw=(0.5 * DEG, 2.0 * DEG)),
    )

    def modify_scenario(self, scenario, params):
        m = scenario.platform.mounting
        ypr = np.asarray(m.installation_ypr_rad, dtype=float) + self.vector(params)
        mounting = dataclasses.replace(m, installation_ypr_rad=tuple(ypr))
        return dataclasses.replace(scenario, platform=dataclasses.replace(scenario.platform, mounting=mounting))

    def installation(self, ypr_st, th):
        return ypr_st + th
