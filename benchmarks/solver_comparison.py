"""The NLP solvers the multistart driver offers, on one calibration NLP: a single run (pool_m0)
and a 4-transect river survey, same starts, same tolerance.

Each solver (:data:`~adcpdyn.solvers.nlp_methods.METHODS`, with the QP solvers this CasADi
build has) is built on the NLP of a default :class:`CalibrationProblem` and run from the
problem's own starts with the first noise guess, one start at a time, in a child process
of its own (a plugin that crashes or outlasts the time limit costs its row, not the run).
Rows: the best start's success and status in the solver's words, the share of starts that
succeeded, the objective against the best feasible one of any solver, the constraint and
bound violations of its solution, mean iterations, solver set-up and solve wall time, the
solve time as a ratio to IPOPT's in the same run, and the share of starts reaching the best.
"""

from __future__ import annotations

import dataclasses
import json
import time

import numpy as np

from ..solvers.multistart import SolverOptions
from .common import json_from_child
from ..solvers.nlp_methods import METHODS, NOT_OFFERED, QPSOLS, availability, qp_availability

CASES = {"single run": "pool_m0 (one run, 627 residuals, 25 unknowns)",
         "survey": "river_survey, 4 transects (~1600 pings, assembled Jacobian)"}
OBJECTIVE_RTOL = 1e-6  # starts within this of the best objective reached it
FEASIBLE = 1e-9  # a solution defines the best only if its constraint and bound violations are below this
BASE = "ipopt"
# each solver on one thread of BLAS: multithreaded OpenBLAS on a shared 2-core machine made one 643 x 16 SVD
# (scipy's TRF step) take 4.7 ms instead of 0.2 ms
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def variants() -> tuple[dict, list]:
    """({label: (SolverOptions, what it solves)}, [not measured: (name, reason)]) for this build."""
    rows, skipped = {}, []

    def add(label, what, **kw):
        rows[label] = (SolverOptions(**kw), what)

    for name in METHODS:
        ok, why = availability(name)
        if not ok:
            skipped.append((name, why))
    for name, why in NOT_OFFERED.items():
        ok, build = availability(name)
        skipped.append((name, why if ok else f"{build}; {why}"))
    qps = [q for q in QPSOLS if qp_availability(q)[0]]
    skipped += [(f"QP solver {q}", qp_availability(q)[1]) for q in QPSOLS if q not in qps]
    have = lambda m: availability(m)[0]  # noqa: E731
    if have("ipopt"):
        add(BASE, "the NLP; Gauss-Newton Hessian, MUMPS (the default)")
    if have("sqpmethod"):
        for q in qps:
            add(f"sqpmethod + {q}", "the NLP; Gauss-Newton Hessian", method="sqpmethod", qpsol=q)
        if "qrqp" in qps:
            add("sqpmethod + qrqp, exact Hessian", "the NLP; exact Hessian, eigenvalues clipped",
                method="sqpmethod", hessian="exact")
            add("sqpmethod + qrqp, L-BFGS", "the NLP; limited-memory BFGS", method="sqpmethod", hessian="limited-memory")
    if have("feasiblesqpmethod") and "qrqp" in qps:
        add("feasiblesqpmethod + qrqp", "the NLP; Gauss-Newton Hessian, feasible iterates", method="feasiblesqpmethod")
    for name, what in (("blocksqp", "the NLP; damped BFGS, one block"), ("fatrop", "the NLP; exact Hessian, no structure"),
                       ("uno", "the NLP; exact Hessian, Uno's default preset"), ("alpaqa", "the NLP; ALM + PANOC (L-BFGS)")):
        if have(name):
            add(name, what, method=name)
    kept, free = "bounds kept", "bounds dropped"
    elim = "equalities eliminated (pivoted QR; eliminated unknowns' bounds not enforced)"
    pen = f"quadratic penalty {SolverOptions().penalty_weight:g} |g - c|^2 (objective reported without it)"
    add("least_squares trf, eliminated", f"residuals, {elim}, other {kept}", method="least_squares-trf")
    add("least_squares lm, eliminated", f"residuals, {elim}, all {free}", method="least_squares-lm")
    add("least_squares trf, penalty", f"residuals + {pen}, {kept}", method="least_squares-trf", constraints="penalty")
    add("least_squares lm, penalty", f"residuals + {pen}, {free}", method="least_squares-lm", constraints="penalty")
    return rows, skipped


