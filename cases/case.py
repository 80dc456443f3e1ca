"""In-memory form of a case file (``docs/case-format.md``, version 1).

One frozen dataclass per group of the file. Arrays are float64, SI units, NaN for
missing values. Optional groups are ``None`` when absent; optional datasets inside a
group are ``None`` when absent, so that writing a case back reproduces the file it
was read from.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import warnings
from dataclasses import dataclass, field

import numpy as np

FORMAT_NAME = "adcp-case"
FORMAT_VERSION = 1
ATTITUDE_FRAMES = ("vessel", "transducer")


@dataclass(frozen=True)
class Instrument:
    """``/instrument``: beam geometry and the instrument's own Doppler settings."""

    beam_angle_rad: float
    transducer_radius_m: float
    frequency_hz: float
    sound_speed_m_s: float
    n_beams: int = 4
    layout: str = "janus4"
    beam_dirs_t: np.ndarray | None = None  # (4, 3) override of the Janus beam vectors
    beam_pos_t: np.ndarray | None = None  # (4, 3) override of the transducer positions
    make: str = ""  # who built it ("TRDI", "Nortek"; a simulator names itself); "" when not known
    model: str = ""  # the maker's model name
    serial_number: str = ""
    temperature_c: float | None = None  # the transducer's water temperature (median) its sound speed was computed from
    salinity_psu: float | None = None  # the salinity setting its sound speed was computed with

    def beam_directions(self) -> np.ndarray:
        """Outward unit beam vectors in the transducer frame, (4, 3)."""
        if self.beam_dirs_t is not None:
            return np.asarray(self.beam_dirs_t, dtype=float)
        from ..models.janus import janus_beam_directions

        return np.asarray(janus_beam_directions(self.beam_angle_rad), dtype=float)

    def transducer_positions(self) -> np.ndarray:
        """Transducer centres in the transducer frame relative to P, (4, 3)."""
        if self.beam_pos_t is not None:
            return np.asarray(self.beam_pos_t, dtype=float)
        from ..models.janus import janus_transducer_positions

        return np.asarray(janus_transducer_positions(self.transducer_radius_m), dtype=float)


@dataclass(frozen=True)
class Environment:
    """``/environment``: flat bottom depth and the transducer depth when level (H_O)."""

    water_depth_m: float
    transducer_depth_m: float
    water_depth_per_ping_m: np.ndarray | None = None  # (N,), overrides the attribute

    def depth_at_pings(self, n_pings: int) -> np.ndarray:
        """Bottom depth below the surface at each ping, (N,); the attribute where the per-ping value is NaN (missing)."""
        if self.water_depth_per_ping_m is not None:
            d = np.asarray(self.water_depth_per_ping_m, dtype=float)
            return np.where(np.isnan(d), float(self.water_depth_m), d)
        return np.full(n_pings, float(self.water_depth_m))


def depth_from_vertical_ranges(time_s, vertical_m, transducer_depth_m: float) -> np.ndarray | None:
    """The per-ping water depth derived where none is recorded (the importers' rule): the transducer
    depth plus the mean of the beams' vertical ranges, interpolated in time where no beam has one;
    None without any range."""
    vertical_m = np.asarray(vertical_m, dtype=float)
    if not np.any(np.isfinite(vertical_m)):
        return None
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # pings without a range: NaN, interpolated below
        mean = np.nanmean(vertical_m, axis=1)
    ok = np.isfinite(mean)
    t = np.asarray(time_s, dtype=float)
    return float(transducer_depth_m) + np.interp(t, t[ok], mean[ok])


@dataclass(frozen=True)
class Vessel:
    """``/vessel``: optional hull figures for the empirical initial guesses."""

    length_m: float | None = None
    beam_m: float | None = None
    height_m: float | None = None
    mass_kg: float | None = None
    draft_m: float | None = None
    displaced_volume_m3: float | None = None


@dataclass(frozen=True)
class Pings:
    """``/pings``: transmit times and bottom-track radial velocities."""

    time_s: np.ndarray  # (N,)
    bt_radial_m_s: np.ndarray  # (N, 4), positive when the bottom approaches
    bt_range_m: np.ndarray | None = None  # (N, 4) slant ranges

    @property
    def n(self) -> int:
        return int(self.time_s.shape[0])


@dataclass(frozen=True)
class Water:
    """``/water``: profile of radial water velocities relative to the transducer."""

    cell_depth_m: np.ndarray  # (K,)
    radial_m_s: np.ndarray  # (N, 4, K)


