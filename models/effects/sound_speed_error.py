"""True sound speed differs from the instrument's: every Doppler radial velocity and every
range is scaled by c_instrument / c_true (Eq. 65 with the wrong c)."""

from __future__ import annotations

import dataclasses

from .base import Effect, Parameter


class SoundSpeedError(Effect):
    name = "sound_speed_error"
    description = "true sound speed = instrument's x (1 + relative_error)"
    parameters = (Parameter("relative_error", 0.01, -0.2, 0.2, draw=(0.015, 0.04)),)

    def modify_scenario(self, scenario, params):
        c_inst = scenario.platform.instrument.sound_speed_m_s
        run = dataclasses.replace(scenario.run, true_sound_speed_m_s=c_inst * (1 + params["relative_error"]))
        return dataclasses.replace(scenario, run=run)

    def radial_scale(self, th):
        return 1 / (1 + th[0])

    def range_scale(self, th):
        return 1 / (1 + th[0])
