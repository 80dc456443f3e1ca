"""Every lever-arm formulation calibrated on one case, side by side (one row each)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ...cases.case import Case
from .config import CalibrationConfig
from .problem import CalibrationProblem
from ..formulations import FORMULATIONS


def compare_formulations(case: Case, config: CalibrationConfig, formulations=FORMULATIONS) -> dict:
    """Calibrate ``case`` once per formulation; rows keyed by formulation.

    Each row: objective, max constraint violation, wall time, iterations (best start
    and mean over starts), share of starts at the best, success, the unobservable and
    weak lever-arm directions, and, for a simulated case, the errors against truth
    (:func:`~adcpdyn.estimators.statistics.evaluation.calibration_errors`).
    """
    from ..statistics.evaluation import calibration_errors

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


FORMULATION_COLUMNS = (  # (key, header, unit, format)
    ("objective", "Obj", "-", ".5g"), ("max_constraint_violation", "MaxViol", "-", ".1e"),
    ("iterations_best", "Iter", "count", "d"), ("iterations_mean", "IterMean", "count", ".1f"),
    ("time_s", "Time", "s", ".2f"), ("fraction_at_best", "AtBest", "fraction", ".2f"),
    ("n_unobservable", "Unobs", "count", "d"), ("n_weak", "Weak", "count", "d"))
TRUTH_COLUMNS = (("tangential_radial_rms_m_s", "TangRMS", "mm/s", ".3f", 1e3), ("lever_arm_rms_error_m", "LeverRMS", "mm", ".2f", 1e3))
FORMULATION_LEGEND = ("Obj: half the noise-weighted sum of squares; MaxViol: largest constraint violation (scaled); "
                      "Iter: iterations of the best start, IterMean: over the starts; AtBest: starts at the best; "
                      "Unobs, Weak: lever-arm directions not, weakly determined")
TRUTH_LEGEND = "; TangRMS: tangential radial velocity error, LeverRMS: lever-arm error, RMS against the truth"


def format_rows(rows: dict) -> str:
    """The comparison as a fixed-width table (:func:`~adcpdyn.text.text_table`), units under the headers."""
    from ...text import Column, text_table

    truth = any("tangential_radial_rms_m_s" in r for r in rows.values())
    columns = [Column(key, head, unit, spec=spec) for key, head, unit, spec in FORMULATION_COLUMNS]
    if truth:
        columns += [Column(key, head, unit, scale=scale, spec=spec) for key, head, unit, spec, scale in TRUTH_COLUMNS]
    return text_table(rows, columns, first="formulation", legend=FORMULATION_LEGEND + (TRUTH_LEGEND if truth else ""))