@dataclass(frozen=True)
class Attitude:
    """``/attitude``: low-rate sensor samples; ``frame`` says whose angles they are."""

    time_s: np.ndarray  # (M,)
    heading_rad: np.ndarray  # (M,)
    pitch_rad: np.ndarray  # (M,)
    roll_rad: np.ndarray  # (M,)
    frame: str = "vessel"

    def ypr(self) -> np.ndarray:
        """(M, 3) yaw, pitch, roll with the heading unwrapped (over its finite samples; NaN stays NaN)."""
        heading = np.array(self.heading_rad, dtype=float)
        ok = np.isfinite(heading)
        heading[ok] = np.unwrap(heading[ok])
        return np.column_stack([heading, self.pitch_rad, self.roll_rad])

    def ypr_at(self, times) -> np.ndarray:
        """(n, 3) yaw, pitch, roll interpolated linearly to ``times`` over the complete samples,
        heading unwrapped; the nearest sample held outside the record."""
        ok = self.complete()
        ypr = self.ypr()[ok]
        t = np.asarray(self.time_s, dtype=float)[ok]
        return np.column_stack([np.interp(times, t, ypr[:, j]) for j in range(3)])

    def subset(self, rows) -> "Attitude":
        """The samples ``rows`` (a mask or indices)."""
        return dataclasses.replace(self, time_s=self.time_s[rows], heading_rad=self.heading_rad[rows],
                                   pitch_rad=self.pitch_rad[rows], roll_rad=self.roll_rad[rows])

    def complete(self) -> np.ndarray:
        """(M,) True where heading, pitch and roll are all finite (NaN: a missing sample)."""
        return np.isfinite(self.heading_rad) & np.isfinite(self.pitch_rad) & np.isfinite(self.roll_rad)


@dataclass(frozen=True)
class Reference:
    """``/reference``: independent velocity of a point of the vessel (GNSS, video)."""

    time_s: np.ndarray | None = None  # (L,)
    velocity_m_s: np.ndarray | None = None  # (L, 3) Earth frame
    point_body_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    stationary: bool = False
    # (L, 2) or None: the interval each velocity averages over, on the case clock (GNSS velocity from
    # differenced positions: the mean over [fix_k, fix_k+1]); None: instantaneous samples at time_s
    window_s: np.ndarray | None = None

    def shifted(self, delay_s: float) -> "Reference":
        """The samples (and their windows) stamped ``delay_s`` later."""
        return dataclasses.replace(self, time_s=self.time_s + delay_s,
                                   window_s=None if self.window_s is None else self.window_s + delay_s)

    def subset(self, rows) -> "Reference":
        """The samples ``rows`` (a mask or indices), with their windows."""
        return dataclasses.replace(self, time_s=self.time_s[rows], velocity_m_s=self.velocity_m_s[rows],
                                   window_s=None if self.window_s is None else self.window_s[rows])


@dataclass(frozen=True)
class Position:
    """``/position`` (optional): where the vessel was, on the case clock.

    GNSS fixes (WGS84 latitude and longitude in degrees, the universal convention of
    positions; float64 keeps about 1 mm) for what depends on the site, such as the
    magnetic declination. With ``Case.time_origin_utc`` the fixes have dates too.
    """

    time_s: np.ndarray  # (P,) on the case clock, strictly increasing
    latitude_deg: np.ndarray  # (P,) north positive
    longitude_deg: np.ndarray  # (P,) east positive, in [-180, 180]


def parse_utc(text: str) -> _dt.datetime:
    """An ISO 8601 time as an aware UTC datetime; no offset means UTC.

    Raises ValueError (with the text) when it is not ISO 8601.
    """
    if not isinstance(text, str):
        raise ValueError(f"expected an ISO 8601 string, got {text!r}")
    when = _dt.datetime.fromisoformat(text.strip())
    if when.tzinfo is None:
        return when.replace(tzinfo=_dt.timezone.utc)
    return when.astimezone(_dt.timezone.utc)


def format_utc(when: _dt.datetime) -> str:
    """``YYYY-MM-DDTHH:MM:SS.ffffffZ`` of a datetime (naive taken as UTC)."""
    if when.tzinfo is not None:
        when = when.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    return when.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


