"""The NLP solvers the multistart driver can use, and each one's options from :class:`SolverOptions`.

CasADi ships several solvers that fit a bound- and equality-constrained least-squares NLP;
scipy's ``least_squares`` solves the same residuals with the constraints eliminated or
penalised (:mod:`.least_squares`). Each entry says which Hessians it takes and whether it
needs a QP solver; :func:`casadi_options` turns the shared settings (tolerance, iterations,
Hessian) into the plugin's own option names.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class Method:
    """One solver the driver can use.

    ``hessians``: the ``SolverOptions.hessian`` values it takes besides ``auto``;
    ``auto``: what ``auto`` means for it (``size`` = the driver's rule: Gauss-Newton above
    ``AUTO_GN_SIZE``, else exact); ``qpsol``: whether ``SolverOptions.qpsol`` is used.
    """

    name: str
    family: str  # "casadi" (an nlpsol plugin) or "scipy" (scipy.optimize.least_squares)
    hessians: tuple
    auto: str
    qpsol: bool
    summary: str


METHODS = {m.name: m for m in (
    Method("ipopt", "casadi", ("gauss-newton", "exact", "limited-memory"), "size", False,
           "interior point, filter line search"),
    Method("sqpmethod", "casadi", ("gauss-newton", "exact", "limited-memory"), "gauss-newton", True,
           "line-search SQP, one QP per iteration"),
    Method("feasiblesqpmethod", "casadi", ("gauss-newton", "exact", "limited-memory"), "gauss-newton", True,
           "trust-region SQP keeping its iterates feasible"),
    Method("blocksqp", "casadi", ("limited-memory",), "quasi-newton", False,
           "filter SQP with quasi-Newton updates (damped BFGS), qpOASES"),
    Method("fatrop", "casadi", ("exact",), "exact", False,
           "interior point for optimal-control structure, here without structure"),
    Method("uno", "casadi", ("exact",), "exact", False,
           "Uno's default: trust-region filter SQP, BQPD"),
    Method("alpaqa", "casadi", (), "quasi-newton", False,
           "augmented Lagrangian, PANOC inner solver with L-BFGS"),
    Method("least_squares-trf", "scipy", ("gauss-newton",), "gauss-newton", False,
           "scipy trust-region reflective on the residuals (bounds kept)"),
    Method("least_squares-lm", "scipy", ("gauss-newton",), "gauss-newton", False,
           "scipy Levenberg-Marquardt (MINPACK) on the residuals (no bounds)"),
)}

# shipped as CasADi plugins but not offered, and why (the benchmark lists them)
NOT_OFFERED = {
    "bonmin": "a mixed-integer front end: with no integer unknowns it solves the NLP with IPOPT",
    "scpgen": "lifted-Newton SQP: takes an MX graph with the residual vector as its objective, another problem form",
    "qrsqp": ("an older textbook SQP without a Hessian-function option (no Gauss-Newton); with its exact Hessian "
              "one of four pool_m0 starts never returned (NaN objective in its line search)"),
    "knitro": "commercial (licensed library)",
    "snopt": "commercial (licensed library)",
    "worhp": "licensed library",
    "madnlp": "Julia-based interior point",
}

JIT_OPTIONS = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"], "verbose": False}}
QPSOLS = ("qrqp", "osqp", "qpoases", "proxqp", "highs", "daqp")
CONSTRAINT_HANDLING = ("eliminate", "penalty")


def availability(name: str) -> tuple[bool, str]:
    """(loads, reason) for an NLP solver plugin of this CasADi build (scipy's always loads)."""
    if name in METHODS and METHODS[name].family == "scipy":
        return True, "scipy.optimize.least_squares"
    if ca.has_nlpsol(name):
        return True, "loads"
    return False, f"not in this CasADi build (casadi.has_nlpsol({name!r}) is False)"


def qp_availability(name: str) -> tuple[bool, str]:
    if ca.has_conic(name):
        return True, "loads"
    return False, f"not in this CasADi build (casadi.has_conic({name!r}) is False)"


def _quiet_qp(qpsol: str, verbose: bool) -> dict:
    """The QP solver's options: its printing off (unless verbose), a failed QP returned, not raised."""
    opts = {"error_on_fail": False}
    if verbose:
        return opts
    opts.update({"qrqp": {"print_iter": False, "print_header": False, "print_info": False},
                 "osqp": {"osqp": {"verbose": False}},
                 "qpoases": {"printLevel": "none"},
                 "highs": {"highs": {"output_flag": False}},
                 }.get(qpsol, {}))
    return opts


def casadi_options(options, hessian: str) -> dict:
    """``nlpsol`` options for ``options.method`` (not IPOPT: :meth:`SolverOptions.ipopt`), with
    ``hessian`` already resolved (``gauss-newton`` means a ``hess_lag`` the caller adds)."""
    m, tol, it = options.method, options.tol, options.max_iter
    verbose = options.print_level > 0
    opts = {"expand": options.expand, "print_time": False}
    if options.jit:
        opts.update(JIT_OPTIONS)
    if m in ("sqpmethod", "feasiblesqpmethod"):
        opts.update({"qpsol": options.qpsol, "qpsol_options": _quiet_qp(options.qpsol, verbose), "max_iter": it,
                     "tol_pr": tol, "tol_du": tol, "print_header": verbose, "print_iteration": verbose,
                     "print_status": verbose})
        if m == "feasiblesqpmethod":
            opts.update({"optim_tol": tol, "feas_tol": tol})
        if hessian == "limited-memory":
            opts["hessian_approximation"] = "limited-memory"
        elif hessian == "exact":  # the exact Lagrangian Hessian need not be convex
            opts["convexify_strategy"] = "eigen-clip"
    elif m == "blocksqp":
        # schur=False: qpOASES' Schur-complement mode needs an inertia-revealing sparse solver (ma27)
        opts.update({"opttol": tol, "nlinfeastol": tol, "max_iter": it, "schur": False, "block_hess": 0,
                     "hess_update": 2, "hess_lim_mem": 1 if hessian == "limited-memory" else 0,
                     "print_header": verbose, "print_iteration": verbose, "print_maxit_reached": verbose,
                     "qpsol_options": {"printLevel": "tabular" if verbose else "none"}})
    elif m == "fatrop":
        opts.update({"structure_detection": "none",
                     "fatrop": {"tol": tol, "max_iter": it, "print_level": options.print_level}})
    elif m == "uno":
        opts["uno"] = {"tolerance": tol, "max_iterations": it, "logger": "INFO" if verbose else "SILENT"}
    elif m == "alpaqa":
        opts["alpaqa"] = {"alm": {"tolerance": tol, "dual_tolerance": tol, "max_iter": it}}
    return opts
