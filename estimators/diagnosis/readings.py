"""What a named effect's estimate means in the field's terms: a sound-speed error as the water's
sound speed and the salinity (or temperature) that gives it, beside the setting the instrument used;
a moving bed by its direction against the flow's."""

from __future__ import annotations

import numpy as np

from ...models.sound_speed import salinity_for_sound_speed, salinity_slope, temperature_for_sound_speed
from ..calibration.moving_bed_decision import bed_direction


def sound_speed_reading(c_instrument_m_s: float, relative_error: float, se: float, temperature_c: float | None,
                        salinity_psu: float | None, depth_m: float = 0.0) -> dict:
    """The water's sound speed c_instrument (1 + relative_error) +- c_instrument se, and where the
    instrument recorded the temperature and salinity setting its sound speed came from, the salinity
    (+- SE) that gives that speed at the recorded temperature and the temperature that gives it at the
    recorded salinity (:mod:`adcpdyn.models.sound_speed`); ``text`` says it in one clause."""
    c = c_instrument_m_s * (1.0 + relative_error)
    out = {"instrument_sound_speed_m_s": c_instrument_m_s, "sound_speed_m_s": c, "sound_speed_se_m_s": c_instrument_m_s * se,
           "recorded_temperature_c": temperature_c, "salinity_setting_psu": salinity_psu,
           "salinity_psu": None, "salinity_se_psu": None, "temperature_c": None}
    text = (f"the water's sound speed {c:.0f} +- {c_instrument_m_s * se:.0f} m/s against the instrument's "
            f"{c_instrument_m_s:.0f}")
    if temperature_c is not None and salinity_psu is not None:
        out["salinity_psu"] = float(salinity_for_sound_speed(c, temperature_c, depth_m))
        out["salinity_se_psu"] = c_instrument_m_s * se / salinity_slope(temperature_c)
        out["temperature_c"] = temperature_for_sound_speed(c, salinity_psu, depth_m)
        text += (f" (computed from {temperature_c:.1f} deg C and a salinity setting of {salinity_psu:g} ppt): "
                 f"a salinity of {out['salinity_psu']:.0f} +- {out['salinity_se_psu']:.0f} ppt at that temperature")
        if out["temperature_c"] is not None:
            text += f", or {out['temperature_c']:.1f} deg C at that salinity"
        text += "; if so, re-import with `--salinity-psu` set to the water's"
    else:
        text += " (the file records no temperature and salinity setting to read it as a salinity)"
    out["text"] = text
    return out


def bed_reading(velocity_m_s, se_m_s, flow: dict, base_bed_m_s=None) -> dict:
    """A named bed (north, east, m/s, with its SEs) against the runs' flow (:func:`...calibration.
    moving_bed_decision.mean_flow`), with the base's own bed under it where it has one: the bed's
    direction, its angle from the flow and whether it moves against it
    (:func:`...calibration.moving_bed_decision.bed_direction`); ``text`` says it in one clause. A bed
    moves with the near-bed flow, so one against it is a heading error on that course (QRev's loop
    test rejects a closure error that is not upstream)."""
    total = np.asarray(velocity_m_s, dtype=float) + (0.0 if base_bed_m_s is None else np.asarray(base_bed_m_s, dtype=float))
    out = bed_direction(total, se_m_s, flow)
    if out["from_flow_deg"] is None:
        return {**out, "text": "the bed has no direction (zero speed)"}
    under = " with the base's own bed under it" if base_bed_m_s is not None and np.any(base_bed_m_s) else ""
    off = abs(out["from_flow_deg"])
    text = (f"the bed{under} moves towards {out['direction_deg']:.0f} +- {out['direction_se_deg']:.0f} deg, {off:.0f} deg "
            f"from the flow's {out['flow_direction_deg']:.0f} deg")
    if out["against_flow"]:
        text += (": against the flow, which no bed does (QRev's loop test rejects a closure error that is not upstream), "
                 "so a heading error on this course, which turns the bottom track alike, is the likelier cause")
    else:
        text += (": with the flow, as a moving bed goes" if off <= 45 else
                 ": off the flow's direction, but too uncertain in it to rule a bed out")
    return {**out, "text": text}