@dataclass(frozen=True)
class Truth:
    """``/truth``: what a simulator used; absent from real and withheld cases."""

    radius_vectors_m: np.ndarray  # (4, 3) body frame
    installation_ypr_rad: np.ndarray  # (3,)
    vessel_velocity_m_s: np.ndarray  # (N, 3)
    water_velocity_m_s: np.ndarray | None = None  # (N, K, 3)
    moving_bed_velocity_m_s: np.ndarray | None = None  # (N, 3) Earth velocity of the bed under each ping
    effects: list = field(default_factory=list)  # [{"name": ..., "params": {...}}]
    extra_attrs: dict = field(default_factory=dict)  # other attributes, JSON strings


@dataclass(frozen=True)
class Case:
    """One measurement run: what the instrument recorded, and truth when simulated."""

    name: str
    instrument: Instrument
    environment: Environment
    pings: Pings
    attitude: Attitude
    description: str = ""
    vessel: Vessel = field(default_factory=Vessel)
    water: Water | None = None
    reference: Reference | None = None
    truth: Truth | None = None
    position: Position | None = None
    time_origin_utc: str | None = None  # ISO 8601 UTC time of the case clock's zero (root attribute)

    def replace(self, **changes) -> "Case":
        """A copy with some fields replaced (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def depth_from_ranges(self, tol_m: float = 1e-3) -> bool:
        """Whether the per-ping water depth is the transducer depth plus the mean of the beams'
        vertical ranges (slant range x |beam z|), as an importer derives it where no other depth
        is recorded: then a uniform scale of the ranges (a wrong sound speed) scales the depth with
        them, and the ranges tell nothing of it. True when nine pings in ten with a range agree to
        ``tol_m``."""
        d, derived = self.environment.water_depth_per_ping_m, self.depth_of_ranges()
        if d is None or derived is None:
            return False
        seen = np.any(np.isfinite(self.pings.bt_range_m), axis=1) & np.isfinite(d)
        return bool(seen.any() and np.mean(np.abs(np.asarray(d, dtype=float)[seen] - derived[seen]) <= tol_m) >= 0.9)

    def with_recorded_pings(self, pings: Pings) -> "Case":
        """A copy with ``pings`` as recorded; a water depth derived from the old ranges
        (:meth:`depth_from_ranges`) derived again from the new ones, as importing them would."""
        new = self.replace(pings=pings)
        if not self.depth_from_ranges():
            return new
        depth = new.depth_of_ranges()
        return new.replace(environment=dataclasses.replace(self.environment, water_depth_per_ping_m=depth,
                                                           water_depth_m=float(np.nanmedian(depth))))

    def ping_subset(self, rows) -> "Case":
        """The pings ``rows`` (indices or a mask) with every per-ping array (water profiles, per-ping
        depth, truth); attitude, reference and positions kept whole (their own clocks)."""
        rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, dtype=int)
        p, env, w, tr = self.pings, self.environment, self.water, self.truth
        take = lambda a: None if a is None else np.asarray(a)[rows]
        changes = {"pings": dataclasses.replace(p, time_s=p.time_s[rows], bt_radial_m_s=p.bt_radial_m_s[rows],
                                                bt_range_m=take(p.bt_range_m)),
                   "environment": dataclasses.replace(env, water_depth_per_ping_m=take(env.water_depth_per_ping_m))}
        if w is not None:
            changes["water"] = dataclasses.replace(w, radial_m_s=w.radial_m_s[rows])
        if tr is not None:
            changes["truth"] = dataclasses.replace(tr, vessel_velocity_m_s=tr.vessel_velocity_m_s[rows],
                                                   water_velocity_m_s=take(tr.water_velocity_m_s),
                                                   moving_bed_velocity_m_s=take(tr.moving_bed_velocity_m_s))
        return self.replace(**changes)

    def depth_of_ranges(self) -> np.ndarray | None:
        """The per-ping water depth the ranges give by the importers' rule (:func:`depth_from_vertical_ranges`,
        vertical range = slant range x |beam z|); None without ranges."""
        if self.pings.bt_range_m is None:
            return None
        cos_b = np.abs(self.instrument.beam_directions()[:, 2])
        return depth_from_vertical_ranges(self.pings.time_s, np.asarray(self.pings.bt_range_m, dtype=float) * cos_b[None, :],
                                          self.environment.transducer_depth_m)


def check_distinct_names(cases) -> None:
    """Raise one line unless the runs' names differ: a survey's runs, their results and channels are keyed by
    them (two windows of one file, each read back from its own file, keep the file's name)."""
    names = [c.name for c in cases]
    if len(set(names)) != len(names):
        raise ValueError(f"cases: expected distinct case names (a survey's runs are keyed by them), got {names}")
