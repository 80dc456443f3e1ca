"""The reference velocity (GNSS antenna) is measured away from where the file says."""

from __future__ import annotations

import dataclasses

import numpy as np

from .base import Effect, Parameter


class ReferenceLeverArm(Effect):
    name = "reference_lever_arm"
    description = "reference point offset (x, y, z)_m from the recorded point_body_m"
    parameters = tuple(Parameter(f"{a}_m", 0.2, -30.0, 30.0, draw=(0.8, 2.0)) for a in "xyz")
    needs_reference = True
    needs_rotation = True

    def modify_scenario(self, scenario, params):
        m = scenario.platform.mounting
        p = np.asarray(m.reference_point_body_m, dtype=float) + self.vector(params)
        mounting = dataclasses.replace(m, reference_point_body_m=tuple(p))
        return dataclasses.replace(scenario, platform=dataclasses.replace(scenario.platform, mounting=mounting))

    def record(self, case, params):
        if case.reference is None:
            return case
        ref = dataclasses.replace(case.reference, point_body_m=case.reference.point_body_m - self.vector(params))
        return dataclasses.replace(case, reference=ref)

    def reference_point(self, p_ref, th):
        return p_ref + th
