"""Attitude time stamps late (or early) by a constant delay: the sensor's sample stamped t
holds the attitude of t - delay_s."""

from __future__ import annotations

from .base import Effect, Parameter


class AttitudeLatency(Effect):
    name = "attitude_latency"
    description = "attitude samples stamped late (delay_s > 0) or early by a constant delay"
    parameters = (Parameter("delay_s", 0.1, -2.0, 2.0, draw=(0.12, 0.4)),)
    needs_rotation = True

    def wrap_attitude_sensor(self, read, params):
        delay = params["delay_s"]
        return lambda t: read(t - delay)

    def attitude_time(self, t, th):
        return t - th[0]

    def sampled_time(self, t, th):
        return t + th[0]

    def extra_starts(self):
        return [{"attitude_latency.delay_s": 0.25}, {"attitude_latency.delay_s": -0.25}]
