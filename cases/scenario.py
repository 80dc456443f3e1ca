"""Scenario definitions: a platform (hull, instrument, mounting) plus a run.

Scenarios are data, kept as TOML in ``cases/scenarios/``: one file per platform with
its ``[platform]``, run ``[defaults]`` and named ``[runs.NAME]`` that override the
defaults, so runs of one platform share its hardware (the paper's Measurement 0 radius
vectors serve Measurements 1 and 2). Angles in the TOML carry their unit in the key
(``_deg`` or ``_rad``); everything in the dataclasses is SI with radians.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ..models.motion import AttitudeParams
from ..models.navigation import Navigation
from ..models.sensors import ATTITUDE_FRAMES
from .case import Vessel, parse_utc
from .survey_spec import nominal_transect
from .tables import angles_in_radians, build, deep_merge

TIMINGS = ("two_way", "instantaneous")
TRAVEL_TIMES = ("exact", "paper")
RECEIVE_DIRECTIONS = ("beam_axis", "echo_ray")


def _check_choice(owner, name, value, allowed):
    if value not in allowed:
        raise ValueError(f"{owner}.{name}: expected one of {list(allowed)}, got {value!r}")


@dataclass(frozen=True)
class InstrumentSpec:
    """Beam angle, transducer radius tr, carrier frequency f0 and the instrument's sound speed."""

    beam_angle_rad: float
    transducer_radius_m: float
    frequency_hz: float
    sound_speed_m_s: float = 1500.0


@dataclass(frozen=True)
class Mounting:
    """Where the head sits: installation angles (Lambda_tb), its centre P_b, sensor frame, reference point."""

    installation_ypr_rad: tuple
    centre_body_m: tuple
    attitude_frame: str = "vessel"
    reference_point_body_m: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        _check_choice("mounting", "attitude_frame", self.attitude_frame, ATTITUDE_FRAMES)


@dataclass(frozen=True)
class Platform:
    name: str
    vessel: Vessel
    instrument: InstrumentSpec
    mounting: Mounting
    description: str = ""


@dataclass(frozen=True)
class Noise:
    """Measurement noise (1-sigma) and sensor resolution.

    ``bt_ar1``, ``reference_ar1`` and ``heading_ar1`` colour the bottom-track, reference (GNSS)
    and heading noise:
    lag-1 autocorrelation from sample to sample of an AR(1) process with the same
    stationary variance as the white noise (0, the default, is white).
    """

    bt_m_s: float = 0.003  # bottom-track radial, constant part
    bt_fraction: float = 0.003  # ... plus this fraction of the transducer speed
    bt_dropout_probability: float = 0.0  # per beam and ping, lost bottom (NaN)
    range_m: float = 0.01
    range_fraction: float = 0.002
    water_m_s: float = 0.01
    tilt_rad: float = np.deg2rad(0.15)
    heading_rad: float = np.deg2rad(0.5)
    attitude_resolution_rad: float = np.deg2rad(0.01)
    reference_m_s: float = 0.003
    bt_ar1: float = 0.0  # lag-1 autocorrelation of the BT noise from ping to ping
    reference_ar1: float = 0.0  # ... of the reference velocity noise from sample to sample
    heading_ar1: float = 0.0  # ... of the heading noise from sample to sample (a compass's slowly wandering error)

    def __post_init__(self):
        for name in ("bt_ar1", "reference_ar1", "heading_ar1"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and -1.0 < value < 1.0):
                raise ValueError(f"noise.{name}: expected a lag-1 autocorrelation in (-1, 1), got {value!r}")


