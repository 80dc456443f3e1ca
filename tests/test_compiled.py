"""The per-machine cache of compiled per-ping models (solvers/compiled.py) and the calibration
that uses it: the same numbers as interpreted, derivatives included, one compilation per model."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from adcpdyn.cases.scenario import get_scenario
from adcpdyn.cases.simulation import simulate
from adcpdyn.estimators.calibration.config import CalibrationConfig
from adcpdyn.estimators.calibration.problem import CalibrationProblem
from adcpdyn.solvers import compiled

pytestmark = pytest.mark.skipif(not compiled.available(), reason="no C compiler")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(compiled.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache"


def _model() -> ca.Function:
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    return ca.Function("ping_model", [x, p], [ca.sin(x) * ca.exp(p[0]), ca.dot(x, x) * p[1]], ["x", "p"], ["y", "z"])


def test_compiled_model_and_its_gradient_equal_the_interpreted_ones(cache):
    f = _model()
    g = compiled.compiled(f, reverse=True)
    assert g.class_name() == "External" and g.name_in() == f.name_in() and g.name_out() == f.name_out()
    x0, p0 = np.array([0.3, -1.2, 2.0]), np.array([0.1, -0.7])
    for a, b in zip(f(x0, p0), g(x0, p0)):
        assert np.max(np.abs(np.asarray(a) - np.asarray(b))) < 1e-15
    X, P = ca.MX.sym("X", 3), ca.MX.sym("P", 2)
    grads = []
    for fun in (f, g):  # a solver's gradient: reverse mode through the model, over a map of pings
        y, z = fun.map(4)(ca.repmat(X, 1, 4), ca.repmat(P, 1, 4))
        grads.append(ca.Function("grad", [X, P], [ca.gradient(ca.sumsqr(y) + ca.sum2(z), ca.vertcat(X, P))])(x0, p0))
    assert np.max(np.abs(np.asarray(grads[0]) - np.asarray(grads[1]))) < 1e-12


def test_one_compilation_per_model_kept_in_the_named_folder(cache):
    f = _model()
    compiled.compiled(f)
    (lib,) = compiled.entries()
    assert lib.parent == cache and lib.name.startswith("ping_model_")
    stamp = lib.stat().st_mtime_ns
    compiled.compiled(_model())  # the same model built again: loaded, not compiled
    assert compiled.entries() == [lib] and lib.stat().st_mtime_ns == stamp
    compiled.compiled(f, reverse=True)  # another library: the model with its derivative
    assert len(compiled.entries()) == 2
    assert not list(cache.glob(".build-*"))  # no half-built library left behind
    assert compiled.clear() == 2 and compiled.entries() == []


def test_a_model_built_again_gets_the_loaded_library_until_the_cache_is_cleared(cache):
    """The same expressions built twice: one library loaded once, the same Function object (CasADi keeps
    its derivatives with it); another folder or a cleared cache loads (and builds) it again."""
    first = compiled.compiled(_model(), reverse=True)
    assert compiled.compiled(_model(), reverse=True) is first
    assert compiled.compiled(_model()) is not first  # without the reverse derivative: another library
    compiled.clear()
    again = compiled.compiled(_model(), reverse=True)
    assert again is not first and len(compiled.entries()) == 1
    x0, p0 = np.array([0.3, -1.2, 2.0]), np.array([0.1, -0.7])
    assert all(np.array_equal(np.asarray(a), np.asarray(b)) for a, b in zip(first(x0, p0), again(x0, p0)))


def test_without_a_compiler_the_interpreted_model_is_returned(cache, monkeypatch):
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    f = _model()
    assert compiled.compiled(f) is f and "no C compiler" in compiled.last_failure
    assert compiled.entries() == []


def test_compile_always_needs_the_assembled_jacobian():
    with pytest.raises(ValueError, match=r"CalibrationConfig.compile \(--compile\).*expected jacobian \(--jacobian\) "
                                         r"'assembled', got 'auto'"):
        CalibrationConfig(compile="always")


@pytest.mark.parametrize("scenario, attitude", [("pool_m0", "model"),
                                               pytest.param("deep_ship", "model", marks=pytest.mark.slow),  # 5.5 s
                                               ("diag_boat", "samples")])
def test_compiled_calibration_problem_equals_the_interpreted_one(cache, scenario, attitude):
    """Residuals, assembled Jacobian, J^T J and the NLP's gradient (the solver's reverse sweep through
    the compiled bottom-track, attitude and reference models) of the same problem, compiled and not."""
    sc = get_scenario(scenario)
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=25.0)), seed=2)
    problems = {c: CalibrationProblem(case, CalibrationConfig(n_starts=1, seed=1, jacobian="assembled", compile=c,
                                                              attitude=attitude, workers=1))
                for c in ("always", "never")}
    assert compiled.entries(), "the compiled problem built no library"
    z = problems["never"].start_points(2, 1)[1]
    w = problems["never"].weights()
    out = {}
    for c, pr in problems.items():
        x, p = pr.nlp["x"], pr.nlp["p"]
        grad = ca.Function("grad", [x, p], [ca.gradient(pr.nlp["f"], x)])(z, w)
        out[c] = (np.asarray(pr.residual_fun(z, w)[0]).ravel(), pr.jacobian_fun(z, w).toarray(),
                  pr.jacobian_fun.gram(z, w), np.asarray(grad).ravel())
    for a, b in zip(out["always"], out["never"]):
        assert np.max(np.abs(a - b)) <= 1e-12 * max(np.max(np.abs(b)), 1.0)
    e, J = out["never"][0], out["never"][1]
    assert np.max(np.abs(out["always"][3] - J.T @ e)) <= 1e-9 * np.max(np.abs(J.T @ e))  # f = |e|^2 / 2


def test_calibrate_help_states_the_compile_threshold():
    from adcpdyn.cli.parser import build_parser
    from adcpdyn.estimators.calibration.problem import COMPILE_MIN_PINGS

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["calibrate"]
    text = next(a.help for a in sub._actions if a.dest == "compile")
    assert f"{COMPILE_MIN_PINGS} pings or more" in text


def test_a_compiler_refusing_native_code_builds_portable_libraries(cache, tmp_path, monkeypatch):
    """-march=native where the compiler takes it, the portable flags where it does not (the
    library's name changes with the flags, so neither is mistaken for the other)."""
    real = compiled.compiler()
    fussy = tmp_path / "fussy-cc"
    fussy.write_text(f'#!/bin/sh\nfor a in "$@"; do [ "$a" = "-march=native" ] && exit 1; done\nexec {real} "$@"\n')
    fussy.chmod(0o755)
    assert compiled._flags_for(str(fussy)) == compiled.PORTABLE_FLAGS
    native_path = compiled.library_path(_model())[0]
    monkeypatch.setenv("CC", str(fussy))
    f = compiled.compiled(_model())
    assert isinstance(f, ca.Function)
    if compiled._flags_for(real) == compiled.NATIVE_FLAGS:
        assert compiled.library_path(_model())[0] != native_path
    x, p = np.array([0.3, -1.2, 2.0]), np.array([0.5, -2.0])
    assert np.allclose(np.asarray(f(x, p)[0]).ravel(), np.sin(x) * np.exp(0.5), rtol=1e-15, atol=0)
    assert [e.name for e in compiled.entries()] == [compiled.library_path(_model())[0].name]


def test_compiled_diagnosis_model_equals_the_interpreted_one(cache, monkeypatch):
    """A diagnosis's gap model (base and a catalog effect) with its per-ping models compiled, as
    diagnose builds it, and interpreted: residuals and Jacobian at the same point."""
    from adcpdyn.estimators.diagnosis import model as gap
    from adcpdyn.estimators.diagnosis.base import base_from
    from adcpdyn.estimators.diagnosis.config import DiagnosisConfig
    from adcpdyn.models.effects import get_effect

    sc = get_scenario("diag_boat")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=20.0)), seed=3)
    config = DiagnosisConfig(navigation="random_walk")
    base = base_from([case], config)
    out = {}
    for threshold in (0, None):
        monkeypatch.setattr(gap, "GAP_COMPILE_MIN_PINGS", threshold)
        m = gap.GapModel(base, [get_effect("moving_bed")], solver=config.solver)
        assert m.model.compiled == (threshold is not None)
        z = m.start({}) / m.scale + 0.01
        e, _, J = m.residuals_at(z, m.weights(base.sigma0))
        out[threshold] = (np.asarray(e).ravel(), np.asarray(ca.densify(J)))
    assert compiled.entries(), "the compiled gap model built no library"
    for a, b in zip(out[0], out[None]):
        assert np.max(np.abs(a - b)) <= 1e-12 * max(np.max(np.abs(b)), 1.0)
