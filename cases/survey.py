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

import tomllib

import numpy as np

from .scenario import Scenario, builtin_scenario_files, platform_from_table, run_from_table
from .survey_spec import draw_survey, modes_of, survey_spec, transect_overrides
from .tables import deep_merge

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
    spec = survey_spec(data["survey"][name], path.name, name)
    platform = platform_from_table(data["platform"], path.name)
    template = deep_merge(data.get("defaults", {}), data["runs"][name])
    draw = draw_survey(spec, runs, len(modes_of(template.get("motion", {}))), seed, compass_rad, bed_speed_m_s, bed_profile)
    out = []
    for k in range(runs):
        run_name = f"{name}_run{k + 1:02d}"
        d = deep_merge(template, transect_overrides(spec, template, k, runs, draw))
        out.append(Scenario(run_name, platform, run_from_table(run_name, d, path.name)))
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
