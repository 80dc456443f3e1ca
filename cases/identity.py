"""Who measured, where and when: an instrument's identity, and the site and time span of runs.

A calibration belongs to one instrument on one installation: lever arms, installation angles
and compass corrections of another head are wrong for this one, silently. These records let
CALIB.json say whose it is and every reader refuse another instrument's.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import asdict, dataclass

import numpy as np

from .case import format_utc, parse_utc

FREQUENCY_TOLERANCE = 0.05  # relative: 1200 vs 1228.8 kHz is one head's nominal vs carrier figure; models differ by > 15 %
BEAM_ANGLE_TOLERANCE_DEG = 0.5
SITE_SPAN_KM = 50.0  # farther apart than a survey reaches: another site
DATE_SPAN_DAYS = 365.0  # a calibration older than this is of another season, maybe another installation


@dataclass(frozen=True)
class InstrumentIdentity:
    """The instrument a run was measured with (``""`` where the file does not say)."""

    make: str
    model: str
    serial_number: str
    frequency_hz: float
    beam_angle_deg: float
    n_beams: int
    sensor_frame: str  # where the attitude sensor sits: "vessel" or "transducer"

    def label(self) -> str:
        name = " ".join(x for x in (self.make, self.model) if x) or "instrument"
        serial = f" SN {self.serial_number}" if self.serial_number else ""
        return f"{name}{serial} ({self.frequency_hz / 1e3:g} kHz, {self.beam_angle_deg:.1f} deg, {self.n_beams} beams)"

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "InstrumentIdentity":
        return cls(make=str(d.get("make") or ""), model=str(d.get("model") or ""),
                   serial_number=str(d.get("serial_number") or ""), frequency_hz=float(d["frequency_hz"]),
                   beam_angle_deg=float(d["beam_angle_deg"]), n_beams=int(d.get("n_beams", 4)),
                   sensor_frame=str(d.get("sensor_frame") or ""))


def identity_of(case) -> InstrumentIdentity:
    ins = case.instrument
    return InstrumentIdentity(make=ins.make, model=ins.model, serial_number=ins.serial_number,
                              frequency_hz=float(ins.frequency_hz), beam_angle_deg=math.degrees(ins.beam_angle_rad),
                              n_beams=int(ins.n_beams), sensor_frame=str(case.attitude.frame))


def instrument_difference(a: InstrumentIdentity, b: InstrumentIdentity) -> str | None:
    """How two identities show two instruments (a serial number, make or model both name and
    differ; else the frequency, the beam angle or the beam count), or None when they may be one."""
    for key in ("make", "serial_number", "model"):
        x, y = getattr(a, key), getattr(b, key)
        if x and y and x.strip().lower() != y.strip().lower():
            return f"{key.replace('_', ' ')} {x} vs {y}"
    if abs(a.frequency_hz - b.frequency_hz) > FREQUENCY_TOLERANCE * max(a.frequency_hz, b.frequency_hz):
        return f"frequency {a.frequency_hz / 1e3:g} vs {b.frequency_hz / 1e3:g} kHz"
    if abs(a.beam_angle_deg - b.beam_angle_deg) > BEAM_ANGLE_TOLERANCE_DEG:
        return f"beam angle {a.beam_angle_deg:.1f} vs {b.beam_angle_deg:.1f} deg"
    if a.n_beams != b.n_beams:
        return f"{a.n_beams} vs {b.n_beams} beams"
    return None


@dataclass(frozen=True)
class Site:
    """Where and when runs were measured: the mean GNSS position (None without positions) and the
    UTC span (None without a UTC origin)."""

    latitude_deg: float | None
    longitude_deg: float | None
    start_utc: str | None
    end_utc: str | None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Site":
        return cls(*(d.get(k) for k in ("latitude_deg", "longitude_deg", "start_utc", "end_utc")))


def site_of(cases) -> Site:
    """The runs' mean position and their UTC span."""
    lat, lon, starts, ends = [], [], [], []
    for case in cases:
        p = case.position
        if p is not None and np.any(np.isfinite(p.latitude_deg)):
            lat.append(float(np.nanmean(p.latitude_deg)))
            lon.append(float(np.nanmean(p.longitude_deg)))
        if case.time_origin_utc:
            t0 = parse_utc(case.time_origin_utc)
            starts.append(t0 + _dt.timedelta(seconds=float(case.pings.time_s[0])))
            ends.append(t0 + _dt.timedelta(seconds=float(case.pings.time_s[-1])))
    return Site(float(np.mean(lat)) if lat else None, float(np.mean(lon)) if lon else None,
                format_utc(min(starts)) if starts else None, format_utc(max(ends)) if ends else None)


def distance_km(a: Site, b: Site) -> float | None:
    """Great-circle distance between two sites' mean positions (None when either has none)."""
    if None in (a.latitude_deg, a.longitude_deg, b.latitude_deg, b.longitude_deg):
        return None
    p1, p2 = math.radians(a.latitude_deg), math.radians(b.latitude_deg)
    dl = math.radians(b.longitude_deg - a.longitude_deg)
    c = math.sin(p1) * math.sin(p2) + math.cos(p1) * math.cos(p2) * math.cos(dl)
    return 6371.0 * math.acos(max(-1.0, min(1.0, c)))


def days_apart(a: Site, b: Site) -> float | None:
    """Days between two sites' spans (0 when they overlap; None when either has no dates)."""
    if None in (a.start_utc, a.end_utc, b.start_utc, b.end_utc):
        return None
    gap = max(parse_utc(b.start_utc) - parse_utc(a.end_utc), parse_utc(a.start_utc) - parse_utc(b.end_utc),
              _dt.timedelta(0))
    return gap.total_seconds() / 86400.0


def site_differences(a: Site, b: Site) -> list:
    """Warnings when two sites lie farther apart than a survey reaches, or their dates a year apart."""
    out = []
    d = distance_km(a, b)
    if d is not None and d > SITE_SPAN_KM:
        out.append(f"{d:.0f} km apart (beyond a survey's {SITE_SPAN_KM:g} km)")
    days = days_apart(a, b)
    if days is not None and days > DATE_SPAN_DAYS:
        out.append(f"{days:.0f} days apart")
    return out
