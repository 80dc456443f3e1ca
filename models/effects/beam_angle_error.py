"""True beam angle differs from nominal by the same error on every beam."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from .base import Effect, Parameter


class BeamAngleError(Effect):
    name = "beam_angle_error"
    description = "every beam tilted error_rad further from the instrument axis than nominal"
    parameters = (Parameter("error_rad", 0.01, -0.1, 0.1, draw=(np.deg2rad(0.6), np.deg2rad(1.5))),)

    def modify_scenario(self, scenario, params):
        ins = scenario.platform.instrument
        ins = dataclasses.replace(ins, beam_angle_rad=ins.beam_angle_rad + params["error_rad"])
        return dataclasses.replace(scenario, platform=dataclasses.replace(scenario.platform, instrument=ins))

    def record(self, case, params):
        ins = dataclasses.replace(case.instrument, beam_angle_rad=case.instrument.beam_angle_rad - params["error_rad"])
        return dataclasses.replace(case, instrument=ins)

    def beam_directions(self, beam_dirs_t, beam_angle_rad, th):
        b = np.asarray(beam_dirs_t, dtype=float)
        rows = []
        for d in b:
            h = np.hypot(d[0], d[1])
            a = np.arctan2(h, d[2]) + th[0]
            rows.append(ca.horzcat(d[0] / h * ca.sin(a), d[1] / h * ca.sin(a), ca.cos(a)))
        return ca.vertcat(*rows)
