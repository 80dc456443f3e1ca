"""River surveys: several transects across one section by one boat, alternating banks.

A survey is a run template in a scenario TOML (``[runs.NAME]``, with the platform and
``[defaults]`` of its file) plus a ``[survey.NAME]`` table: the site, the section, the
current, the time between transects and the compass error and moving bed every run
shares. :func:`survey_scenarios` makes transect k from the template by TOML-level
overrides, so each transect is an ordinary :class:`~.scenario.Scenario`:

- course over ground: the section's course, reversed on every other transect;
- heading: the boat crabs, pointing its velocity through the water (over-ground minus
  current) along its heading; the navigation is the current plus that speed along the
  heading trend, so the track runs exactly along the section from bank to bank;
- each transect on its own clock from 0 (``time_origin_utc`` is its UTC start:
  ``start_utc`` + k (duration + gap_s)), G starting on its bank in the site's plane;
- the phase of every motion mode (roll, pitch, heading wander) drawn per transect;
- effects: ``compass_deviation`` (A, B, C) and ``moving_bed`` (speed downstream), the
  same in every transect; drawn from the table's ranges by the survey seed unless fixed.

Transect k is simulated with seed ``seed + k``; the survey's own draws use a separate
stream of the same seed.
"""

from __future__ import annotations

import datetime as dt
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from .case import format_utc, parse_utc
from .scenario import Scenario, _angles, _build, _deep_merge, _platform, _run, builtin_scenario_files

SURVEY_STREAM = 0x5A7E  # second word of the survey draws' seed: never the transects' own streams
BED_PROFILES = ("uniform", "parabolic")


