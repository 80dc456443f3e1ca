"""Every lever-arm formulation calibrated on one case, side by side (one row each)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..cases.case import Case
from .calibration.problem import CalibrationConfig, CalibrationProblem
from .formulations import FORMULATIONS


def compare_formulations(case: Case, config: CalibrationConfig, formulations=FORMULATIONS) -> dict:
    """Calibrate ``case`` once per formulation; rows keyed by formulation.

    Each row: objective, max constraint violation, wall time, iterations (best start
    and mean over starts), share of starts at the best, success, the unobservable and
    weak lever-arm directions, and, for a simulated case, the errors against truth
    (:func:`~adcpdyn.estimators.evaluation.calibration_errors`).
    """
    from .evaluation import calibration_errors

    rows = {}
    for form in formulations:
        tic = time.perf_counter()
        r = CalibrationProblem(case, dataclasses.replace(config, formulation=form)).solve()
        elapsed = time.perf_counter() - tic
        ms = r.multistart
        unobs = [u for u in r.uncertainty.unobservable if "attitude-model" not in u["description"]]
        row = {"objective": r.objective, "max_constraint_violation": r.max_constraint_violation, "time_s": elapsed,
               "iterations_best": ms.iterations, "iterations_mean": float(np.mean([s.iterations for s in ms.starts])),
               "fraction_at_best": ms.fraction_at_best, "success": r.success,
               "n_unobservable": sum(u["kind"] == "unobservable" for u in unobs),
               "n_weak": sum(u["kind"] == "weak" for u in unobs), "unobservable": unobs}
        if case.truth is not None:
            row.update(calibration_errors(case, r))
        rows[form] = row
    return rows


def format_rows(rows: dict) -> str:
    """The comparison as a fixed-width table."""
    truth = any("tangential_radial_rms_m_s" in r for r in rows.values())
    head = (f"{'formulation':<12}{'objective':>12}{'max viol':>10}{'iter':>6}{'iter mean':>10}{'time s':>8}"
            f"{'at best':>9}{'unobs':>7}{'weak':>6}")
    if truth:
        head += f"{'tang rms mm/s':>15}{'lever rms mm':>14}"
    lines = [head]
    for form, r in rows.items():
        line = (f"{form:<12}{r['objective']:>12.5g}{r['max_constraint_violation']:>10.1e}{r['iterations_best']:>6d}"
                f"{r['iterations_mean']:>10.1f}{r['time_s']:>8.2f}{r['fraction_at_best']:>9.2f}"
                f"{r['n_unobservable']:>7d}{r['n_weak']:>6d}")
        if truth:
            line += f"{1e3 * r['tangential_radial_rms_m_s']:>15.3f}{1e3 * r['lever_arm_rms_error_m']:>14.2f}"
        lines.append(line)
    return "\n".join(lines)
