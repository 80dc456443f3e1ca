"""A survey's ``[survey.NAME]`` table and the TOML overrides that make transect k of a run
template (course, crab, clock, site, motion phases, the shared compass error and bed): the
part of :mod:`.survey` the scenario loader needs to list a survey's nominal transect, kept
below both so neither imports the other's internals."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, fields

import numpy as np

from .case import format_utc, parse_utc
from .tables import angles_in_radians, build, deep_merge

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


def survey_spec(d: dict, source: str, name: str) -> SurveySpec:
    owner = f"{source}: survey.{name}"
    d = angles_in_radians(d, owner)
    known = {f.name for f in fields(SurveySpec)}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"{owner}: unknown key(s) {unknown}; expected some of {sorted(known)}")
    return build(SurveySpec, d, owner)


def modes_of(motion: dict) -> list[tuple[str, int]]:
    return [(key, i) for key in ("roll_modes", "pitch_modes", "yaw_modes")
            for i in range(len(motion.get(key, [])))]


def _shift_modes(motion: dict, fractions) -> dict:
    """Motion rows [A, t0, omega, decay] with t0 moved by a fraction of each mode's period."""
    out = {k: [list(r) for r in motion.get(k, [])] for k in ("roll_modes", "pitch_modes", "yaw_modes")}
    for (key, i), f in zip(modes_of(motion), fractions):
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
    spec = survey_spec(survey_table, source, name)
    draw = SurveyDraw(tuple(spec.compass_rad), spec.bed_speed_m_s, spec.bed_profile, np.zeros((1, len(modes_of(template.get("motion", {}))))))
    return deep_merge(template, transect_overrides(spec, template, 0, 1, draw))


def draw_survey(spec: SurveySpec, runs: int, n_modes: int, seed: int, compass_rad, bed_speed_m_s, bed_profile) -> SurveyDraw:
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
