"""Diagnosis models with the recorded numbers as parameters, and their graphs kept by shape
(issue 25 item 1): a model built on another run of the same shape takes the kept graph only when it
computes the same residuals, and then gives what a model built from scratch gives."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest
from conftest import real, without_pings

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators import model_cache
from adcpdyn.estimators.diagnosis.base import base_from
from adcpdyn.estimators.diagnosis.config import DiagnosisConfig
from adcpdyn.estimators.diagnosis.field_errors import inject
from adcpdyn.estimators.diagnosis.model import GapModel, Pins
from adcpdyn.estimators.measurement_model import EffectTerm, SurveyModel
from adcpdyn.models.effects import get_effect

CONFIG = DiagnosisConfig(navigation="random_walk")


def _case(seconds=20.0, seed=4):
    sc = get_scenario("diag_boat")
    return simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=seconds)), seed=seed)


def _at(model: GapModel, z: np.ndarray, sigma: float = 0.05):
    e, raw, J = model.residuals_at(z, model.weights({k: sigma for k in model.sigma_keys}))
    return np.asarray(e).ravel(), np.asarray(raw).ravel(), np.asarray(ca.densify(J))


def _start(model: GapModel, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)  # a velocity that changes from ping to ping, every unknown off zero
    return model.start({n: 0.1 * rng.normal() for n in model.names}) / model.scale


def _sampled_real_case():
    from adcpdyn import api

    case = api.import_file(real("winriver02_transect.PD0")).case
    return without_pings(case, np.arange(case.pings.n) >= 80)  # 80 pings: the sensor's samples, differenced fixes


@pytest.mark.parametrize("source", ["model", pytest.param("samples", marks=pytest.mark.slow)])  # 7.2 s
def test_recorded_numbers_as_parameters_are_the_constants_they_replace(source):
    """The measurement model with its recorded numbers as parameters (radials, ranges, depths, the
    sensor's segments, the reference's times, segments and velocities) computes, on those numbers, the
    residuals of the model with them as constants, with the motion model and with the sensor's samples."""
    case = _case() if source == "model" else _sampled_real_case()
    base = base_from([case], CONFIG)
    assert base.runs[0].attitude_source == source
    const = SurveyModel(base.runs, base.spec)
    param = SurveyModel(base.runs, base.spec, data_parameters=True)
    assert const.data_values.size == 0 and param.data_values.size > 0
    names = {n.split("/", 1)[1].split(" ")[0] for n, _ in param.data_layout}
    assert {"bt_beam1", "depth", "reference_north", "reference"} <= names
    assert ("segments" in names) == (source == "samples") and ("heading" in names) == (source == "model")
    f_const = ca.Function("c", [const.x], [const.raw])
    f_param = ca.Function("p", [param.x, param.data_sym], [param.raw])
    x = np.random.default_rng(3).normal(scale=0.1, size=const.x.shape[0]) * const.unknowns.scale
    x = np.clip(x, const.unknowns.lower, const.unknowns.upper)
    np.testing.assert_allclose(np.asarray(f_param(x, param.data_values)), np.asarray(f_const(x)), rtol=1e-13, atol=1e-13)


