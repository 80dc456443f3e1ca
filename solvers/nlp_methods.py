"""The NLP solvers the multistart driver can use, their settings (:class:`SolverOptions`) and
each one's options from them.

CasADi ships several solvers that fit a bound- and equality-constrained least-squares NLP;
scipy's ``least_squares`` solves the same residuals with the constraints eliminated or
penalised (:mod:`.least_squares`). Each entry says which Hessians it takes and whether it
needs a QP solver; :func:`casadi_options` turns the shared settings (tolerance, iterations,
Hessian) into the plugin's own option names.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

HESSIANS = ("auto", "gauss-newton", "exact", "limited-memory")
IPOPT_ONLY = {"warm_start": False}  # fields that mean something to IPOPT alone, with their inert values


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


@dataclass(frozen=True)
class SolverOptions:
    """Which NLP solver, and its settings.

    Parameters
    ----------
    method : str
        The solver (:data:`~adcpdyn.solvers.nlp_methods.METHODS`): ``ipopt``; the CasADi
        plugins ``sqpmethod``, ``feasiblesqpmethod``, ``blocksqp``, ``fatrop``,
        ``uno``, ``alpaqa``; or scipy's ``least_squares-trf`` / ``least_squares-lm`` on the
        residuals, with the constraints handled as ``constraints`` says. A plugin missing
        from the installed CasADi is refused here.
    qpsol : str
        QP solver of ``sqpmethod`` and ``feasiblesqpmethod`` (one of
        :data:`~adcpdyn.solvers.nlp_methods.QPSOLS`).
    max_iter : int
    tol : float
        Convergence tolerance, given to each solver as its own: IPOPT's ``tol`` (acceptable
        level: 1e3 tol, five iterations in a row), the SQP methods' ``tol_pr`` and
        ``tol_du`` (and ``feasiblesqpmethod``'s ``optim_tol``, ``feas_tol``), blockSQP's
        ``opttol`` and ``nlinfeastol``, fatrop's ``tol``, Uno's ``tolerance``, alpaqa's ALM
        ``tolerance`` and ``dual_tolerance``, least_squares' ``ftol``, ``xtol``, ``gtol``.
    hessian : str
        ``auto`` (IPOPT: exact for tiny least-squares problems; Gauss-Newton above
        ``multistart.AUTO_GN_SIZE`` residuals x unknowns, where each iteration costs a fraction of
        an exact one: 32 starts on pool_m0 in 2.7 s instead of 4.6 s, estimates equal to
        1e-6 standard errors; the SQP methods with a QP solver: Gauss-Newton, convex by
        construction; the others: their own, see ``METHODS``),
        ``gauss-newton`` (J^T J of the weighted residuals), ``exact`` or
        ``limited-memory`` (quasi-Newton), where the method takes it.
    linear_solver : str
        IPOPT linear solver available in this CasADi build (``mumps`` ships with it).
    scaling : bool
        IPOPT's gradient-based NLP scaling.
    expand : bool
        Expand MX graphs to SX before solving (faster for small and medium problems).
    warm_start : bool
        IPOPT multistart: starts after the first begin from their own x0 but with the first
        start's multipliers and a small barrier parameter (IPOPT warm start).
    jit : bool
        Compile the NLP's functions with the system C compiler (CasADi ``jit``; the
        C source and objects are written in the working folder).
    print_level : int
        0: the solver prints nothing (what CasADi plugins print unasked is dropped).
    mu_init : float
        IPOPT's initial barrier parameter (its default 0.1; about 1e-5 for warm starts).
    constraints : str
        ``least_squares-*``: ``eliminate`` (affine equality constraints solved for some of
        the unknowns, whose bounds are then not enforced) or ``penalty`` (a quadratic
        penalty of weight ``penalty_weight`` on the violation): :mod:`.least_squares`.
    penalty_weight : float
    """

    method: str = "ipopt"
    qpsol: str = "qrqp"
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
    constraints: str = "eliminate"
    penalty_weight: float = 1e10  # scaled problem of pool_m0: violation ~6e-8, objective -1e-7 relative

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"SolverOptions.method: expected one of {list(METHODS)}, got {self.method!r}")
        ok, why = availability(self.method)
        if not ok:
            raise ValueError(f"SolverOptions.method: {self.method!r} is {why}")
        if self.hessian not in HESSIANS:
            raise ValueError(f"SolverOptions.hessian: expected one of {list(HESSIANS)}, got {self.hessian!r}")
        spec = METHODS[self.method]
        if self.hessian != "auto" and self.hessian not in spec.hessians:
            raise ValueError(f"SolverOptions.hessian: method {self.method!r} takes one of "
                             f"{['auto', *spec.hessians]}, got {self.hessian!r}")
        if self.qpsol not in QPSOLS:
            raise ValueError(f"SolverOptions.qpsol: expected one of {list(QPSOLS)}, got {self.qpsol!r}")
        if spec.qpsol:
            ok, why = qp_availability(self.qpsol)
            if not ok:
                raise ValueError(f"SolverOptions.qpsol: {self.qpsol!r} is {why}")
        if self.constraints not in CONSTRAINT_HANDLING:
            raise ValueError(f"SolverOptions.constraints: expected one of {list(CONSTRAINT_HANDLING)}, "
                             f"got {self.constraints!r}")
        if not float(self.penalty_weight) > 0:
            raise ValueError(f"SolverOptions.penalty_weight: expected > 0, got {self.penalty_weight!r}")
        if not float(self.tol) > 0:
            raise ValueError(f"SolverOptions.tol: expected > 0, got {self.tol!r}")
        if int(self.max_iter) < 1:
            raise ValueError(f"SolverOptions.max_iter: expected >= 1, got {self.max_iter!r}")
        if self.method != "ipopt":
            for name, inert in IPOPT_ONLY.items():
                if getattr(self, name) != inert:
                    raise ValueError(f"SolverOptions.{name}: IPOPT's alone; expected {inert!r} with method "
                                     f"{self.method!r}, got {getattr(self, name)!r}")
        if spec.family == "scipy" and self.jit:
            raise ValueError(f"SolverOptions.jit: CasADi code generation; expected False with method {self.method!r}")

    def ipopt(self) -> dict:
        opts = {
            "expand": self.expand,
            "print_time": False,
            # a trial point where the model is NaN (a step out of its domain) is IPOPT's to cut back, and each
            # start's status says how it ended: CasADi's warning line per such point only alarms (print_level
            # > 0 shows them)
            "show_eval_warnings": self.print_level > 0,
            "ipopt.print_level": self.print_level,
            "ipopt.sb": "yes",
            "ipopt.max_iter": self.max_iter,
            "ipopt.tol": self.tol,
            "ipopt.acceptable_tol": 1e3 * self.tol,
            # at the optimum of a large least-squares objective the line search stalls on round-off
            # (steps of 1e-9, f unchanged to 1e-13): two acceptable iterations in a row end it
            # (five cost three more iterations per solve and moved the estimates by < 1e-5 SE on
            # pool_m1, deep_ship and a 3e4-ping pool_m0 run)
            "ipopt.acceptable_iter": 2,
            "ipopt.hessian_approximation": "limited-memory" if self.hessian == "limited-memory" else "exact",
            "ipopt.linear_solver": self.linear_solver,
            "ipopt.nlp_scaling_method": "gradient-based" if self.scaling else "none",
            "ipopt.mu_init": self.mu_init,
        }
        if self.warm_start:
            opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                         "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
        if self.jit:  # CasADi writes the C source and the compiled objects in the working folder
            opts.update(JIT_OPTIONS)
        return opts


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
    opts = {"expand": options.expand, "print_time": False, "show_eval_warnings": verbose}  # as IPOPT's
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
