"""The shallow model (instantaneous round trip, Eq. 52) used where transmit/receive timing
matters: the refit switches to the two-way model with receive times (Eqs. 65-70).

No extra unknowns; injected by running the scenario in deep water (the simulator's
physics is always two-way with exact travel times)."""

from __future__ import annotations

import dataclasses

from .base import Effect


class DeepWaterTiming(Effect):
    name = "deep_water_timing"
    description = "two-way timing: beams turn and transducers move between transmit and receive"
    parameters = ()
    timing = "deep"
    needs_rotation = True

    def draw(self, rng):
        return {"water_depth_m": float(rng.uniform(90.0, 200.0))}

    def modify_scenario(self, scenario, params):
        return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, water_depth_m=params["water_depth_m"]))
