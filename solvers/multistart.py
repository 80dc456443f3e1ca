"""Multistart: one NLP solver built per problem shape, many starting points.

The NLP is a CasADi dict ``{'x', 'p', 'f', 'g'}``; the solver (IPOPT by default, another
CasADi nlpsol plugin or scipy's ``least_squares``: :mod:`.nlp_methods`) is created once and
called from every start. Local solutions are grouped by objective and position; the result
says which start reached the best, how many did, and every start's record with the solver's
own status.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from threadpoolctl import threadpool_limits

from .gauss_newton import AssembledLeastSquares, GaussNewtonHessian
from .least_squares import LeastSquaresSolver
from .nlp_methods import METHODS, SolverOptions, casadi_options

AUTO_GN_SIZE = 5_000  # nonzeros of the residual Jacobian's bounding box


@dataclass(frozen=True)
class StartRecord:
    index: int
    objective: float
    iterations: int
    time_s: float
    status: str
    success: bool
    group: int = -1

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class MultistartResult:
    """Best local solution of a multistart, like scipy's OptimizeResult.

    ``success`` is the best start's solver success; ``fraction_at_best`` is the share of
    starts that reached the best objective (within ``objective_rtol``).
    """

    x: np.ndarray
    objective: float
    success: bool
    status: str
    message: str
    iterations: int
    time_s: float
    lam_g: np.ndarray
    g: np.ndarray
    starts: list = field(default_factory=list)
    n_groups: int = 0
    fraction_at_best: float = 0.0
    best_start: int = 0


def _progress(iterable, total, enabled):
    if not enabled:
        return iterable
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a declared dependency
        return iterable
    return tqdm(iterable, total=total, desc="multistart", unit="start", leave=False)


def expand_problem(nlp: dict, residuals: ca.MX, extra: dict | None = None):
    """MX problem -> SX problem (and SX versions of ``extra`` expressions of x and p)."""
    x, p = nlp["x"], nlp.get("p", ca.MX.sym("p", 0))
    extra = extra or {}
    names = ["f", "g", "residuals"] + list(extra)
    fun = ca.Function("problem", [x, p], [nlp["f"], nlp["g"], residuals] + list(extra.values())).expand()
    xs, ps = ca.SX.sym("x", x.sparsity()), ca.SX.sym("p", p.sparsity())
    out = dict(zip(names, fun(xs, ps)))
    sx_nlp = {"x": xs, "p": ps, "f": out["f"], "g": out["g"]}
    return sx_nlp, out["residuals"], {k: out[k] for k in extra}


def _assembled(residuals) -> bool:
    """An assembled Jacobian (scipy, e.g. :class:`~adcpdyn.estimators.row_jacobian.RowJacobian`), not CasADi's."""
    return residuals is not None and hasattr(type(residuals), "sparsity") and \
        not isinstance(residuals, (ca.Function, ca.SX, ca.MX))  # the type's: the pattern is built on first use


def _gauss_newton_hessian(nlp: dict, residuals, upper: bool, oracle: AssembledLeastSquares | None = None):
    """sigma J^T J as the ``hess_lag`` Function (upper triangle for IPOPT, whole for the SQP methods)."""
    if residuals is None:
        raise ValueError("residuals: required for hessian='gauss-newton' (f must be 0.5 |residuals|^2)")
    if _assembled(residuals):  # assembled per-row Jacobian (scipy): the callback
        return GaussNewtonHessian(residuals, nlp["g"].shape[0], upper=upper, oracle=oracle)
    x, p = nlp["x"], nlp.get("p", ca.MX.sym("p", 0))
    jac = residuals if isinstance(residuals, ca.Function) else \
        ca.Function("residual_jacobian", [x, p], [ca.jacobian(residuals, x)])
    # sigma J^T J as a CasADi graph: evaluated in C, threads run free
    X, P, lam_f = ca.MX.sym("x", jac.size1_in(0)), ca.MX.sym("p", jac.size1_in(1)), ca.MX.sym("lam_f")
    J = jac(X, P)
    H = ca.mtimes(J.T, J)
    return ca.Function("nlp_hess_l", [X, P, lam_f, ca.MX.sym("lam_g", nlp["g"].shape[0])],
                       [lam_f * (ca.triu(H) if upper else H)], ["x", "p", "lam_f", "lam_g"],
                       ["triu_hess_gamma_x_x" if upper else "hess_gamma_x_x"])


