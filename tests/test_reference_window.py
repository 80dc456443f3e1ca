"""A GNSS velocity differenced from two fixes is the mean velocity between them: its window in the
case file, its exact model, and the simulator writing it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from adcpdyn.cases.case import Reference
from adcpdyn.cases.io import read_case, write_case
from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators.knots import window_basis_sparse


def test_window_mean_is_exact_against_fine_quadrature():
    rng = np.random.default_rng(4)
    knots = np.cumsum(rng.uniform(0.5, 1.5, 30))
    V = rng.normal(size=knots.size)
    windows = np.array([[knots[0] - 2.0, knots[1] + 0.3],  # beyond the first knot: held constant there
                        [knots[3] + 0.1, knots[3] + 0.4],  # inside one segment
                        [knots[5] - 0.2, knots[12] + 0.7],  # over several knots
                        [knots[-2] + 0.5, knots[-1] + 3.0]])
    for (a, b), got in zip(windows, window_basis_sparse(windows, knots) @ V):
        t = np.linspace(a, b, 200001)
        assert got == pytest.approx(np.trapezoid(np.interp(t, knots, V), t) / (b - a), abs=1e-9)
    assert window_basis_sparse(windows, knots).sum(axis=1) == pytest.approx(np.ones((4, 1)))


def _positions_case(seed=1):
    sc = get_scenario("diag_boat")
    run = dataclasses.replace(sc.run, duration_s=60.0, reference_from="positions", reference_interval_s=(4.0, 6.0))
    return simulate(dataclasses.replace(sc, run=run), seed=seed)


def test_simulated_differenced_fixes_are_window_means_of_the_truth(tmp_path):
    case = _positions_case()
    ref = case.reference
    assert ref.window_s.shape == (ref.time_s.size, 2) and np.allclose(ref.window_s.mean(axis=1), ref.time_s)
    # noise-free: the mean of the true velocity over the window (a fine quadrature of the truth's samples)
    quiet = dataclasses.replace(get_scenario("diag_boat"))
    run = dataclasses.replace(quiet.run, duration_s=60.0, reference_from="positions", reference_interval_s=(4.0, 6.0),
                              noise=dataclasses.replace(quiet.run.noise, reference_m_s=0.0))
    exact = simulate(dataclasses.replace(quiet, run=run), seed=1)
    t, v = exact.pings.time_s, exact.truth.vessel_velocity_m_s
    for (a, b), got in zip(exact.reference.window_s, exact.reference.velocity_m_s):
        if a >= t[0] and b <= t[-1]:
            grid = np.linspace(a, b, 4001)
            mean = [np.trapezoid(np.interp(grid, t, v[:, j]), grid) / (b - a) for j in range(2)]
            assert got[:2] == pytest.approx(mean, abs=0.01)  # the truth sampled at the pings only
    write_case(case, tmp_path / "c.h5")
    back = read_case(tmp_path / "c.h5").reference
    np.testing.assert_array_equal(back.window_s, ref.window_s)
    assert back.shifted(0.5).window_s == pytest.approx(ref.window_s + 0.5)
    assert back.subset(np.arange(3)).window_s.shape == (3, 2)


def test_a_window_ending_before_it_starts_is_refused_in_one_line(tmp_path):
    case = _positions_case()
    w = case.reference.window_s.copy()
    w[2] = w[2, ::-1]
    with pytest.raises(ValueError, match=r"/reference/window_s: expected each window's end after its start"):
        write_case(case.replace(reference=dataclasses.replace(case.reference, window_s=w)), tmp_path / "bad.h5")
    with pytest.raises(ValueError, match=r"/reference/window_s: expected shape \(L, 2\)"):
        write_case(case.replace(reference=dataclasses.replace(case.reference, window_s=w[:, :1])), tmp_path / "bad.h5")


@pytest.mark.slow  # 7 s: `make test-slow`, CI's second step
def test_the_window_model_fits_differenced_fixes_that_a_point_model_misses():
    """A boat changing speed every 3 s, fixes every 4-6 s with 1 cm/s noise, on the base that follows it
    (a velocity per ping): read as window means the fixes fit at their noise; read as instantaneous
    samples at the windows' middles they misfit by the speed changes inside the windows."""
    from adcpdyn.estimators.diagnosis.base import fit_base
    from adcpdyn.estimators.diagnosis.config import DiagnosisConfig
    from adcpdyn.models.navigation import Navigation

    sc = get_scenario("diag_boat")
    rng = np.random.default_rng(0)
    kt = np.arange(0.0, 63.0, 3.0)
    kv = np.column_stack([rng.normal(0, 0.5, kt.size), rng.normal(0, 0.5, kt.size), np.zeros(kt.size)])
    nav = Navigation(tuple(kt), tuple(map(tuple, kv)), sc.run.navigation.speed_along_heading_m_s)
    run = dataclasses.replace(sc.run, duration_s=60.0, navigation=nav, reference_from="positions",
                              reference_interval_s=(4.0, 6.0), noise=dataclasses.replace(sc.run.noise, reference_m_s=0.01))
    case = simulate(dataclasses.replace(sc, run=run), seed=2)
    point = case.replace(reference=dataclasses.replace(case.reference, window_s=None))
    config = DiagnosisConfig(navigation="random_walk", effects=())
    level = [fit_base([c], config)[3][(0, "reference")] for c in (case, point)]
    assert level[0] < 0.02 < 0.05 < level[1]
