"""The multistart driver's choice of NLP solver: validation, the scipy least-squares adapter
against closed forms, failures reported not raised, and a calibration by SQP reaching IPOPT's optimum."""

from __future__ import annotations

import warnings

import casadi as ca
import numpy as np
import pytest

from adcpdyn.solvers import nlp_methods
from adcpdyn.solvers.least_squares import LeastSquaresSolver
from adcpdyn.solvers.multistart import SolverOptions, build_solver, multistart


@pytest.mark.parametrize("changes, field", [
    ({"method": "no_such_solver"}, "method"),
    ({"method": "fatrop", "hessian": "gauss-newton"}, "hessian"),
    ({"method": "alpaqa", "hessian": "exact"}, "hessian"),
    ({"method": "sqpmethod", "qpsol": "no_such_qp"}, "qpsol"),
    ({"method": "sqpmethod", "warm_start": True}, "warm_start"),
    ({"method": "least_squares-trf", "constraints": "ignore"}, "constraints"),
    ({"method": "least_squares-trf", "penalty_weight": 0.0}, "penalty_weight"),
    ({"method": "least_squares-lm", "jit": True}, "jit"),
    ({"tol": -1.0}, "tol"),
])
def test_bad_solver_options_name_the_field(changes, field):
    with pytest.raises(ValueError, match=rf"^SolverOptions\.{field}: ") as err:
        SolverOptions(**changes)
    assert "\n" not in str(err.value)


def test_a_solver_missing_from_the_casadi_build_is_refused_with_the_reason(monkeypatch):
    monkeypatch.setattr(nlp_methods.ca, "has_nlpsol", lambda name: name != "fatrop")
    with pytest.raises(ValueError, match=r"^SolverOptions\.method: 'fatrop' is not in this CasADi build "
                                         r"\(casadi\.has_nlpsol\('fatrop'\) is False\)"):
        SolverOptions(method="fatrop")
    monkeypatch.setattr(nlp_methods.ca, "has_conic", lambda name: name != "osqp")
    with pytest.raises(ValueError, match=r"^SolverOptions\.qpsol: 'osqp' is not in this CasADi build"):
        SolverOptions(method="sqpmethod", qpsol="osqp")
    SolverOptions(method="ipopt", qpsol="osqp")  # the QP solver is not used by IPOPT: not checked


def _linear_problem(seed=0, m=40, n=6):
    """min 0.5 |A x - b|^2 s.t. C x = d, and its KKT solution (bounds far away)."""
    rng = np.random.default_rng(seed)
    A, b = rng.standard_normal((m, n)), rng.standard_normal(m)
    C, d = rng.standard_normal((2, n)), rng.standard_normal(2)
    K = np.block([[A.T @ A, C.T], [C, np.zeros((2, 2))]])
    sol = np.linalg.solve(K, np.concatenate([A.T @ b, d]))
    x, p = ca.SX.sym("x", n), ca.SX.sym("p", 0)
    e = ca.mtimes(ca.DM(A), x) - ca.DM(b)
    nlp = {"x": x, "p": p, "f": 0.5 * ca.sumsqr(e), "g": ca.mtimes(ca.DM(C), x)}
    res = ca.Function("e", [x, p], [e])
    jac = ca.Function("J", [x, p], [ca.jacobian(e, x)])
    return nlp, res, jac, d, sol[:n], sol[n:]


@pytest.mark.parametrize("method", ["trf", "lm"])
def test_least_squares_with_eliminated_equalities_reaches_the_kkt_solution(method):
    nlp, res, jac, d, x_kkt, _ = _linear_problem()
    solver = LeastSquaresSolver(nlp, res, jac, method=method, constraints="eliminate", tol=1e-12)
    n = x_kkt.size
    out = solver(x0=np.zeros(n), lbx=np.full(n, -100.0), ubx=np.full(n, 100.0), lbg=d, ubg=d, p=np.zeros(0))
    assert solver.stats()["success"]
    assert np.max(np.abs(out["x"] - x_kkt)) < 1e-9
    assert np.max(np.abs(out["g"] - d)) < 1e-12


def test_least_squares_penalty_violation_is_the_multiplier_over_the_weight():
    """The exterior penalty's stationarity: grad f + mu C^T (C x - d) = 0 against the KKT
    grad f + C^T lam = 0 gives C x - d -> lam / mu (to first order in 1/mu)."""
    nlp, res, jac, d, x_kkt, lam = _linear_problem(seed=1)
    mu, n = 1e8, x_kkt.size
    solver = LeastSquaresSolver(nlp, res, jac, method="lm", constraints="penalty", penalty_weight=mu, tol=1e-14)
    out = solver(x0=np.zeros(n), lbx=np.full(n, -np.inf), ubx=np.full(n, np.inf), lbg=d, ubg=d, p=np.zeros(0))
    assert np.allclose(out["g"] - d, lam / mu, rtol=1e-4, atol=1e-14)


