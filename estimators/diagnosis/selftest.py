"""Blind self-test of the diagnosis: simulate cases with one random effect (or none) at a
random realistic magnitude on a random platform of the house, diagnose them without looking,
and score the verdicts.

Platforms (:data:`PLATFORMS`): the self-test launch with its sensor aligned to the vessel or
inside a head turned on its mount, the pool boat pushed diagonally, the 13-m survey ship
(installation yaw 7.4 deg, GNSS), a river transect (compass in the head with a misalignment,
GNSS); each draw also picks the attitude sampling (the platform's own, or 2.5 times slower for a
sensor on its own clock: still four samples per motion period; one sampled per ping stays) and
the noise colour (white or AR(1) 0.5 on bottom track and GNSS). An effect the base model
carries on that platform (the base's navigation follows speed changes; an installation the
base estimates; a sensor in the head sees no installation) is expected to get ``none``.

The shrink reported for the right effect is compared with the shrink of the oracle refit: the
same effect model with its parameters pinned at the injected values (where the simulator's
parameters are the model's; surge and deep-water timing have none).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ...cases.scenario import Scenario, get_scenario
from ...models.effects import get_effect
from ...cases.simulation import simulate
from .config import DiagnosisConfig
from .diagnose import diagnose
from .heldout import cv_residuals, heldout_gap

NONE = "none"
SLOW_ATTITUDE = 2.5  # the slower attitude sampling: this many times the platform's interval


def _launch_head() -> Scenario:
    sc = get_scenario("diag_boat")
    m = dataclasses.replace(sc.platform.mounting, attitude_frame="transducer", installation_ypr_rad=(0.05, 0.015, -0.02))
    return dataclasses.replace(sc, name="diag_boat_head", platform=dataclasses.replace(sc.platform, mounting=m))


def _river() -> Scenario:
    from ...cases.survey import survey_scenarios

    return survey_scenarios("river_survey", 1, 7, compass_rad=(np.deg2rad(-12.0), 0.0, 0.0), bed_speed_m_s=0.0)[0]


PLATFORMS = {  # name -> (scenario maker, run length s)
    "launch_vessel": (lambda: get_scenario("diag_boat"), 90.0),
    "launch_head": (_launch_head, 90.0),
    "pool": (lambda: get_scenario("pool_diag"), None),
    "survey_ship": (lambda: get_scenario("deep_ship"), 120.0),
    "river": (_river, None),
}


def platform_scenario(name: str, slow_attitude: bool, ar1: float) -> Scenario:
    """A platform's base scenario with the drawn attitude sampling and noise colour."""
    make, duration = PLATFORMS[name]
    sc = make()
    run = sc.run if duration is None else dataclasses.replace(sc.run, duration_s=min(duration, sc.run.duration_s))
    if slow_attitude and run.attitude_interval_s is not None:  # a sensor of its own clock; one sampled per ping stays
        run = dataclasses.replace(run, attitude_interval_s=tuple(SLOW_ATTITUDE * np.asarray(run.attitude_interval_s, dtype=float)))
    if ar1:
        run = dataclasses.replace(run, noise=dataclasses.replace(run.noise, bt_ar1=ar1, reference_ar1=ar1))
    return dataclasses.replace(sc, run=run)