def resolved_hessian(options: SolverOptions, residuals=None) -> str:
    """What ``options.hessian`` means for this method and problem (``auto`` resolved)."""
    if options.hessian != "auto":
        return options.hessian
    rule = METHODS[options.method].auto
    assembled = _assembled(residuals) or isinstance(residuals, (ca.SX, ca.MX))  # or the residual vector itself
    if rule == "size":
        size = residuals.size1_out(0) * residuals.size2_out(0) if isinstance(residuals, ca.Function) else 0
        return "gauss-newton" if assembled or (residuals is not None and size > AUTO_GN_SIZE) else "exact"
    if rule == "gauss-newton":
        return "gauss-newton" if residuals is not None else "exact"
    return rule


def build_solver(nlp: dict, options: SolverOptions, name: str = "nlp", residuals=None,
                 like: ca.Function | None = None, residual_fun: ca.Function | None = None):
    """The solver of ``options.method`` for an NLP dict: a CasADi nlpsol Function, or for
    ``least_squares-*`` a :class:`~adcpdyn.solvers.least_squares.LeastSquaresSolver`
    (called the same way; it needs ``residual_fun``, (x, p) -> e as its first output).

    For the Gauss-Newton Hessian pass ``residuals``: the vector e with f = 0.5 |e|^2,
    the Function (x, p) -> de/dx, or an assembled Jacobian such as
    :class:`~adcpdyn.estimators.row_jacobian.RowJacobian`. The Lagrangian Hessian is then
    sigma J^T J (constraint curvature left out, as in CasADi's ``sysid.py`` example): a
    CasADi graph over the Jacobian Function (numeric product in C, no Python in IPOPT's
    loop: 32 starts on pool_m0 2.2 s -> 0.9 s), or for an assembled Jacobian the callback
    :class:`~adcpdyn.solvers.gauss_newton.GaussNewtonHessian`.

    ``like``: an IPOPT solver already built for the same NLP and options; its derivative
    Functions (gradient, constraint Jacobian, exact Hessian) are reused instead of being
    derived again (CasADi evaluates a Function from several threads, each call with its
    own memory). The Gauss-Newton callback is never shared.
    """
    spec = METHODS[options.method]
    if spec.family == "scipy":
        if residual_fun is None and residuals is not None and isinstance(residuals, (ca.SX, ca.MX)):
            x, p = nlp["x"], nlp.get("p", ca.MX.sym("p", 0))
            residual_fun = ca.Function("residuals", [x, p], [residuals])
            residuals = ca.Function("residual_jacobian", [x, p], [ca.jacobian(residuals, x)])
        if residual_fun is None or residuals is None:
            raise ValueError(f"SolverOptions.method: {options.method!r} solves the residuals; build_solver needs "
                             "residual_fun ((x, p) -> e) and residuals (their Jacobian)")
        return LeastSquaresSolver(nlp, residual_fun, residuals, method=options.method.split("-")[1],
                                  constraints=options.constraints, penalty_weight=options.penalty_weight,
                                  tol=options.tol, max_iter=options.max_iter)
    hessian = resolved_hessian(options, residuals)
    opts = options.ipopt() if options.method == "ipopt" else casadi_options(options, hessian)
    oracle = None
    if _assembled(residuals) and residual_fun is not None and options.method == "ipopt" and isinstance(nlp["x"], ca.MX):
        # f and its gradient from the assembled Jacobian: IPOPT never differentiates the residual graph
        oracle = AssembledLeastSquares(residual_fun, residuals)
        objective, gradient = oracle.functions(ca.Function("objective", [nlp["x"], nlp["p"]], [nlp["f"]]))
        nlp = {**nlp, "f": objective(nlp["x"], nlp["p"])}
        opts["grad_f"] = gradient
        opts["calc_lam_p"] = False  # d(Lagrangian)/dp would differentiate the residual graph after all
        like = None  # nothing of another solver's derivatives is needed
    # a Gauss-Newton Hessian that is a CasADi graph (not the assembled callback) is shared like the exact one
    share_hessian = hessian == "exact" or (hessian == "gauss-newton" and not _assembled(residuals))
    shared = [("grad_f", "nlp_grad_f"), ("jac_g", "nlp_jac_g")] + ([("hess_lag", "nlp_hess_l")] if share_hessian else [])
    if like is not None and options.method == "ipopt":
        opts.update({opt: like.get_function(fn) for opt, fn in shared if like.has_function(fn)})
    if hessian == "gauss-newton" and "hess_lag" not in opts:
        opts["hess_lag"] = _gauss_newton_hessian(nlp, residuals, upper=options.method == "ipopt", oracle=oracle)
    quiet = options.print_level == 0 and options.method != "ipopt"
    with silenced(quiet):
        solver = ca.nlpsol(name, options.method, nlp, opts)
    solver.quiet_stdout = quiet  # some plugins print whatever their options say: the driver drops it
    if "hess_lag" in opts and isinstance(opts["hess_lag"], GaussNewtonHessian):
        solver.gauss_newton_callback = opts["hess_lag"]  # the callback lives as long as its solver, no longer
    if oracle is not None:
        solver.least_squares_callbacks = (objective, gradient)  # likewise
    return solver