def test_least_squares_holds_fixed_unknowns_and_trf_keeps_bounds():
    nlp, res, jac, d, _, _ = _linear_problem(seed=2)
    n = 6
    lbx, ubx = np.full(n, -0.05), np.full(n, 0.05)
    lbx[0] = ubx[0] = 0.01  # held
    out = LeastSquaresSolver(nlp, res, jac, constraints="penalty", tol=1e-10)(
        x0=np.zeros(n), lbx=lbx, ubx=ubx, lbg=d, ubg=d, p=np.zeros(0))
    assert out["x"][0] == 0.01 and np.all(out["x"] >= lbx) and np.all(out["x"] <= ubx)


def test_eliminating_inequalities_is_a_clear_error():
    nlp, res, jac, d, _, _ = _linear_problem()
    solver = LeastSquaresSolver(nlp, res, jac)
    with pytest.raises(ValueError, match=r"^SolverOptions\.constraints: 'eliminate' needs equality constraints"):
        solver(x0=np.zeros(6), lbx=-np.ones(6), ubx=np.ones(6), lbg=d - 1, ubg=d, p=np.zeros(0))


def test_a_solver_error_is_a_failed_start_with_its_reason():
    class Broken:
        def __call__(self, **kw):
            raise RuntimeError("Error in Function::call for 's'\n.../casadi/core/x.cpp:12: Cannot load 'libhsl.so'")

        def stats(self):
            return {}

    ms = multistart(Broken(), np.zeros((2, 3)), -np.ones(3), np.ones(3), np.zeros(1), np.zeros(1), np.zeros(0),
                    progress=False)
    assert not ms.success and ms.objective == np.inf
    assert [s.status for s in ms.starts] == ["error: Cannot load 'libhsl.so'"] * 2


def test_trial_points_out_of_the_models_domain_are_the_starts_status_not_a_warning_per_point(capfd):
    # sqrt(x) + x^2 from x = 1: IPOPT's Newton step lands at x < 0, where f is NaN, again and again
    x = ca.MX.sym("x")
    nlp = {"x": x, "p": ca.MX.sym("p", 0), "f": ca.sqrt(x) + x**2, "g": ca.MX(0, 1)}
    for level in (0, 1):
        solver = build_solver(nlp, SolverOptions(hessian="exact", print_level=level, max_iter=30))
        ms = multistart(solver, np.ones((1, 1)), -np.ones(1), np.ones(1), np.zeros(0), np.zeros(0), np.zeros(0),
                        progress=False)
        captured = capfd.readouterr()
        assert ("NaN detected" in captured.out + captured.err) == (level > 0)
        assert not ms.success and ms.starts[0].status != "Solve_Succeeded"


def test_least_squares_method_without_residuals_is_a_clear_error():
    nlp, *_ = _linear_problem()
    with pytest.raises(ValueError, match=r"^SolverOptions\.method: 'least_squares-trf' solves the residuals"):
        build_solver(nlp, SolverOptions(method="least_squares-trf"))


