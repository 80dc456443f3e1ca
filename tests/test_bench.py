"""Benchmark helpers (the suites themselves run under `make bench`; targets are never asserted)."""

from __future__ import annotations

import numpy as np
import pytest

from adcpdyn.benchmarks.suites import run
from adcpdyn.benchmarks.scale import growth_exponent
from adcpdyn.solvers.linear_solvers import probe_linear_solver

TOL_EXPONENT = 1e-9


def test_growth_exponent_recovers_a_power_law():
    n = np.array([100, 1000, 10000])
    b, a = growth_exponent(n, 3.0 * n**1.3)
    assert abs(b - 1.3) < TOL_EXPONENT and abs(a - 3.0) < 1e-6


def test_mumps_loads_and_a_missing_solver_says_why():
    ok, note = probe_linear_solver("mumps")
    assert ok, note
    ok, note = probe_linear_solver("no_such_solver")
    assert not ok and note


def test_unknown_suite_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="suite"):
        run("everything", True, tmp_path)