def _cases(key: str, seed: int):
    from ..cases.scenario import get_scenario
    from ..cases.simulation import simulate
    from .survey import _transects

    if key == "single run":
        return simulate(get_scenario("pool_m0"), seed=seed)
    return _transects(4, seed, fast=True)


def measure(problem, options: SolverOptions, starts: int, seed: int) -> dict:
    """One solver on a built CalibrationProblem's NLP from its starts (one at a time)."""
    from ..solvers.multistart import build_solver, multistart

    options = dataclasses.replace(options, expand=problem.solver_options.expand)  # an assembled problem stays MX
    tic = time.perf_counter()
    solver = build_solver(problem.nlp, options, "calibration", residuals=problem.jacobian_fun,
                          residual_fun=problem.residual_fun)
    setup = time.perf_counter() - tic
    lbz, ubz = problem.lbx / problem.scale, problem.ubx / problem.scale
    tic = time.perf_counter()
    ms = multistart(solver, problem.start_points(starts, seed), lbz, ubz, problem.lbg, problem.ubg, problem.parameters(),
                    workers=1, progress=False)
    solve = time.perf_counter() - tic
    x = ms.x * problem.scale
    g = np.asarray(ms.g, dtype=float)
    g_viol = float(np.max(np.abs(g - np.clip(g, problem.lbg, problem.ubg)), initial=0.0)) if g.size else 0.0
    box_viol = float(np.max(np.maximum(np.maximum(problem.lbx - x, x - problem.ubx), 0.0), initial=0.0))
    return {"setup_s": setup, "solve_s": solve, "objective": ms.objective, "success": ms.success, "status": ms.status,
            "g_violation": g_viol, "box_violation": box_viol,
            "starts": [{"objective": s.objective, "success": s.success, "status": s.status, "iterations": s.iterations,
                        "time_s": s.time_s} for s in ms.starts]}


def _child(key: str, seed: int, starts: int, options: str) -> None:
    """Entry of one solver's run in its own process: the problem built, the solver measured."""
    import warnings

    from ..estimators.calibration.config import CalibrationConfig
    from ..estimators.calibration.problem import CalibrationProblem

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = CalibrationProblem(_cases(key, seed), CalibrationConfig(n_starts=starts, seed=seed, workers=1))
        row = measure(problem, SolverOptions(**json.loads(options)), starts, seed)
    print(json.dumps(row))


def _run_child(key, seed, starts, options: SolverOptions, time_limit_s: float, why_limit: str = "") -> dict:
    """The row from a child process on one BLAS thread, or ``{"error": reason}`` (crash, time limit)."""
    code = (f"from adcpdyn.benchmarks.solver_comparison import _child; "
            f"_child({key!r}, {seed}, {starts}, {json.dumps(json.dumps(dataclasses.asdict(options)))})")
    row, why = json_from_child(code, time_limit_s, env=ONE_THREAD)
    return row if row is not None else {"error": why + (why_limit if why.startswith("did not finish") else "")}


def _summarise(rows: dict) -> dict:
    """Objective against the best feasible one, starts at the best, time ratio to IPOPT."""
    ok = {k: r for k, r in rows.items() if "error" not in r}
    feasible = [r["objective"] for r in ok.values()
                if r["success"] and r["g_violation"] <= FEASIBLE and r["box_violation"] <= FEASIBLE]
    best = min(feasible) if feasible else np.inf
    base = rows.get(BASE, {}).get("solve_s")
    for r in ok.values():
        objs = np.array([s["objective"] for s in r["starts"]])
        r["best_objective"] = best
        r["objective_rel_to_best"] = (r["objective"] - best) / abs(best) if np.isfinite(best) else np.nan
        r["fraction_at_best"] = float(np.mean(np.abs(objs - best) <= OBJECTIVE_RTOL * abs(best))) if np.isfinite(best) else 0.0
        r["fraction_success"] = float(np.mean([s["success"] for s in r["starts"]]))
        its = [s["iterations"] for s in r["starts"] if s["iterations"] >= 0]
        r["iterations_mean"] = float(np.mean(its)) if its else None
        r["solve_ratio_to_ipopt"] = r["solve_s"] / base if base else np.nan
    return rows