@dataclass(frozen=True)
class SurveySpec:
    """``[survey.NAME]``: site, section, current, timing and the shared effects (SI, radians)."""

    latitude_rad: float  # bank A, origin of the site's north-east plane
    longitude_rad: float
    start_utc: str  # UTC of the first transect's clock zero
    section_course_rad: float  # course over ground of transect 1, bank A -> bank B
    width_m: float
    crossing_speed_m_s: float  # speed over ground along the section
    current_speed_m_s: float
    downstream_rad: float  # direction of the current and the moving bed
    gap_s: float  # at the bank between transects
    compass_rad: tuple  # nominal (A, B, C): heading reads psi + A + B sin psi + C cos psi
    compass_A_range_rad: tuple  # drawn |A|, random sign
    compass_BC_max_rad: float  # drawn B, C uniform in +-this
    bed_speed_m_s: float  # nominal
    bed_speed_range_m_s: tuple  # drawn
    bed_profile: str = "uniform"
    description: str = ""

    def __post_init__(self):
        for name in ("width_m", "crossing_speed_m_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"survey.{name}: expected a value > 0, got {getattr(self, name)!r}")
        for name in ("current_speed_m_s", "gap_s", "compass_BC_max_rad", "bed_speed_m_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"survey.{name}: expected a value >= 0, got {getattr(self, name)!r}")
        if len(self.compass_rad) != 3:
            raise ValueError(f"survey.compass_deg: expected [A, B, C], got {len(self.compass_rad)} values")
        for name in ("compass_A_range_rad", "bed_speed_range_m_s"):
            lo_hi = getattr(self, name)
            if len(lo_hi) != 2 or not 0 <= lo_hi[0] <= lo_hi[1]:
                raise ValueError(f"survey.{name}: expected [low, high] with 0 <= low <= high, got {list(lo_hi)}")
        if self.bed_profile not in BED_PROFILES:
            raise ValueError(f"survey.bed_profile: expected one of {list(BED_PROFILES)}, got {self.bed_profile!r}")
        try:
            parse_utc(self.start_utc)
        except ValueError:
            raise ValueError(f"survey.start_utc: expected an ISO 8601 UTC time, got {self.start_utc!r}") from None

    @property
    def duration_s(self) -> float:
        """One transect, bank to bank."""
        return self.width_m / self.crossing_speed_m_s

    def unit(self, angle_rad) -> np.ndarray:
        return np.array([np.cos(angle_rad), np.sin(angle_rad)])

    def bank_b_m(self) -> np.ndarray:
        """Bank B (north, east) from bank A, metres."""
        return self.width_m * self.unit(self.section_course_rad)


@dataclass(frozen=True)
class SurveyDraw:
    """What every transect of one survey shares (compass error, bed) and each one's mode phases."""

    compass_rad: tuple  # (A, B, C)
    bed_speed_m_s: float
    bed_profile: str
    phase_fractions: np.ndarray  # (runs, modes): each mode's phase shift as a fraction of its period


def _spec(d: dict, source: str, name: str) -> SurveySpec:
    owner = f"{source}: survey.{name}"
    d = _angles(d, owner)
    known = {f.name for f in fields(SurveySpec)}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"{owner}: unknown key(s) {unknown}; expected some of {sorted(known)}")
    return _build(SurveySpec, d, owner)


def _find(name: str):
    """(path, parsed TOML) of the built-in file that defines survey ``name``."""
    for path in builtin_scenario_files():
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
        if name in data.get("survey", {}):
            return path, data
    return None, None


def survey_names() -> list[str]:
    """Names of the built-in surveys."""
    out = []
    for path in builtin_scenario_files():
        with open(path, "rb") as fh:
            out += list(tomllib.load(fh).get("survey", {}))
    return sorted(out)


def is_survey(name: str) -> bool:
    return _find(name)[0] is not None


def _modes(motion: dict) -> list[tuple[str, int]]:
    return [(key, i) for key in ("roll_modes", "pitch_modes", "yaw_modes")
            for i in range(len(motion.get(key, [])))]


def _shift_modes(motion: dict, fractions) -> dict:
    """Motion rows [A, t0, omega, decay] with t0 moved by a fraction of each mode's period."""
    out = {k: [list(r) for r in motion.get(k, [])] for k in ("roll_modes", "pitch_modes", "yaw_modes")}
    for (key, i), f in zip(_modes(motion), fractions):
        out[key][i][1] += float(f) * 2 * np.pi / out[key][i][2]
    return {k: v for k, v in out.items() if v}


def transect_overrides(spec: SurveySpec, template: dict, k: int, runs: int, draw: SurveyDraw) -> dict:
    """TOML-level overrides that make transect k (0-based) of ``runs`` from the run template."""
    forward = k % 2 == 0
    course = spec.section_course_rad + (0.0 if forward else np.pi)
    v_ground = spec.crossing_speed_m_s * spec.unit(course)
    current = spec.current_speed_m_s * spec.unit(spec.downstream_rad)
    through_water = v_ground - current
    heading = float(np.arctan2(through_water[1], through_water[0]))  # the boat points along its water velocity
    start = np.zeros(2) if forward else spec.bank_b_m()
    bank_b = spec.bank_b_m()
    utc0 = parse_utc(spec.start_utc) + dt.timedelta(seconds=k * (spec.duration_s + spec.gap_s))
    bed = spec.unit(spec.downstream_rad) * draw.bed_speed_m_s
    bed_params = {"velocity_north_m_s": float(bed[0]), "velocity_east_m_s": float(bed[1])}
    if draw.bed_profile != "uniform":
        bed_params.update(profile=draw.bed_profile, bank_a_north_m=0.0, bank_a_east_m=0.0,
                          bank_b_north_m=float(bank_b[0]), bank_b_east_m=float(bank_b[1]))
    A, B, C = (float(x) for x in draw.compass_rad)
    motion = dict(template.get("motion", {}))
    motion.update(_shift_modes(motion, draw.phase_fractions[k]), yaw_trend=[heading])
    return {
        "description": (f"{spec.description or template.get('description', 'river survey')}: transect {k + 1} of {runs}, "
                        f"{'bank A -> bank B' if forward else 'bank B -> bank A'}, course "
                        f"{np.rad2deg(course) % 360:.1f} deg, heading {np.rad2deg(heading) % 360:.1f} deg"),
        "duration_s": spec.duration_s,
        "t_start_s": 0.0,
        "navigation": {"knot_times_s": [0.0], "knot_velocities_m_s": [[float(current[0]), float(current[1]), 0.0]],
                       "speed_along_heading_m_s": float(np.hypot(*through_water))},
        "motion": motion,
        "site": {"latitude_rad": spec.latitude_rad, "longitude_rad": spec.longitude_rad,
                 "time_origin_utc": format_utc(utc0), "start_north_m": float(start[0]), "start_east_m": float(start[1])},
        "effects": list(template.get("effects", [])) + [
            {"name": "compass_deviation", "params": {"A_rad": A, "B_rad": B, "C_rad": C}},
            {"name": "moving_bed", "params": bed_params},
        ],
    }


def nominal_transect(name: str, survey_table: dict, template: dict, source: str) -> dict:
    """The template completed as transect 1 with the nominal compass error and bed (the
    scenario listed under the survey's name)."""
    spec = _spec(survey_table, source, name)
    draw = SurveyDraw(tuple(spec.compass_rad), spec.bed_speed_m_s, spec.bed_profile, np.zeros((1, len(_modes(template.get("motion", {}))))))
    return _deep_merge(template, transect_overrides(spec, template, 0, 1, draw))


def _draw(spec: SurveySpec, runs: int, n_modes: int, seed: int, compass_rad, bed_speed_m_s, bed_profile) -> SurveyDraw:
    rng = np.random.default_rng([int(seed), SURVEY_STREAM])
    a = rng.uniform(*spec.compass_A_range_rad) * rng.choice([-1.0, 1.0])
    b, c = rng.uniform(-spec.compass_BC_max_rad, spec.compass_BC_max_rad, 2)
    bed = rng.uniform(*spec.bed_speed_range_m_s)
    phases = rng.uniform(0.0, 1.0, (runs, n_modes))
    if compass_rad is not None:
        if len(compass_rad) != 3:
            raise ValueError(f"compass_rad: expected (A, B, C), got {len(compass_rad)} values")
        a, b, c = compass_rad
    if bed_speed_m_s is not None:
        if not bed_speed_m_s >= 0:
            raise ValueError(f"bed_speed_m_s: expected a speed >= 0, got {bed_speed_m_s!r}")
        bed = bed_speed_m_s
    profile = spec.bed_profile if bed_profile is None else bed_profile
    if profile not in BED_PROFILES:
        raise ValueError(f"bed_profile: expected one of {list(BED_PROFILES)}, got {profile!r}")
    return SurveyDraw((float(a), float(b), float(c)), float(bed), profile, phases)


def survey_scenarios(name: str, runs: int, seed: int, compass_rad=None, bed_speed_m_s: float | None = None,
                     bed_profile: str | None = None) -> list[Scenario]:
    """The transects of a built-in survey, one scenario each (``NAME_run01``, ...).

    Parameters
    ----------
    name : str
        A survey (``adcpdyn scenarios`` lists it; e.g. ``river_survey``).
    runs : int
        Number of transects K >= 1, alternating banks (odd ones bank A -> B).
    seed : int
        Survey seed: draws the compass error and bed speed (unless fixed) and each
        transect's motion phases; transect k is then simulated with ``seed + k``.
    compass_rad : (A, B, C) or None
        Fixes the compass deviation (heading reads psi + A + B sin psi + C cos psi).
    bed_speed_m_s : float or None
        Fixes the moving bed's speed (downstream).
    bed_profile : "uniform", "parabolic" or None (the survey's own)
        Bed speed across the section: constant, or 4 s (1 - s) of the peak, s from bank A.
    """
    if not isinstance(runs, (int, np.integer)) or isinstance(runs, bool) or runs < 1:
        raise ValueError(f"runs: expected an integer >= 1, got {runs!r}")
    path, data = _find(name)
    if path is None:
        raise ValueError(f"survey: unknown name {name!r}; expected one of {survey_names()}")
    if name not in data.get("runs", {}):
        raise ValueError(f"{path.name}: survey.{name}: expected a run template [runs.{name}], got none")
    spec = _spec(data["survey"][name], path.name, name)
    platform = _platform(data["platform"], path.name)
    template = _deep_merge(data.get("defaults", {}), data["runs"][name])
    draw = _draw(spec, runs, len(_modes(template.get("motion", {}))), seed, compass_rad, bed_speed_m_s, bed_profile)
    out = []
    for k in range(runs):
        run_name = f"{name}_run{k + 1:02d}"
        d = _deep_merge(template, transect_overrides(spec, template, k, runs, draw))
        out.append(Scenario(run_name, platform, _run(run_name, d, path.name)))
    return out


def simulate_survey(name: str, runs: int, seed: int, **options) -> list:
    """Simulated cases of :func:`survey_scenarios` (transect k with seed ``seed + k``), each
    with ``/truth`` attribute ``survey`` (JSON: name, run, runs, seed, course, heading, crab)."""
    import dataclasses
    import json

    from .simulation import simulate

    cases = []
    scenarios = survey_scenarios(name, runs, seed, **options)
    for k, sc in enumerate(scenarios):
        case = simulate(sc, seed=seed + k)
        nav = sc.run.navigation
        v = nav.velocity([0.0], lambda t: np.full_like(t, sc.run.motion.yaw_trend[0]))[0]
        course, heading = float(np.arctan2(v[1], v[0])), float(sc.run.motion.yaw_trend[0])
        info = {"survey": name, "run": k + 1, "runs": runs, "survey_seed": seed, "case_seed": seed + k,
                "course_over_ground_rad": course, "heading_trend_rad": heading,
                "crab_angle_rad": float(np.angle(np.exp(1j * (heading - course)))),
                "speed_over_ground_m_s": float(np.hypot(v[0], v[1]))}
        truth = dataclasses.replace(case.truth, extra_attrs={**case.truth.extra_attrs, "survey": json.dumps(info)})
        cases.append(case.replace(truth=truth))
    return cases
