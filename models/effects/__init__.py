"""Catalog of unmodelled effects (issue: sim-to-real gap diagnosis).

Each module holds one effect: how the simulator injects it and which unknowns it
adds to the estimation model (:class:`.base.Effect`). ``CATALOG`` lists them by name.
"""

from __future__ import annotations

from .attitude_latency import AttitudeLatency
from .base import Effect, Parameter
from .beam_angle_error import BeamAngleError
from .compass_deviation import CompassDeviation
from .compass_offset import CompassOffset
from .deep_water_timing import DeepWaterTiming
from .forced_roll import ForcedRoll
from .heave import Heave
from .installation_misalignment import InstallationMisalignment
from .moving_bed import MovingBed
from .reference_latency import ReferenceLatency
from .reference_lever_arm import ReferenceLeverArm
from .sound_speed_error import SoundSpeedError
from .surge import Surge
from .tilt_lowpass import TiltLowpass

CATALOG: dict[str, Effect] = {e.name: e for e in (
    AttitudeLatency(), SoundSpeedError(), BeamAngleError(), Heave(), Surge(), ForcedRoll(), CompassOffset(), CompassDeviation(),
    TiltLowpass(), MovingBed(), ReferenceLeverArm(), ReferenceLatency(), InstallationMisalignment(), DeepWaterTiming(),
)}


def get_effect(name: str) -> Effect:
    if name not in CATALOG:
        raise ValueError(f"effect: unknown name {name!r}; expected one of {sorted(CATALOG)}")
    return CATALOG[name]


def effect_of(unknown: str) -> str:
    """The catalog effect an effect unknown belongs to (``run2/moving_bed.velocity_north_m_s`` -> ``moving_bed``)."""
    return unknown.split("/")[-1].split(".")[0]


__all__ = ["CATALOG", "Effect", "Parameter", "effect_of", "get_effect"]
