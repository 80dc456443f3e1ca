"""Shared pieces of the benchmark suites: machine record, targets, JSON and figures."""

from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np


def machine() -> dict:
    """CPU count, platform and the versions that matter for the figures."""
    return {"python": platform.python_version(), "casadi": ca.__version__, "numpy": np.__version__,
            "machine": platform.machine(), "cpus": os.cpu_count(), "platform": platform.platform()}


@dataclass(frozen=True)
class Target:
    """One issue target: label, measured value and whether it was met."""

    label: str
    value: float
    met: bool

    def to_dict(self) -> dict:
        return {"target": self.label, "value": float(self.value), "met": bool(self.met)}


def print_targets(res: dict, targets: list[Target]) -> None:
    """Print verdicts and store them in ``res["targets"]`` (never asserted)."""
    print("\ntargets")
    for t in targets:
        print(f"  [{'met' if t.met else 'NOT met'}] {t.label}: {t.value:.4g}")
    res["targets"] = [t.to_dict() for t in targets]


def timed_calibration(case, fit=None, **config):
    """(result, setup seconds, solve seconds) of one calibration, warnings silenced."""
    from ..estimators.calibration.problem import CalibrationConfig, CalibrationProblem

    tic = time.perf_counter()
    problem = CalibrationProblem(case, CalibrationConfig(**config), fit=fit)
    setup = time.perf_counter() - tic
    tic = time.perf_counter()
    result = problem.solve()
    return result, setup, time.perf_counter() - tic


def write_json(res: dict, path: Path) -> None:
    """The suite's figures as JSON, written atomically."""
    from ..cases.atomic import atomic_path
    from ..estimators.calibration.result import jsonable

    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(jsonable(res), fh, indent=2)


def save_figure(fig, path: Path) -> None:
    """Save a matplotlib figure atomically and close it."""
    import matplotlib.pyplot as plt

    from ..cases.atomic import atomic_path

    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