def test_a_model_on_another_runs_numbers_takes_the_kept_graph_and_gives_a_fresh_builds_numbers(monkeypatch):
    """A field error written into the recorded channels (a compass offset turns the sensor's headings, a
    bed moves the reference) changes numbers, not the graph: the model takes the clean run's graph, solver
    and Jacobian, and its residuals and Jacobian at random unknowns equal those of a model built from
    scratch with no cache. A calibration pinned at another value changes the graph: refused, built anew."""
    model_cache.clear()
    clean = _case()
    terms = [EffectTerm(get_effect("compass_offset"))]
    first = GapModel(base_from([clean], CONFIG), terms, solver=CONFIG.solver)
    assert model_cache.stats()["misses"] == 1
    errored = inject(inject(clean, "compass_offset_deg", 3.0), "moving_bed_m_s", 0.2)
    base = base_from([errored], CONFIG)
    kept = GapModel(base, terms, solver=CONFIG.solver)
    assert model_cache.stats()["hits"] == 1 and kept.jacobian_fun is first.jacobian_fun
    assert kept.solver is not first.solver  # a solver of its own: never called from two threads at once
    assert not np.array_equal(kept.data, first.data)  # the same graph, other numbers
    monkeypatch.setenv(model_cache.CACHE_ENV, "0")
    fresh = GapModel(base, terms, solver=CONFIG.solver)
    assert fresh.jacobian_fun is not first.jacobian_fun
    z = _start(fresh)
    for a, b in zip(_at(kept, z), _at(fresh, z)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    sigma = {k: 0.05 for k in fresh.sigma_keys}
    fits = [m.solve(m.start({})[None, :], sigma) for m in (kept, fresh)]
    np.testing.assert_allclose(fits[0].x, fits[1].x, rtol=1e-8, atol=1e-10)
    assert fits[0].status == fits[1].status
    monkeypatch.delenv(model_cache.CACHE_ENV)
    name = next(n for n in ("P_x", "P_y", "P_z") if n in first.names)
    pinned = dataclasses.replace(base, pins=Pins({**base.pins.values, name: 0.3}, "test"))
    repinned = dataclasses.replace(base, pins=Pins({**base.pins.values, name: 0.2}, "test"))
    at_03 = GapModel(pinned, terms, solver=CONFIG.solver)
    before = model_cache.stats()
    at_02 = GapModel(repinned, terms, solver=CONFIG.solver)
    after = model_cache.stats()
    assert after["rejected"] == before["rejected"] + 2 and after["hits"] == before["hits"]  # neither kept one fits
    assert at_02.jacobian_fun is not at_03.jacobian_fun
    monkeypatch.setenv(model_cache.CACHE_ENV, "0")
    for a, b in zip(_at(at_02, z), _at(GapModel(repinned, terms, solver=CONFIG.solver), z)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_a_kept_graph_at_another_reference_shift_is_the_model_built_there(monkeypatch):
    """A model that took a kept graph moves its reference rows to another delay on its own numbers: its
    residuals and Jacobian there equal those of the model built from scratch at that delay."""
    model_cache.clear()
    terms = [EffectTerm(get_effect("reference_latency"))]
    GapModel(base_from([_case()], CONFIG), terms, solver=CONFIG.solver)
    base = base_from([inject(_case(), "moving_bed_m_s", 0.2)], CONFIG)
    kept = GapModel(base, terms, solver=CONFIG.solver)
    assert model_cache.stats()["hits"] == 1
    moved = kept.at_reference_shift(0.7)
    monkeypatch.setenv(model_cache.CACHE_ENV, "0")
    built = GapModel(base.at_delays(reference_shift_s=0.7), terms, solver=CONFIG.solver)
    z = _start(built)
    for a, b in zip(_at(moved, z), _at(built, z)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-10)


def test_a_graph_another_model_took_outlives_graphs_no_model_took(monkeypatch):
    """Over its capacity the cache drops the least recently used graph no model has taken: the clean run's
    graph, taken by an injected run, survives a run of other shapes."""
    model_cache.clear()
    monkeypatch.setenv(model_cache.CACHE_ENV, "2")
    clean = _case()
    GapModel(base_from([clean], CONFIG), solver=CONFIG.solver)
    GapModel(base_from([inject(clean, "moving_bed_m_s", 0.2)], CONFIG), solver=CONFIG.solver)  # takes it
    assert model_cache.stats()["hits"] == 1
    for seconds in (16.0, 18.0):  # other lengths: graphs of other shapes, each kept, never taken
        GapModel(base_from([_case(seconds)], CONFIG), solver=CONFIG.solver)
    assert model_cache.stats()["kept"] == 2
    GapModel(base_from([inject(clean, "compass_offset_deg", 2.0)], CONFIG), solver=CONFIG.solver)
    assert model_cache.stats()["hits"] == 2


def test_the_cache_size_is_read_in_one_line(monkeypatch):
    monkeypatch.setenv(model_cache.CACHE_ENV, "many")
    with pytest.raises(ValueError, match=r"\$ADCPDYN_MODEL_CACHE: expected a whole number of models to keep, got 'many'"):
        model_cache.capacity()