@dataclass(frozen=True)
class DopplerModel:
    """How the simulator forms each echo (explicit modelling choices).

    timing : ``two_way`` (transmit and receive at their own times, Eq. 70) or
        ``instantaneous`` (V_T . d at transmit, Eq. 49: the shallow-water idealisation).
    travel_time : ``exact`` (solve |T(t_R) - S| = c (t_R - t_T - l/c) with the transducer
        moving during the flight) or ``paper`` (t_R = t_T + 2 l / c, Eq. 68).
    receive_direction : ``beam_axis`` (the echo arrives along the beam axis at t_R, as
        Eq. 70 assumes: the receive beam selects the bottom patch it looks at) or
        ``echo_ray`` (along the ray from the bottom spot hit at transmit to the
        transducer at t_R).
    """

    timing: str = "two_way"
    travel_time: str = "exact"
    receive_direction: str = "beam_axis"

    def __post_init__(self):
        _check_choice("doppler", "timing", self.timing, TIMINGS)
        _check_choice("doppler", "travel_time", self.travel_time, TRAVEL_TIMES)
        _check_choice("doppler", "receive_direction", self.receive_direction, RECEIVE_DIRECTIONS)


@dataclass(frozen=True)
class WaterProfile:
    """Current profile: power law from the surface velocity to zero at the bottom."""

    first_cell_depth_m: float
    cell_size_m: float
    n_cells: int
    surface_velocity_m_s: tuple = (0.0, 0.0, 0.0)
    exponent: float = 1.0 / 6.0

    def cell_depths(self) -> np.ndarray:
        return self.first_cell_depth_m + self.cell_size_m * np.arange(self.n_cells)

    def velocity(self, depth_m, water_depth_m) -> np.ndarray:
        """Earth velocity at depths (..., 3)."""
        frac = np.clip((water_depth_m - np.asarray(depth_m, dtype=float)) / water_depth_m, 0.0, 1.0)
        return frac[..., None] ** self.exponent * np.asarray(self.surface_velocity_m_s, dtype=float)


@dataclass(frozen=True)
class Site:
    """Where and when a run is (optional): the simulator then writes ``/position`` and
    ``time_origin_utc``. G is at (start_north_m, start_east_m) at t_start_s in the local
    tangent plane about (latitude, longitude)."""

    latitude_rad: float
    longitude_rad: float
    time_origin_utc: str  # ISO 8601 UTC of the run clock's zero
    start_north_m: float = 0.0
    start_east_m: float = 0.0

    def __post_init__(self):
        if not abs(self.latitude_rad) < np.pi / 2:
            raise ValueError(f"site.latitude_deg: expected |latitude| < 90, got {np.rad2deg(self.latitude_rad)!r}")
        if not abs(self.longitude_rad) <= np.pi:
            raise ValueError(f"site.longitude_deg: expected |longitude| <= 180, got {np.rad2deg(self.longitude_rad)!r}")
        try:
            parse_utc(self.time_origin_utc)
        except ValueError:
            raise ValueError(f"site.time_origin_utc: expected an ISO 8601 UTC time such as \"2022-08-19T20:14:21Z\", "
                             f"got {self.time_origin_utc!r}") from None


REFERENCE_FROM = ("velocity", "positions")


@dataclass(frozen=True)
class Run:
    """One measurement with a platform: motion, navigation, water, sensors, noise."""

    name: str
    motion: AttitudeParams
    navigation: Navigation
    duration_s: float
    water_depth_m: float
    transducer_depth_m: float
    ping_interval_s: tuple = (0.64, 0.95)
    t_start_s: float = 0.0
    description: str = ""
    true_sound_speed_m_s: float | None = None
    attitude_interval_s: tuple | None = None  # None: one sample per ping, at the ping time
    reference_interval_s: tuple | None = (1.0, 1.0)
    reference_stationary: bool = False
    reference_present: bool = True
    # "velocity": instantaneous samples (VTG, INS); "positions": differenced fixes, each velocity the
    # antenna's displacement between two fixes over their interval (GGA without VTG), with its window
    reference_from: str = "velocity"
    water: WaterProfile | None = None
    noise: Noise = field(default_factory=Noise)
    doppler: DopplerModel = field(default_factory=DopplerModel)
    effects: tuple = ()  # ({"name": effect, "params": {...}}, ...) injected beyond the base model
    site: Site | None = None  # where and when: /position and time_origin_utc in the case

    def __post_init__(self):
        from ..models.effects import get_effect

        if self.reference_from not in REFERENCE_FROM:
            raise ValueError(f"runs.{self.name}.reference_from: expected one of {list(REFERENCE_FROM)}, "
                             f"got {self.reference_from!r}")

        for spec in self.effects:
            if not isinstance(spec, dict) or set(spec) != {"name", "params"}:
                raise ValueError(f"runs.{self.name}.effects: expected tables with keys name and params, got {spec!r}")
            get_effect(spec["name"])


