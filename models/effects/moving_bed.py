"""The bottom moves under bottom tracking (bed load): BT measures the transducer velocity
relative to the moving bed, the reference does not.

The bed moves at (velocity_north_m_s, velocity_east_m_s) everywhere (``profile`` absent
or "uniform"), or, with ``profile = "parabolic"``, at that velocity times 4 s (1 - s),
s the fraction of the way from bank A (bank_a_north_m, bank_a_east_m) to bank B
(bank_b_...) of G's position at the ping (zero at the banks, largest mid-channel,
zero outside the section). The model's unknown is the constant velocity.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .base import Effect, Parameter

PROFILES = ("uniform", "parabolic")
SECTION_KEYS = ("bank_a_north_m", "bank_a_east_m", "bank_b_north_m", "bank_b_east_m")


def section_fraction(position_ne_m, bank_a_ne_m, bank_b_ne_m) -> np.ndarray:
    """s = (x - a) . (b - a) / |b - a|^2 of horizontal positions x (n, 2): 0 at bank A, 1 at bank B."""
    a, b = np.asarray(bank_a_ne_m, dtype=float), np.asarray(bank_b_ne_m, dtype=float)
    ab = b - a
    return (np.asarray(position_ne_m, dtype=float)[:, :2] - a) @ ab / (ab @ ab)


class MovingBed(Effect):
    name = "moving_bed"
    description = "the bottom moves horizontally at velocity_north/east_m_s"
    parameters = (
        Parameter("velocity_north_m_s", 0.02, -3.0, 3.0),
        Parameter("velocity_east_m_s", 0.02, -3.0, 3.0),
    )
    needs_reference = True

    def draw(self, rng):
        speed, direction = rng.uniform(0.06, 0.25), rng.uniform(0, 2 * np.pi)
        return {"velocity_north_m_s": float(speed * np.cos(direction)), "velocity_east_m_s": float(speed * np.sin(direction))}

    def bottom_velocity(self, params):
        return np.array([params["velocity_north_m_s"], params["velocity_east_m_s"], 0.0])

    def bottom_velocity_at(self, t, position_ne_m, params):
        profile = params.get("profile", "uniform")
        if profile not in PROFILES:
            raise ValueError(f"moving_bed.profile: expected one of {list(PROFILES)}, got {profile!r}")
        v = self.bottom_velocity(params)
        if profile == "uniform":
            return np.broadcast_to(v, (np.size(t), 3))
        missing = [k for k in SECTION_KEYS if k not in params]
        if missing:
            raise ValueError(f"moving_bed: profile {profile!r} needs the section's banks, missing {missing}")
        s = section_fraction(position_ne_m, (params["bank_a_north_m"], params["bank_a_east_m"]),
                             (params["bank_b_north_m"], params["bank_b_east_m"]))
        weight = np.where((s >= 0) & (s <= 1), 4 * s * (1 - s), 0.0)
        return weight[:, None] * v

    def bottom_velocity_model(self, th):
        return ca.vertcat(th[0], th[1], 0)