class _Discard(io.TextIOBase):
    def write(self, text):
        return len(text)


@contextlib.contextmanager
def silenced(quiet: bool):
    """Drop what is printed while ``quiet``: to Python's stdout (where CasADi's C++ output goes)
    and to the process's standard output (libraries inside plugins, e.g. blockSQP's qpOASES,
    call printf)."""
    if not quiet:
        yield
        return
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    saved, sink = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(sink, 1)
    try:
        with contextlib.redirect_stdout(_Discard()):
            yield
    finally:
        libc.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)
        os.close(sink)


def _casadi_error(err: Exception) -> str:
    """The informative line of a CasADi error (its last, without the source location)."""
    lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
    line = lines[-1] if lines else type(err).__name__
    return line.split(": ", 1)[1] if line.startswith(".../") and ": " in line else line


def multistart(solver: ca.Function, x0s, lbx, ubx, lbg, ubg, p, objective_rtol: float = 1e-6,
               x_scale=None, progress: bool | None = None, workers: int = 1, make_solver=None,
               warm_start: bool = False, build_s: float | None = None) -> MultistartResult:
    """Solve from every row of ``x0s``; return the best with per-start records.

    Parameters
    ----------
    solver : casadi.Function
        From :func:`build_solver`.
    x0s : (S, n) array
        Starting points.
    lbx, ubx, lbg, ubg, p : arrays
        Bounds and parameter values passed to every call.
    objective_rtol : float
        Starts whose objectives agree to this relative tolerance share a group.
    x_scale : (n,) array, optional
        Typical magnitudes of x, to compare solutions position-wise when grouping.
    progress : bool, optional
        Show a progress bar (default: when stderr is a terminal, never with ``ADCPDYN_PROGRESS=0``).
    workers : int
        Threads solving starts at once. CasADi releases the GIL while it computes, so
        threads use several cores; each thread gets its own solver from ``make_solver``
        (a solver's memory is not shared between concurrent calls).
    make_solver : callable, optional
        Builds another solver like ``solver``; required when ``workers > 1``.
    warm_start : bool
        Solve the first start alone, then give every other start its multipliers
        (``lam_x0``, ``lam_g0``); the solver must be built with IPOPT's warm start.
    build_s : float, optional
        Seconds ``solver`` took to build. Given, the first start is solved alone and the other
        workers' solvers are built only if the time their starts save exceeds what building them
        costs (a symbolic problem of a real run takes seconds to build and well under one to solve).
    """
    x0s = np.atleast_2d(np.asarray(x0s, dtype=float))
    done = run_starts(solver, x0s, lbx, ubx, lbg, ubg, p, progress=progress, workers=workers, make_solver=make_solver,
                      warm_start=warm_start, build_s=build_s)
    return combine_starts(done, x0s.shape[1], objective_rtol, x_scale)


