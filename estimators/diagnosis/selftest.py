"""Blind self-test of the diagnosis: simulate cases with one random effect (or none) at a
random realistic magnitude, diagnose them without looking, and score the verdicts.

The shrink reported for the right effect is compared with the shrink of the oracle
refit: the same effect model with its parameters pinned at the injected values (where
the simulator's parameters are the model's; surge and deep-water timing have none).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ...cases.scenario import Scenario, get_scenario
from ...models.effects import get_effect
from ...models.simulator import simulate
from .diagnose import DiagnosisConfig, _cv_residuals, _gap, diagnose

NONE = "none"


def draw_cases(n: int, seed: int, effects, p_none: float = 0.2):
    """n (label, params, simulation seed) drawn with one generator: reproducible."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        label = NONE if rng.uniform() < p_none else str(rng.choice(list(effects)))
        params = {} if label == NONE else get_effect(label).draw(rng)
        out.append((label, params, int(rng.integers(0, 2**31 - 1))))
    return out


def with_effect(scenario: Scenario, label: str, params: dict) -> Scenario:
    effects = () if label == NONE else ({"name": label, "params": params},)
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
    cv = _cv_residuals(model, pinned, config.cv_folds, config.cv_block_s)
    gap, _ = _gap(model, cv, result.noise_levels)
    return (result.gap_before - gap) / result.gap_before if result.gap_before > 0 else None


def run_one(label: str, params: dict, sim_seed: int, scenario: str, config: DiagnosisConfig) -> dict:
    """Simulate, diagnose blind, then (only afterwards) compare with what was injected."""
    case = simulate(with_effect(get_scenario(scenario), label, params), seed=sim_seed)
    case = dataclasses.replace(case, truth=dataclasses.replace(case.truth, effects=[]))  # blind
    t0 = time.perf_counter()
    r = diagnose(case, config)
    seconds = time.perf_counter() - t0
    reported = next((s for s in r.ranking if s["effect"] == label), None)
    oracle = oracle_shrink(r, label, params, config)
    return {"truth": label, "params": params, "seed": sim_seed, "verdict": r.verdict,
            "correct": r.verdict == label, "gap_before": r.gap_before, "gap_after": r.gap_after,
            "remaining_gap_significant": r.remaining_gap_significant,
            "where_top": r.where[0]["channel"] if r.where else None,
            "where_detail": r.where[0]["detail"] if r.where else None,
            "shrink_reported": reported["shrink_fraction"] if reported else None,
            "shrink_oracle": oracle, "seconds": seconds, "statement": r.statement}


def summarise(rows: list[dict], labels: list[str]) -> dict:
    """Confusion matrix, top-1 accuracy, false-alarm rate, shrink error against the oracle."""
    names = list(labels) + [NONE]
    verdicts = sorted({r["verdict"] for r in rows} | set(names), key=lambda v: (v not in names, names.index(v) if v in names else 0, v))
    matrix = {t: {v: 0 for v in verdicts} for t in names}
    for r in rows:
        matrix[r["truth"]][r["verdict"]] += 1
    with_effect_rows = [r for r in rows if r["truth"] != NONE]
    none_rows = [r for r in rows if r["truth"] == NONE]
    shrink_err = [abs(r["shrink_reported"] - r["shrink_oracle"]) / abs(r["shrink_oracle"])
                  for r in rows if r["correct"] and r["shrink_oracle"] not in (None, 0) and r["shrink_reported"] is not None]
    return {
        "n_cases": len(rows),
        "top1_accuracy": float(np.mean([r["correct"] for r in rows])) if rows else float("nan"),
        "top1_accuracy_with_effect": float(np.mean([r["correct"] for r in with_effect_rows])) if with_effect_rows else float("nan"),
        "false_alarm_rate": float(np.mean([r["verdict"] != NONE for r in none_rows])) if none_rows else float("nan"),
        "n_effect_free": len(none_rows),
        "every_case_says_where": all(r["where_top"] for r in rows),
        "remaining_gap_flagged_when_correct": float(np.mean([r["remaining_gap_significant"] for r in with_effect_rows
                                                             if r["correct"]])) if with_effect_rows else float("nan"),
        "shrink_relative_error_max": float(max(shrink_err)) if shrink_err else float("nan"),
        "shrink_relative_error_median": float(np.median(shrink_err)) if shrink_err else float("nan"),
        "shrink_within_20pct": float(np.mean(np.array(shrink_err) <= 0.2)) if shrink_err else float("nan"),
        "confusion": matrix,
    }


def format_summary(s: dict) -> str:
    names = list(s["confusion"])
    cols = [v for v in next(iter(s["confusion"].values()))]
    short = {v: v[:8] for v in cols}
    w = max(len(n) for n in names) + 2
    lines = ["confusion matrix (rows: injected, columns: verdict)",
             " " * w + " ".join(f"{short[c]:>8s}" for c in cols)]
    for t in names:
        lines.append(f"{t:<{w}s}" + " ".join(f"{s['confusion'][t][c]:8d}" for c in cols))
    lines += [f"cases: {s['n_cases']}  top-1 accuracy: {100 * s['top1_accuracy']:.1f}% (target >= 90%)",
              f"false alarms on {s['n_effect_free']} effect-free cases: {100 * s['false_alarm_rate']:.1f}% (target <= 10%)",
              f"every report says where the gap lies: {s['every_case_says_where']}",
              f"right verdicts that still claim a significant remaining gap: "
              f"{100 * s['remaining_gap_flagged_when_correct']:.0f}%",
              f"reported vs oracle shrink, relative error: median {s['shrink_relative_error_median']:.3f}, "
              f"max {s['shrink_relative_error_max']:.3f}, within 20%: {100 * s['shrink_within_20pct']:.0f}% of cases"]
    return "\n".join(lines)