def test_sqpmethod_calibration_reaches_ipopts_optimum(pool_m0):
    """The same small simulated calibration by IPOPT and by sqpmethod (qrqp, Gauss-Newton):
    one optimum, to the tolerance, each with its own status."""
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.calibration.config import CalibrationConfig
    from adcpdyn.estimators.calibration.problem import calibrate

    case = simulate(pool_m0, seed=2)
    out = {}
    for method in ("ipopt", "sqpmethod"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[method] = calibrate(case, CalibrationConfig(n_starts=2, seed=1, workers=1,
                                                            solver=SolverOptions(method=method)))
    ip, sq = out["ipopt"], out["sqpmethod"]
    assert ip.success and sq.success
    assert sq.multistart.status == "Solve_Succeeded"  # sqpmethod's own words
    assert abs(sq.objective - ip.objective) <= 1e-7 * abs(ip.objective)
    se = ip.x_se
    ok = np.isfinite(se) & (se > 0)
    assert np.max(np.abs(sq.x - ip.x)[ok] / se[ok]) < 1e-2
    assert sq.max_constraint_violation < 1e-9


def test_another_workers_solver_is_built_only_when_it_pays():
    """With the solver's build time known, the first start is solved alone and a second worker's
    solver is built only if the starts it takes save more than building it costs."""
    import time as _time

    from adcpdyn.solvers.multistart import run_starts, worth_building

    class Fake:  # a solver that takes 10 ms a start
        def __call__(self, x0, **kw):
            _time.sleep(0.01)
            return {"f": float(np.sum(x0**2)), "x": x0, "lam_g": np.zeros(0), "g": np.zeros(0), "lam_x": 0 * x0}

        def stats(self):
            return {"return_status": "Solve_Succeeded", "success": True, "iter_count": 1}

    built = []
    make = lambda: built.append(1) or Fake()
    x0s = np.arange(16.0).reshape(8, 2)
    args = (x0s, -np.inf, np.inf, np.zeros(0), np.zeros(0), np.zeros(0))
    done = run_starts(Fake(), *args, progress=False, workers=2, make_solver=make, build_s=5.0)
    assert built == [] and sorted(d[0]["index"] for d in done) == list(range(8))
    run_starts(Fake(), *args, progress=False, workers=2, make_solver=make, build_s=1e-4)
    assert built == [1]
    run_starts(Fake(), *args, progress=False, workers=2, make_solver=make)  # cost unknown: built as before
    assert built == [1, 1]
    assert worth_building(1.0, 7, 2, 3.0) and not worth_building(0.5, 7, 2, 2.0) and worth_building(0.1, 1, 2, None)


def test_starts_in_worker_threads_run_blas_on_one_thread():
    """While starts run in threads of their own, numpy's and scipy's BLAS take one thread each (their own
    threads would spin beside the workers); a lone worker leaves BLAS as it was, and so does the end."""
    from threadpoolctl import threadpool_info

    from adcpdyn.solvers.multistart import run_starts

    def blas_threads():
        return sorted({lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"})

    seen = []

    class Recording:
        def __call__(self, x0, **kw):
            seen.append(blas_threads())
            return {"f": float(np.sum(x0**2)), "x": x0, "lam_g": np.zeros(0), "g": np.zeros(0), "lam_x": 0 * x0}

        def stats(self):
            return {"return_status": "Solve_Succeeded", "success": True, "iter_count": 1}

    before = blas_threads()
    x0s = np.arange(8.0).reshape(4, 2)
    args = (x0s, -np.inf, np.inf, np.zeros(0), np.zeros(0), np.zeros(0))
    run_starts(Recording(), *args, progress=False, workers=2, make_solver=Recording)
    assert seen == [[1]] * 4 and blas_threads() == before
    seen.clear()
    run_starts(Recording(), *args, progress=False, workers=1, make_solver=Recording)
    assert seen == [before] * 4


def test_the_gauss_newton_hessian_is_dense_only_for_few_velocity_columns():
    """J^T J formed dense from an assembled Jacobian's blocks for a few thousand unknowns whose runs
    hold few velocity columns each (knots: twenty transects, 1897 unknowns, 42.5 s dense, 49.2 s
    sparse), sparse where one run holds thousands (a velocity per ping: an 830-ping transect 90 s
    dense, 5.5 s sparse) or beyond 3000 unknowns."""
    from types import SimpleNamespace

    from adcpdyn.solvers.gauss_newton import dense_gram

    def jacobian(n, knot_columns):
        return SimpleNamespace(n_z=n, gram_and_gradient=None, max_knot_columns=knot_columns)

    assert dense_gram(jacobian(1897, 96)) and dense_gram(jacobian(200, 0))
    assert not dense_gram(jacobian(2540, 2490))
    assert not dense_gram(jacobian(3001, 90))
    assert not dense_gram(SimpleNamespace(n_z=10))  # no blocks to form it from



def test_a_best_that_one_start_alone_reached_is_said_to_be_unconfirmed():
    from adcpdyn.estimators.calibration.problem import lone_best
    from adcpdyn.solvers.multistart import combine_starts

    def starts(objectives, xs):
        return [(dict(index=i, objective=f, iterations=10, time_s=0.1, status="Solve_Succeeded", success=True),
                 (np.array(x, dtype=float), np.zeros(0), np.zeros(0), np.zeros(2)))
                for i, (f, x) in enumerate(zip(objectives, xs))]

    spread = combine_starts(starts([4.0, 1.0, 3.0, 2.0], [[0, 0], [1, 0], [2, 0], [3, 0]]), 2)
    assert spread.best_start == 1 and spread.n_groups == 4
    assert "only 1 of 4 starts reached the best objective, the others ended at 3 other" in lone_best(spread)
    confirmed = combine_starts(starts([1.0, 1.0, 3.0, 2.0], [[1, 0], [1, 0], [2, 0], [3, 0]]), 2)
    assert lone_best(confirmed) is None  # two starts agree on the best
    assert lone_best(combine_starts(starts([1.0, 2.0, 3.0], [[1, 0], [2, 0], [3, 0]]), 2)) is None  # too few starts
