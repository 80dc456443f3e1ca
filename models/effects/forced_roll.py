"""Wave-forced roll on top of the free decay: a steady (undamped) oscillation at the
wave encounter frequency, seen by the sensor's roll and pitch."""

from __future__ import annotations

import dataclasses

import numpy as np

from .base import Effect, Parameter


class ForcedRoll(Effect):
    name = "forced_roll"
    description = "steady wave-forced roll (no decay) at omega_rad_s"
    parameters = (
        Parameter("omega_rad_s", 0.1, 0.2, 16.0, draw=(0.9, 1.5), signed=False),
        Parameter("roll_cos_rad", 0.02, -1.0, 1.0, draw=(np.deg2rad(1.0), np.deg2rad(2.5))),
        Parameter("roll_sin_rad", 0.02, -1.0, 1.0, draw=(np.deg2rad(1.0), np.deg2rad(2.5))),
        Parameter("pitch_cos_rad", 0.02, -1.0, 1.0, draw=(0.0, 0.0)),
        Parameter("pitch_sin_rad", 0.02, -1.0, 1.0, draw=(0.0, 0.0)),
    )
    needs_rotation = False

    def modify_scenario(self, scenario, params):
        m = scenario.run.motion
        modes = np.vstack([m.modes, [params["omega_rad_s"], 0.0]])
        add = lambda cs, c, s: np.vstack([cs, [c, s]])
        motion = dataclasses.replace(
            m, modes=modes, roll_cs=add(m.roll_cs, params["roll_cos_rad"], params["roll_sin_rad"]),
            pitch_cs=add(m.pitch_cs, params["pitch_cos_rad"], params["pitch_sin_rad"]), yaw_cs=add(m.yaw_cs, 0.0, 0.0))
        return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, motion=motion))

    def initial(self, ctx):
        return np.array([ctx.residual_peak("tilt"), 0.0, 0.0, 0.0, 0.0])

    def extra_mode(self, th):
        return th[0], 0.0, (th[1], th[2]), (th[3], th[4])
