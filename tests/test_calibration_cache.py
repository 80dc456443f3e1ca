"""Calibration problems with the recorded numbers as NLP parameters, their graphs kept by shape
(issue 25 item 1): a problem on another case's numbers takes a kept graph only when that graph computes
its own residuals, constraints, lever arms and angles, and then solves to what a problem built from
scratch solves to."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators import model_cache
from adcpdyn.estimators.calibration.config import CalibrationConfig
from adcpdyn.estimators.calibration.problem import CalibrationProblem

CONFIG = CalibrationConfig(n_starts=2, seed=1, workers=1, moving_bed="off")


@pytest.fixture(scope="module")
def case():
    return simulate(get_scenario("pool_m1"), seed=1)


def _solved(case, config=CONFIG):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = CalibrationProblem(case, config)
        return problem, problem.solve()


def _with_radials(case, radials):
    return dataclasses.replace(case, pings=dataclasses.replace(case.pings, bt_radial_m_s=radials))


def test_a_case_on_other_numbers_takes_the_kept_graph_and_solves_as_a_fresh_build(case, monkeypatch):
    model_cache.clear()
    first, _ = _solved(case)
    assert not first.assembled and first.graph == "built" and model_cache.stats()["misses"] == 1
    noisier = _with_radials(case, case.pings.bt_radial_m_s + np.random.default_rng(2).normal(0, 0.01, (case.pings.n, 4)))
    kept, r_kept = _solved(noisier)
    assert kept.graph == "kept" and model_cache.stats()["hits"] == 1 and r_kept.to_dict()["solver"]["graph"] == "kept"
    assert kept.jacobian_fun is first.jacobian_fun and kept.solver is not first.solver  # a solver of its own
    assert not np.array_equal(kept.parameters(), first.parameters())  # the same graph, other numbers
    monkeypatch.setenv(model_cache.CACHE_ENV, "0")
    fresh, r_fresh = _solved(noisier)
    assert fresh.graph == "built" and fresh.jacobian_fun is not first.jacobian_fun
    np.testing.assert_allclose(r_kept.x, r_fresh.x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(r_kept.x_se, r_fresh.x_se, rtol=1e-7)
    assert r_kept.objective == pytest.approx(r_fresh.objective, rel=1e-10)
    assert r_kept.multistart.status == r_fresh.multistart.status


def test_a_graph_with_other_constants_is_rejected_not_taken(case):
    """The instrument's sound speed is a constant of the bottom-track graph, as are the ping times: a case
    differing there has the same shape but another graph, and builds its own."""
    model_cache.clear()
    CalibrationProblem(case, CONFIG)
    slower = dataclasses.replace(case, instrument=dataclasses.replace(case.instrument,
                                                                      sound_speed_m_s=0.97 * case.instrument.sound_speed_m_s))
    assert CalibrationProblem(slower, CONFIG).graph == "built"
    assert model_cache.stats()["rejected"] == 1 and model_cache.stats()["hits"] == 0
    later = dataclasses.replace(case, pings=dataclasses.replace(case.pings, time_s=case.pings.time_s + 0.01))
    assert CalibrationProblem(later, CONFIG).graph == "built" and model_cache.stats()["hits"] == 0


def test_an_assembled_problem_keeps_its_numbers_as_constants(case):
    problem = CalibrationProblem(case, dataclasses.replace(CONFIG, jacobian="assembled"))
    assert problem.graph == "assembled" and np.array_equal(problem.parameters(), problem.weights())


def test_a_process_keeps_a_few_calibration_graphs(monkeypatch):
    """Symbolic calibration graphs reach tens of MB: at most KEPT_GRAPHS of them stay, whatever the cache's size."""
    from adcpdyn.estimators.calibration.problem import KEPT_GRAPHS

    monkeypatch.delenv(model_cache.CACHE_ENV, raising=False)
    model_cache.clear()
    sc = get_scenario("pool_m1")
    for seconds in range(10, 10 + 2 * (KEPT_GRAPHS + 2), 2):  # runs of other lengths: graphs of other shapes
        case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=float(seconds))), seed=1)
        assert CalibrationProblem(case, CONFIG).graph == "built"
    assert model_cache.stats()["kept"] == KEPT_GRAPHS < model_cache.capacity()
