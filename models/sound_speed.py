"""Speed of sound in water from temperature, salinity and depth.

TRDI's instruments compute the sound speed they convert Doppler shifts and travel times with
from their transducer's temperature, a salinity setting (ES) and the depth (Medwin 1975, the
formula of their manuals; every TRDI file in ../shared/data/real records a sound speed this
formula gives from its own temperature and salinity to the file's 1 m/s). A salinity entered
wrong (0 ppt in sea water, 35 ppt in a river) makes every radial velocity and range off by
c_instrument / c_true: about 3 % at 35 ppt. Written with arithmetic only, so numpy arrays and
CasADi symbols both go through.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

VALID_TEMPERATURE_C = (-2.0, 40.0)  # where the inversion for a temperature searches


def sound_speed_m_s(temperature_c, salinity_psu, depth_m=0.0):
    """Medwin (1975): c = 1449.2 + 4.6 T - 0.055 T^2 + 0.00029 T^3 + (1.34 - 0.01 T)(S - 35) + 0.016 D,
    T in deg C, S in ppt (PSU), D in m; within 0.2 m/s of the UNESCO equation for 0-35 deg C,
    0-45 ppt, 0-1000 m."""
    T = temperature_c
    return (1449.2 + 4.6 * T - 0.055 * T ** 2 + 0.00029 * T ** 3 + salinity_slope(T) * (salinity_psu - 35.0)
            + 0.016 * depth_m)


def salinity_slope(temperature_c):
    """dc/dS of :func:`sound_speed_m_s`, (m/s)/ppt: 1.34 - 0.01 T (the formula is linear in S)."""
    return 1.34 - 0.01 * temperature_c


def salinity_for_sound_speed(c_m_s, temperature_c, depth_m=0.0):
    """The salinity (ppt) at which :func:`sound_speed_m_s` gives ``c_m_s`` at this temperature and depth."""
    return 35.0 + (c_m_s - sound_speed_m_s(temperature_c, 35.0, depth_m)) / salinity_slope(temperature_c)


def temperature_for_sound_speed(c_m_s: float, salinity_psu: float, depth_m: float = 0.0) -> float | None:
    """The temperature (deg C) at which :func:`sound_speed_m_s` gives ``c_m_s`` at this salinity and
    depth (c rises with T over :data:`VALID_TEMPERATURE_C`); None outside that range."""
    lo, hi = VALID_TEMPERATURE_C
    f = lambda T: sound_speed_m_s(T, salinity_psu, depth_m) - c_m_s
    if not np.isfinite(c_m_s) or f(lo) * f(hi) > 0:
        return None
    return float(brentq(f, lo, hi, xtol=1e-9))