def run_starts(solver: ca.Function, x0s, lbx, ubx, lbg, ubg, p, progress: bool | None = None, workers: int = 1,
               make_solver=None, warm_start: bool = False, indices=None, build_s: float | None = None) -> list:
    """Solve from every row of ``x0s`` (the options of :func:`multistart`): per start its record
    (index, objective, iterations, time, status, success; ``indices`` names the rows, default
    0, 1, ...) and its solution (x, lam_g, g, lam_x), for :func:`combine_starts`. Starts solved
    elsewhere (a Dask worker's share) combine the same way."""
    x0s = np.atleast_2d(np.asarray(x0s, dtype=float))
    names = np.arange(x0s.shape[0]) if indices is None else np.asarray(indices, dtype=int)
    if progress is None:
        from ..progress import progress_bar_enabled

        progress = progress_bar_enabled()
    n = x0s.shape[0]
    workers = max(1, min(int(workers), n)) if make_solver is not None else 1

    warm: dict = {}

    def solve(i, s):
        tic = time.perf_counter()
        try:
            sol = s(x0=x0s[i], lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=p, **warm)
        except RuntimeError as err:  # the solver stopped with an error: a failed start, reported as such
            n_g = np.size(lbg)
            record = dict(index=int(names[i]), objective=np.inf, iterations=-1, time_s=time.perf_counter() - tic,
                          status=f"error: {_casadi_error(err)}", success=False)
            return record, (x0s[i].copy(), np.full(n_g, np.nan), np.full(n_g, np.nan), np.full(x0s.shape[1], np.nan))
        elapsed = time.perf_counter() - tic
        try:
            stats = s.stats()
        except RuntimeError as err:  # some plugins fail to report after a failed solve
            stats = {"return_status": f"no statistics: {_casadi_error(err)}", "success": False}
        status = stats.get("return_status", stats.get("unified_return_status", "unknown"))
        f = float(sol["f"])
        record = dict(index=int(names[i]), objective=f if np.isfinite(f) else np.inf, iterations=int(stats.get("iter_count", -1)),
                      time_s=elapsed, status=str(status), success=bool(stats.get("success", False)))
        return record, (np.asarray(sol["x"]).ravel(), np.asarray(sol["lam_g"]).ravel(), np.asarray(sol["g"]).ravel(),
                        np.asarray(sol["lam_x"]).ravel())

    with silenced(getattr(solver, "quiet_stdout", False)):  # plugins that print whatever they are told
        first = []
        if n > 1 and (warm_start or (build_s is not None and workers > 1)):
            first = [solve(0, solver)]
            if warm_start:
                warm.update(lam_x0=first[0][1][3], lam_g0=first[0][1][1])
            if not worth_building(first[0][0]["time_s"], n - 1, workers, build_s):
                workers = 1
        solvers = [solver] + [make_solver() for _ in range(workers - 1)]
        todo = range(len(first), n)
        if workers == 1:
            done = first + [solve(i, solver) for i in _progress(todo, len(todo), progress)]
        else:
            import queue
            from concurrent.futures import ThreadPoolExecutor, as_completed

            idle = queue.Queue()
            for s in solvers:
                idle.put(s)

            def task(i):
                s = idle.get()
                try:
                    return solve(i, s)
                finally:
                    idle.put(s)

            with ThreadPoolExecutor(workers) as pool, one_blas_thread():
                futures = [pool.submit(task, i) for i in todo]
                done = first + [f.result() for f in _progress(as_completed(futures), len(todo), progress)]
    return done


def one_blas_thread():
    """BLAS on one thread while the starts run in threads of their own: numpy's and scipy's OpenBLAS otherwise
    keep a thread per core busy beside the workers on products too small to share (the 24 screened starts of a
    10^5-ping pool_m0 calibration: 3.5 s on one worker, 3.9 s on two; 2.2 s on two with one BLAS thread)."""
    return threadpool_limits(limits=1, user_api="blas")


def worth_building(per_start_s: float, starts: int, workers: int, build_s: float | None) -> bool:
    """Whether ``workers - 1`` more solvers, each costing ``build_s`` to build, save more on
    ``starts`` starts of ``per_start_s`` each than they cost (always, when the cost is unknown)."""
    if build_s is None or workers < 2:
        return True
    return starts * per_start_s * (1.0 - 1.0 / workers) > build_s * (workers - 1)


def combine_starts(done: list, n_x: int, objective_rtol: float = 1e-6, x_scale=None) -> MultistartResult:
    """The best of the starts ``done`` (:func:`run_starts`' records and solutions, from one process or
    several), every start's record with its group of agreeing solutions."""
    done.sort(key=lambda item: item[0]["index"])
    records = [d[0] for d in done]
    sols = [d[1] for d in done]

    objectives = np.array([r["objective"] for r in records])
    ok = np.array([r["success"] for r in records])
    # Prefer successful starts; a failed start only wins if nothing converged.
    order = np.lexsort((objectives, ~ok))
    best = int(order[0])
    scale = np.ones(n_x) if x_scale is None else np.asarray(x_scale, dtype=float)
    groups: list[tuple[float, np.ndarray]] = []
    for i in order:
        f, x = objectives[i], sols[i][0] / scale
        for gi, (gf, gx) in enumerate(groups):
            if np.isfinite(f) and abs(f - gf) <= objective_rtol * max(1.0, abs(gf)) and np.max(np.abs(x - gx)) < 1e-2:
                records[i]["group"] = gi
                break
        else:
            records[i]["group"] = len(groups)
            groups.append((f, x))
    f_best = objectives[best]
    at_best = np.zeros(len(records), dtype=bool)
    if np.isfinite(f_best):
        at_best = np.isfinite(objectives) & (np.abs(objectives - f_best) <= objective_rtol * max(1.0, abs(f_best)))
    x, lam_g, g, _ = sols[best]
    return MultistartResult(
        x=x,
        objective=float(f_best),
        success=bool(records[best]["success"]),
        status=records[best]["status"],
        message=f"best of {len(records)} starts: {records[best]['status']}; "
                f"{int(at_best.sum())} reached it, {len(groups)} distinct local solutions",
        iterations=records[best]["iterations"],
        time_s=float(sum(r["time_s"] for r in records)),
        lam_g=lam_g,
        g=g,
        starts=[StartRecord(**r) for r in records],
        n_groups=len(groups),
        fraction_at_best=float(at_best.mean()),
        best_start=best,
    )