@dataclass(frozen=True)
class Scenario:
    name: str
    platform: Platform
    run: Run


# ---------------------------------------------------------------- TOML loading

def _motion(d: dict, owner: str) -> AttitudeParams:
    d = angles_in_radians(d, owner)
    allowed = {"roll_modes", "roll_bias_rad", "pitch_modes", "pitch_bias_rad", "yaw_trend", "yaw_coupling", "t_ref_s",
               "yaw_modes"}
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise ValueError(f"{owner}: unknown key(s) {unknown}; expected some of {sorted(allowed)}")
    return AttitudeParams.from_axis_modes(
        d.get("roll_modes", []), d.get("roll_bias_rad", 0.0), d.get("pitch_modes", []), d.get("pitch_bias_rad", 0.0),
        d.get("yaw_trend", [0.0]), d.get("yaw_coupling"), float(d.get("t_ref_s", 0.0)), d.get("yaw_modes", ()))


def platform_from_table(d: dict, source: str) -> Platform:
    owner = f"{source}: platform"
    return Platform(
        name=d["name"],
        description=d.get("description", ""),
        vessel=build(Vessel, d.get("vessel", {}), owner + ".vessel"),
        instrument=build(InstrumentSpec, angles_in_radians(d["instrument"], owner), owner + ".instrument"),
        mounting=build(Mounting, angles_in_radians(d["mounting"], owner), owner + ".mounting"),
    )


def run_from_table(name: str, d: dict, source: str) -> Run:
    owner = f"{source}: runs.{name}"
    d = angles_in_radians(d, owner)
    d["name"] = name
    d["motion"] = _motion(d.get("motion", {}), owner + ".motion")
    d["navigation"] = build(Navigation, d.get("navigation", {}), owner + ".navigation")
    if "water" in d:
        d["water"] = build(WaterProfile, d["water"], owner + ".water")
    d["noise"] = build(Noise, angles_in_radians(d.get("noise", {}), owner), owner + ".noise")
    d["doppler"] = build(DopplerModel, d.get("doppler", {}), owner + ".doppler")
    if "site" in d:
        d["site"] = build(Site, angles_in_radians(d["site"], owner), owner + ".site")
    return build(Run, d, owner)


def load_scenario_file(path) -> dict[str, Scenario]:
    """All scenarios of one platform file, by run name."""
    path = Path(path)
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    platform = platform_from_table(data["platform"], path.name)
    defaults = data.get("defaults", {})
    surveys = data.get("survey", {})
    missing = sorted(set(surveys) - set(data.get("runs", {})))
    if missing:
        raise ValueError(f"{path.name}: survey.{missing[0]}: expected a run template [runs.{missing[0]}], got none")
    out = {}
    for name, run in data.get("runs", {}).items():
        merged = deep_merge(defaults, run)
        if name in surveys:  # a survey's template: listed as its first transect (cases/survey.py)
            merged = nominal_transect(name, surveys[name], merged, path.name)
        out[name] = Scenario(name, platform, run_from_table(name, merged, path.name))
    return out


def builtin_scenario_files() -> list[Path]:
    folder = resources.files(__package__) / "scenarios"
    return sorted(Path(str(p)) for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scenarios(paths=None) -> dict[str, Scenario]:
    """Every scenario defined in the given TOML files (default: the built-in ones)."""
    out: dict[str, Scenario] = {}
    for path in paths or builtin_scenario_files():
        for name, sc in load_scenario_file(path).items():
            if name in out:
                raise ValueError(f"{Path(path).name}: scenario {name!r} is defined twice")
            out[name] = sc
    return out


def get_scenario(name: str) -> Scenario:
    """A built-in scenario by name, or a clear error listing the names."""
    scenarios = load_scenarios()
    if name not in scenarios:
        raise ValueError(f"scenario: unknown name {name!r}; expected one of {sorted(scenarios)}")
    return scenarios[name]
