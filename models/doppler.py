"""Doppler measurement models (Eqs. 49-52, 65-70, 84-88), instrument sign convention.

Radial velocities are positive when the target approaches the transducer, so a
transducer moving with V_T over a still bottom along outward beam d measures
V_T . d (the paper's V_BTRad is minus this). The medium (water) is taken at rest in
the Earth frame for the acoustic propagation, as in the paper. ``u`` below is the
transducer velocity component along the outward ray, ``w`` the scatterer's.

The instrument turns an echo frequency f into a radial velocity v with the two-way
formula f / f0 = (c + v) / (c - v) (Eqs. 65, 84) using its own sound speed c.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def ratio_from_radial(radial, sound_speed):
    """f / f0 = (c + v) / (c - v) (Eqs. 65, 84 in instrument sign)."""
    return (sound_speed + radial) / (sound_speed - radial)


def radial_from_ratio(ratio, sound_speed):
    """Inverse of :func:`ratio_from_radial`: v = c (f/f0 - 1) / (f/f0 + 1)."""
    return sound_speed * (ratio - 1) / (ratio + 1)


def bottom_echo_ratio(u_tx, u_rx, sound_speed):
    """Two-way Doppler ratio off a still bottom (Eq. 70): (c + u_rx) / (c - u_tx).

    u_tx = V_T(t_T) . d(t_T) (source moving toward the bottom at transmit),
    u_rx = V_T(t_R) . e_rx (receiver moving toward the echo at receive).
    """
    return (sound_speed + u_rx) / (sound_speed - u_tx)


def water_echo_ratio(u_tx, u_rx, w_tx, w_rx, sound_speed):
    """Two-way Doppler ratio off scatterers moving with the water (Eq. 88).

    (c - w_tx) / (c - u_tx) * (c + u_rx) / (c + w_rx), with w_tx = V_n . d(t_T) and
    w_rx = V_n . e_rx the water velocity along the outgoing and returning rays.
    """
    return (sound_speed - w_tx) / (sound_speed - u_tx) * (sound_speed + u_rx) / (sound_speed + w_rx)


def shallow_bt_radial(transducer_velocity, beam_dirs):
    """Shallow-water bottom-track radial velocity V_Ti . d_i per beam (Eqs. 49, 52).

    Row arrays (..., 3) of velocities and beam vectors; CasADi (4, 3) gives (4, 1).
    """
    if isinstance(transducer_velocity, (ca.SX, ca.MX, ca.DM)):
        return ca.sum2(transducer_velocity * beam_dirs)
    return np.sum(np.asarray(transducer_velocity) * np.asarray(beam_dirs), axis=-1)


def slant_range(target_depth, transducer_depth, beam_dir_down):
    """Range along the beam from a transducer to a horizontal layer (Eqs. 67, 86).

    l = (H - H_T) / (d . z), depths positive down from the surface.
    """
    return (target_depth - transducer_depth) / beam_dir_down


def reported_range(slant_range_m, radial_velocity, sound_speed):
    """The range an instrument reports, c (t_R - t_T) / 2 = l (1 - u / c) to first order in u/c: the
    echo returns to where the transducer has moved along the beam (u: the transducer's velocity
    along the outward beam, the radial velocity in instrument sign)."""
    return slant_range_m * (1 - radial_velocity / sound_speed)


def receive_time_paper(transmit_time, slant_range_m, sound_speed):
    """t_R = t_T + 2 l / c (Eqs. 68, 87): the transducer assumed still during the flight."""
    return transmit_time + 2 * slant_range_m / sound_speed