def bench_solver_comparison(starts: int, seed: int = 1, time_limit_s: float = 600.0, slowdown: float = 50.0,
                            cases=tuple(CASES)) -> dict:
    """Every offered solver on each case (children, one at a time), with what was not measured.

    IPOPT runs first; every other solver's process is stopped after twice IPOPT's whole process
    time (imports, simulation, problem and solver set-up) plus ``slowdown`` times IPOPT's solve
    time (at least a minute, at most ``time_limit_s``): a solver that much slower is reported as
    not finishing rather than waited for."""
    table, skipped = variants()
    out = {"starts": starts, "seed": seed, "time_limit_s": time_limit_s, "slowdown": slowdown,
           "objective_rtol": OBJECTIVE_RTOL, "feasible": FEASIBLE, "tolerance": SolverOptions().tol,
           "not_measured": [{"solver": n, "reason": r} for n, r in skipped], "cases": {}}
    for key in cases:
        rows, limit, why = {}, time_limit_s, ""
        for label, (options, what) in table.items():
            tic = time.perf_counter()
            row = _run_child(key, seed, starts, options, limit, why)
            rows[label] = {"solves": what, "options": dataclasses.asdict(options), **row}
            if label == BASE and "error" not in row:
                limit = min(time_limit_s, max(60.0, 2 * (time.perf_counter() - tic) + slowdown * row["solve_s"]))
                why = f" (twice IPOPT's process time plus {slowdown:g}x its solve time)"
        out["cases"][key] = {"description": CASES[key], "rows": _summarise(rows), "time_limit_s": limit}
    return out


def _fmt(v, spec):
    return "n/a" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


def comparison_lines(res: dict, markdown: bool = False) -> list:
    """The comparison as text lines (a table per case), plain or GitHub markdown."""
    head = ["solver", "best start: status", "ok starts", "rel obj", "g viol", "box viol", "iter", "set-up s",
            "solve s", "t/IPOPT", "at best"]
    lines = []
    for key, case in res["cases"].items():
        lines.append(f"{key}: {case['description']}; {res['starts']} starts, seed {res['seed']}, tol {res['tolerance']:g}")
        body = []
        for label, r in case["rows"].items():
            if "error" in r:
                body.append([label, f"not measured: {r['error']}"] + [""] * (len(head) - 2))
                continue
            ok_starts = f"{int(round(r['fraction_success'] * len(r['starts'])))}/{len(r['starts'])}"
            body.append([label, f"{'ok' if r['success'] else 'FAILED'}: {r['status']}", ok_starts,
                         _fmt(r["objective_rel_to_best"], ".1e"), _fmt(r["g_violation"], ".0e"),
                         _fmt(r["box_violation"], ".0e"), _fmt(r["iterations_mean"], ".1f"), _fmt(r["setup_s"], ".2f"),
                         _fmt(r["solve_s"], ".2f"), _fmt(r["solve_ratio_to_ipopt"], ".2f"), _fmt(r["fraction_at_best"], ".2f")])
        if markdown:
            lines += ["", "| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
            lines += ["| " + " | ".join(str(c).replace("|", "/") for c in row) + " |" for row in body]
        else:
            w = [max(len(str(row[i])) for row in body + [head]) for i in range(len(head))]
            w[1] = min(w[1], 44)
            lines.append("  ".join(h.ljust(w[i]) if i < 2 else h.rjust(w[i]) for i, h in enumerate(head)))
            for row in body:
                cells = [str(c) for c in row]
                cells[1] = cells[1][:44]
                lines.append("  ".join(c.ljust(w[i]) if i < 2 else c.rjust(w[i]) for i, c in enumerate(cells)))
        lines.append("")
    what = {label: r["solves"] for case in res["cases"].values() for label, r in case["rows"].items()}
    lines.append("what each row solves:" if not markdown else "What each row solves:")
    lines += [f"- {label}: {w}" if markdown else f"  {label}: {w}" for label, w in what.items()]
    lines.append("" if markdown else "")
    lines.append("not measured:" if not markdown else "Not measured:")
    lines += [f"- {n}: {r}" if markdown else f"  {n}: {r}" for n, r in ((s["solver"], s["reason"]) for s in res["not_measured"])]
    return lines
