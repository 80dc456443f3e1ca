"""Empirical initial guesses of the roll and pitch models from hull figures (Eqs. 35-47).

These seed the attitude fits (the paper's Tables 1-3 "initial guess" rows).
Erratum: Eq. 39 prints the hull length L in the added roll inertia; with L the pool
boat's guessed roll frequency comes out 2.6 times too low, with the beam B it
matches the paper's own initial guess (6.3 rad/s). We use B and say so.
Metacentric heights are rarely known; defaults are box-hull estimates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

RHO_WATER = 1000.0
G_ACC = 9.81


@dataclass(frozen=True)
class HullCoefficients:
    """Empirical coefficients of Eqs. 38-47 (typical values as defaults)."""

    k1: float = 0.25  # Eq. 38, 0.2-0.3
    k2: float = 0.1  # Eq. 39, 0.1 short/broad, 0.2 slender, 0.15 flat-bottomed
    k3: float = 0.05  # Eq. 40, 0.03-0.08
    c_m: float = 0.1  # Eq. 46
    c_d: float = 0.1  # Eq. 47
    roll_metacentric_height_m: float | None = None  # h of Eq. 36; default 0.3 B
    pitch_metacentric_height_m: float | None = None  # H_theta of Eq. 44; default box hull


@dataclass(frozen=True)
class MotionGuess:
    """Natural, damped frequencies (rad/s) and decay rates (1/s) of roll and pitch."""

    roll_natural_rad_s: float
    roll_damped_rad_s: float
    roll_decay_1_s: float
    pitch_natural_rad_s: float
    pitch_damped_rad_s: float
    pitch_decay_1_s: float


def motion_guess(length_m, beam_m, height_m, mass_kg, draft_m=None, displaced_volume_m3=None,
                 coeffs: HullCoefficients = HullCoefficients()) -> MotionGuess:
    """Initial guesses of roll and pitch frequency and decay (Eqs. 35-47)."""
    for name, value in (("length_m", length_m), ("beam_m", beam_m), ("height_m", height_m), ("mass_kg", mass_kg)):
        if value is None or not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name}: expected a positive number, got {value!r}")
    L, B, H, m = float(length_m), float(beam_m), float(height_m), float(mass_kg)
    V = float(displaced_volume_m3) if displaced_volume_m3 else m / RHO_WATER
    T = float(draft_m) if draft_m else V / (L * B)
    D = m * G_ACC  # displacement (weight)
    h = coeffs.roll_metacentric_height_m or 0.3 * B
    h_theta = coeffs.pitch_metacentric_height_m or (T / 2 + L**2 / (12 * T) - H / 2)

    J_roll = coeffs.k1 * m * B**2  # Eq. 38
    dJ_roll = coeffs.k2 * RHO_WATER * V * B**2  # Eq. 39 (B, see module note)
    two_N_roll = coeffs.k3 * RHO_WATER * B * T**2 * np.sqrt(B)  # Eq. 40
    n_roll = np.sqrt(D * h / (J_roll + dJ_roll))  # Eq. 36
    v_roll = two_N_roll / (J_roll + dJ_roll) / 2  # Eq. 37

    J_pitch = m * (L**2 + H**2) / 12  # Eq. 45
    dJ_pitch = coeffs.c_m * RHO_WATER * V * L**2  # Eq. 46
    N_pitch = coeffs.c_d * RHO_WATER * V * B * L  # Eq. 47
    n_pitch = np.sqrt(D * h_theta / (J_pitch + dJ_pitch))  # Eq. 44
    v_pitch = N_pitch / (J_pitch + dJ_pitch)  # Eq. 43 with N of Eq. 47 as 2N / 2

    def damped(n, v):  # Eqs. 35, 42
        return float(np.sqrt(max(n**2 - v**2, 1e-12)))

    return MotionGuess(float(n_roll), damped(n_roll, v_roll), float(v_roll),
                       float(n_pitch), damped(n_pitch, v_pitch), float(v_pitch))
