"""Reference time stamps late (or early) by a constant delay: the GNSS/ADCP clock offset and the
receiver's filtering lag, the timing error every field crew fights. The reference sample stamped
t holds the vessel's velocity of t - delay_s."""

from __future__ import annotations

import dataclasses

from .base import Effect, Parameter


class ReferenceLatency(Effect):
    name = "reference_latency"
    description = "reference (GNSS) velocity stamped late (delay_s > 0) or early by a constant delay"
    parameters = (Parameter("delay_s", 0.5, -5.0, 5.0, draw=(0.5, 2.0)),)
    needs_reference = True
    shifts_reference = True  # the model provides the reference point's velocity slope (navigation and rotation)

    def record(self, case, params):
        ref = case.reference
        if ref is None or ref.time_s is None or ref.stationary:
            return case
        return dataclasses.replace(case, reference=ref.shifted(params["delay_s"]))

    def reference_velocity(self, v, ctx, th):
        # the antenna's velocity at t - d, to first order about the current estimate d0 (the navigation,
        # the attitude and their slope taken at t - d0; the diagnosis iterates d0 to a fixed point, so
        # the expansion never reaches far)
        return v - (th[0] - ctx.reference_shift_s) * ctx.reference_slope

    def extra_starts(self):
        return [{"reference_latency.delay_s": 1.0}, {"reference_latency.delay_s": -1.0}]