def draw_cases(n: int, seed: int, effects, p_none: float = 0.2, platforms=tuple(PLATFORMS)):
    """n draws (label, params, simulation seed, platform, slow attitude, AR(1)) from one generator."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        label = NONE if rng.uniform() < p_none else str(rng.choice(list(effects)))
        params = {} if label == NONE else get_effect(label).draw(rng)
        platform = str(rng.choice(list(platforms)))
        out.append((label, params, int(rng.integers(0, 2**31 - 1)), platform, bool(rng.uniform() < 0.3),
                    float(rng.choice([0.0, 0.5]))))
    return out


def with_effect(scenario: Scenario, label: str, params: dict) -> Scenario:
    """The scenario with one more effect injected (beside any the platform carries)."""
    effects = tuple(scenario.run.effects) + (() if label == NONE else ({"name": label, "params": params},))
    return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, effects=effects))


def oracle_shrink(result, label: str, params: dict, config: DiagnosisConfig) -> float | None:
    """Held-out shrink of the effect model with its parameters pinned at the injected values."""
    if label == NONE or label not in result.fits:
        return None
    fixed = get_effect(label).truth_values(params)
    model, fit = result.fits[label]
    if fixed is None:
        return None
    pinned = model.solve(fit.x.copy(), fit.sigma, fixed=fixed)
    cv = cv_residuals(model, pinned, config.cv_folds, config.block_s(model.random_walk))
    gap, _ = heldout_gap(model, cv, result.noise_levels)
    return (result.gap_before - gap) / result.gap_before if result.gap_before > 0 else None


CALIBRATION_STARTS = 8  # multistart of the calibrated self-test's calibration runs


def calibration_of(platform: str, slow_attitude: bool, ar1: float, sim_seed: int):
    """The paper's workflow: the platform calibrated on an effect-free run of its own (another
    noise seed, another case name, so no run-specific number of it is pinned in the diagnosis),
    as the typed record a diagnosis reads."""
    from ..calibration.config import CalibrationConfig
    from ..calibration.problem import calibrate
    from ..calibration.record import as_record

    case = simulate(platform_scenario(platform, slow_attitude, ar1), seed=(sim_seed + 7919) % (2**31 - 1))
    case = dataclasses.replace(case, name=case.name + "_calibration", truth=None)
    return as_record(calibrate(case, CalibrationConfig(n_starts=CALIBRATION_STARTS)))


def run_one(label: str, params: dict, sim_seed: int, platform: str, config: DiagnosisConfig,
            slow_attitude: bool = False, ar1: float = 0.0, calibrated: bool = False) -> dict:
    """Simulate, diagnose blind, then (only afterwards) compare with what was injected. With
    ``calibrated`` the base is the calibration of an effect-free run of the same platform."""
    case = simulate(with_effect(platform_scenario(platform, slow_attitude, ar1), label, params), seed=sim_seed)
    case = dataclasses.replace(case, truth=dataclasses.replace(case.truth, effects=[]))  # blind
    calibration = calibration_of(platform, slow_attitude, ar1, sim_seed) if calibrated else None
    t0 = time.perf_counter()
    r = diagnose(case, config, calibration=calibration)
    seconds = time.perf_counter() - t0
    absorbed = label in r.base["skipped_effects"]
    expected = NONE if absorbed else label
    first = r.selected[0] if r.selected else NONE
    reported = next((s for s in r.ranking if s["effect"] == label and s.get("round", 1) == 1), None)
    oracle = None if absorbed else oracle_shrink(r, label, params, config)
    visible = bool(r.gap_before > config.min_gap and r.gap_z_before > config.gap_z)  # the base shows a gap to explain
    return {"truth": label, "expected": expected, "visible": visible, "absorbed_by_base": r.base["skipped_effects"].get(label) if absorbed else None,
            "params": params, "seed": sim_seed, "platform": platform, "slow_attitude": slow_attitude, "ar1": ar1,
            "calibrated": calibrated,
            "attitude_source": r.base["attitude_source"], "verdict": r.verdict, "correct": first == expected,
            "gap_before": r.gap_before, "gap_after": r.gap_after,
            "remaining_gap_significant": r.remaining_gap_significant,
            "where_top": r.where[0]["channel"] if r.where else None,
            "where_detail": r.where[0]["detail"] if r.where else None,
            "shrink_reported": reported["shrink_fraction"] if reported else None,
            "shrink_oracle": oracle, "seconds": seconds, "statement": r.statement}


def summarise(rows: list[dict], labels: list[str]) -> dict:
    """Confusion matrix, top-1 accuracy, false-alarm rate, shrink error against the oracle."""
    names = list(labels) + [NONE]
    verdicts = sorted({r["verdict"].split("+")[0] for r in rows} | set(names), key=lambda v: (v not in names, names.index(v) if v in names else 0, v))
    matrix = {t: {v: 0 for v in verdicts} for t in names}
    for r in rows:
        matrix[r["expected"]][r["verdict"].split("+")[0]] += 1
    with_effect_rows = [r for r in rows if r["expected"] != NONE]
    none_rows = [r for r in rows if r["expected"] == NONE]
    shrink_err = [abs(r["shrink_reported"] - r["shrink_oracle"]) / abs(r["shrink_oracle"])
                  for r in rows if r["correct"] and r["shrink_oracle"] not in (None, 0) and r["shrink_reported"] is not None]
    return {
        "n_cases": len(rows),
        "top1_accuracy": float(np.mean([r["correct"] for r in rows])) if rows else float("nan"),
        "top1_accuracy_with_effect": float(np.mean([r["correct"] for r in with_effect_rows])) if with_effect_rows else float("nan"),
        "false_alarm_rate": float(np.mean([r["verdict"] != NONE for r in none_rows])) if none_rows else float("nan"),
        "top1_accuracy_visible": (lambda v: float(np.mean([r["correct"] for r in v])) if v else float("nan"))(
            [r for r in rows if r["expected"] == NONE or r.get("visible", True)]),
        "n_invisible": int(sum(r["expected"] != NONE and not r.get("visible", True) for r in rows)),
        "by_platform": {p: {"n": len(g), "top1": float(np.mean([r["correct"] for r in g]))}
                        for p in sorted({r.get("platform", "") for r in rows})
                        for g in [[r for r in rows if r.get("platform", "") == p]]},
        "n_effect_free": len(none_rows),
        "every_case_says_where": all(r["where_top"] for r in rows),
        "remaining_gap_flagged_when_correct": float(np.mean([r["remaining_gap_significant"] for r in with_effect_rows
                                                             if r["correct"]])) if with_effect_rows else float("nan"),
        "shrink_relative_error_max": float(max(shrink_err)) if shrink_err else float("nan"),
        "shrink_relative_error_median": float(np.median(shrink_err)) if shrink_err else float("nan"),
        "shrink_within_20pct": float(np.mean(np.array(shrink_err) <= 0.2)) if shrink_err else float("nan"),
        "confusion": matrix,
    }


def markdown_row(res: dict) -> str:
    """One self-test run (its SELFTEST.json) as a row of docs/diagnosis.md's table: the command,
    top-1 overall and over the effects that left a gap, false alarms, by platform, median time."""
    s = res["summary"]
    command = f"`--selftest {res['n']} --seed {res['seed']}{' --selftest-calibrated' if res['calibrated'] else ''}`"
    alarms = round(s["false_alarm_rate"] * s["n_effect_free"])
    platforms = ", ".join(f"{p} {100 * v['top1']:.0f} % of {v['n']}" for p, v in s["by_platform"].items())
    median = float(np.median([c["seconds"] for c in res["cases"]]))
    return (f"| {command} | {s['n_cases']} | {100 * s['top1_accuracy']:.1f} % | {100 * s['top1_accuracy_visible']:.1f} % "
            f"({s['n_invisible']} invisible) | {alarms} of {s['n_effect_free']} | {platforms} | {median:.1f} s |")


def format_summary(s: dict) -> str:
    names = list(s["confusion"])
    cols = [v for v in next(iter(s["confusion"].values()))]
    number = {v: k + 1 for k, v in enumerate(cols)}  # a verdict's number: its column, and its row when injected
    nw = len(str(len(cols)))
    label = {n: f"{number[n]:>{nw}d} {n}" if n in number else f"{'':>{nw}s} {n}" for n in names}
    w = max(len(v) for v in label.values()) + 1
    cw = max(len(str(len(cols))), max((len(str(c)) for row in s["confusion"].values() for c in row.values()), default=1)) + 2
    lines = ["confusion matrix: cases by injected effect (rows) and verdict (columns, numbered as the rows)",
             f"{'injected':<{w}s}" + "".join(f"{number[c]:>{cw}d}" for c in cols)]
    for t in names:
        lines.append(f"{label[t]:<{w}s}" + "".join(f"{s['confusion'][t][c]:>{cw}d}" for c in cols))
    extra = [c for c in cols if c not in names]
    if extra:
        lines.append("verdicts never injected: " + ", ".join(f"{number[c]} {c}" for c in extra))
    lines += [f"cases: {s['n_cases']}  top-1 accuracy: {100 * s['top1_accuracy']:.1f}% (target >= 90%); "
              f"{100 * s['top1_accuracy_visible']:.1f}% leaving out the {s['n_invisible']} injected effects that left no "
              "significant gap (held-out excess <= min_gap or z <= gap_z: no method can name them from these data)",
              "by platform: " + ", ".join(f"{p} {100 * v['top1']:.0f}% of {v['n']}" for p, v in s.get("by_platform", {}).items()),
              f"false alarms on {s['n_effect_free']} effect-free cases: {100 * s['false_alarm_rate']:.1f}% (target <= 10%)",
              f"every report says where the gap lies: {s['every_case_says_where']}",
              f"right verdicts that still claim a significant remaining gap: "
              f"{100 * s['remaining_gap_flagged_when_correct']:.0f}%",
              f"reported vs oracle shrink, relative error: median {s['shrink_relative_error_median']:.3f}, "
              f"max {s['shrink_relative_error_max']:.3f}, within 20%: {100 * s['shrink_within_20pct']:.0f}% of cases"]
    return "\n".join(lines)
