"""IPOPT multistart: one solver built per problem shape, many starting points.

The NLP is a CasADi dict ``{'x', 'p', 'f', 'g'}``; the solver is created once and
called from every start. Local solutions are grouped by objective and position; the
result says which start reached the best, how many did, and every start's record.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .gauss_newton import GaussNewtonHessian

AUTO_GN_SIZE = 5_000  # nonzeros of the residual Jacobian's bounding box
HESSIANS = ("auto", "gauss-newton", "exact", "limited-memory")


@dataclass(frozen=True)
class SolverOptions:
    """IPOPT settings.

    Parameters
    ----------
    max_iter : int
    tol : float
        IPOPT's convergence tolerance (acceptable level: 1e3 tol, five iterations in a row).
    hessian : str
        ``auto`` (exact for tiny least-squares problems; Gauss-Newton above
        ``AUTO_GN_SIZE`` residuals x unknowns, where each iteration costs a fraction of
        an exact one: 32 starts on pool_m0 in 2.7 s instead of 4.6 s, estimates equal to
        1e-6 standard errors),
        ``gauss-newton`` (J^T J of the weighted residuals), ``exact`` or
        ``limited-memory`` (quasi-Newton).
    linear_solver : str
        IPOPT linear solver available in this CasADi build (``mumps`` ships with it).
    scaling : bool
        IPOPT's gradient-based NLP scaling.
    expand : bool
        Expand MX graphs to SX before solving (faster for small and medium problems).
    warm_start : bool
        Multistart: starts after the first begin from their own x0 but with the first
        start's multipliers and a small barrier parameter (IPOPT warm start).
    jit : bool
        Compile the NLP's functions with the system C compiler (CasADi ``jit``; the
        C source and objects are written in the working folder).
    print_level : int
    mu_init : float
        IPOPT's initial barrier parameter (its default 0.1; about 1e-5 for warm starts).
    """

    max_iter: int = 500
    tol: float = 1e-7
    hessian: str = "auto"
    linear_solver: str = "mumps"
    scaling: bool = True
    expand: bool = True
    warm_start: bool = False
    jit: bool = False
    print_level: int = 0
    mu_init: float = 0.1  # IPOPT's initial barrier; small when the start is already good (warm starts)

    def __post_init__(self):
        if self.hessian not in HESSIANS:
            raise ValueError(f"SolverOptions.hessian: expected one of {list(HESSIANS)}, got {self.hessian!r}")

    def ipopt(self) -> dict:
        opts = {
            "expand": self.expand,
            "print_time": False,
            "ipopt.print_level": self.print_level,
            "ipopt.sb": "yes",
            "ipopt.max_iter": self.max_iter,
            "ipopt.tol": self.tol,
            "ipopt.acceptable_tol": 1e3 * self.tol,
            # at the optimum of a large least-squares objective the line search stalls on round-off
            # (steps of 1e-9, f unchanged to 1e-13): five acceptable iterations in a row end it
            "ipopt.acceptable_iter": 5,
            "ipopt.hessian_approximation": "limited-memory" if self.hessian == "limited-memory" else "exact",
            "ipopt.linear_solver": self.linear_solver,
            "ipopt.nlp_scaling_method": "gradient-based" if self.scaling else "none",
            "ipopt.mu_init": self.mu_init,
        }
        if self.warm_start:
            opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                         "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
        if self.jit:  # CasADi writes the C source and the compiled objects in the working folder
            opts.update({"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"], "verbose": False}})
        return opts


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


def build_solver(nlp: dict, options: SolverOptions, name: str = "nlp", residuals=None,
                 like: ca.Function | None = None) -> ca.Function:
    """The IPOPT solver Function for an NLP dict.

    For ``hessian="gauss-newton"`` pass ``residuals``: the vector e with f = 0.5 |e|^2,
    the Function (x, p) -> de/dx, or an assembled Jacobian such as
    :class:`~adcpdyn.estimators.row_jacobian.RowJacobian`. The Lagrangian Hessian is then
    sigma J^T J (constraint curvature left out, as in CasADi's ``sysid.py`` example): a
    CasADi graph over the Jacobian Function (numeric product in C, no Python in IPOPT's
    loop: 32 starts on pool_m0 2.2 s -> 0.9 s), or for an assembled Jacobian the callback
    :class:`~adcpdyn.solvers.gauss_newton.GaussNewtonHessian`.

    ``like``: a solver already built for the same NLP and options; its derivative
    Functions (gradient, constraint Jacobian, exact Hessian) are reused instead of being
    derived again (CasADi evaluates a Function from several threads, each call with its
    own memory). The Gauss-Newton callback is never shared.
    """
    opts = options.ipopt()
    hessian = options.hessian
    assembled = residuals is not None and hasattr(residuals, "sparsity") and not isinstance(residuals, ca.Function)
    if hessian == "auto":
        size = residuals.size1_out(0) * residuals.size2_out(0) if isinstance(residuals, ca.Function) else 0
        hessian = "gauss-newton" if assembled or (residuals is not None and size > AUTO_GN_SIZE) else "exact"
    if hessian == "gauss-newton":
        if residuals is None:
            raise ValueError("residuals: required for hessian='gauss-newton' (f must be 0.5 |residuals|^2)")
        x, p = nlp["x"], nlp.get("p", ca.MX.sym("p", 0))
        jac = residuals if isinstance(residuals, ca.Function) or assembled else \
            ca.Function("residual_jacobian", [x, p], [ca.jacobian(residuals, x)])
        if isinstance(jac, ca.Function):  # sigma triu(J^T J) as a CasADi graph: evaluated in C, threads run free
            X, P, lam_f = ca.MX.sym("x", jac.size1_in(0)), ca.MX.sym("p", jac.size1_in(1)), ca.MX.sym("lam_f")
            J = jac(X, P)
            opts["hess_lag"] = ca.Function("nlp_hess_l", [X, P, lam_f, ca.MX.sym("lam_g", nlp["g"].shape[0])],
                                           [lam_f * ca.triu(ca.mtimes(J.T, J))],
                                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        else:  # assembled per-row Jacobian (scipy): the callback
            callback = GaussNewtonHessian(jac, nlp["g"].shape[0])
            opts["hess_lag"] = callback
    if like is not None:
        shared = [("grad_f", "nlp_grad_f"), ("jac_g", "nlp_jac_g")] + ([("hess_lag", "nlp_hess_l")] if hessian == "exact" else [])
        opts.update({opt: like.get_function(fn) for opt, fn in shared if like.has_function(fn)})
    solver = ca.nlpsol(name, "ipopt", nlp, opts)
    if "hess_lag" in opts and isinstance(opts["hess_lag"], GaussNewtonHessian):
        solver.gauss_newton_callback = opts["hess_lag"]  # the callback lives as long as its solver, no longer
    return solver


def multistart(solver: ca.Function, x0s, lbx, ubx, lbg, ubg, p, objective_rtol: float = 1e-6,
               x_scale=None, progress: bool | None = None, workers: int = 1, make_solver=None,
               warm_start: bool = False) -> MultistartResult:
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
        Show a progress bar (default: when stderr is a terminal).
    workers : int
        Threads solving starts at once. CasADi releases the GIL while it computes, so
        threads use several cores; each thread gets its own solver from ``make_solver``
        (a solver's memory is not shared between concurrent calls).
    make_solver : callable, optional
        Builds another solver like ``solver``; required when ``workers > 1``.
    warm_start : bool
        Solve the first start alone, then give every other start its multipliers
        (``lam_x0``, ``lam_g0``); the solver must be built with IPOPT's warm start.
    """
    x0s = np.atleast_2d(np.asarray(x0s, dtype=float))
    if progress is None:
        progress = sys.stderr.isatty()
    n = x0s.shape[0]
    workers = max(1, min(int(workers), n)) if make_solver is not None else 1
    solvers = [solver] + [make_solver() for _ in range(workers - 1)]

    warm: dict = {}

    def solve(i, s):
        tic = time.perf_counter()
        sol = s(x0=x0s[i], lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=p, **warm)
        elapsed = time.perf_counter() - tic
        stats = s.stats()
        f = float(sol["f"])
        record = dict(index=i, objective=f if np.isfinite(f) else np.inf, iterations=int(stats.get("iter_count", -1)),
                      time_s=elapsed, status=str(stats.get("return_status", "unknown")),
                      success=bool(stats.get("success", False)))
        return record, (np.asarray(sol["x"]).ravel(), np.asarray(sol["lam_g"]).ravel(), np.asarray(sol["g"]).ravel(),
                        np.asarray(sol["lam_x"]).ravel())

    first = []
    if warm_start and n > 1:
        first = [solve(0, solver)]
        warm.update(lam_x0=first[0][1][3], lam_g0=first[0][1][1])
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

        with ThreadPoolExecutor(workers) as pool:
            futures = [pool.submit(task, i) for i in todo]
            done = first + [f.result() for f in _progress(as_completed(futures), len(todo), progress)]
    done.sort(key=lambda item: item[0]["index"])
    records = [d[0] for d in done]
    sols = [d[1] for d in done]

    objectives = np.array([r["objective"] for r in records])
    ok = np.array([r["success"] for r in records])
    # Prefer successful starts; a failed start only wins if nothing converged.
    order = np.lexsort((objectives, ~ok))
    best = int(order[0])
    scale = np.ones(x0s.shape[1]) if x_scale is None else np.asarray(x_scale, dtype=float)
    groups: list[tuple[float, np.ndarray]] = []
    for i in order:
        f, x = objectives[i], sols[i][0] / scale
        for gi, (gf, gx) in enumerate(groups):
            if abs(f - gf) <= objective_rtol * max(1.0, abs(gf)) and np.max(np.abs(x - gx)) < 1e-2:
                records[i]["group"] = gi
                break
        else:
            records[i]["group"] = len(groups)
            groups.append((f, x))
    f_best = objectives[best]
    at_best = np.abs(objectives - f_best) <= objective_rtol * max(1.0, abs(f_best))
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
