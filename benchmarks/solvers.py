"""``adcpdyn bench solvers``: IPOPT settings and graph forms on one calibration, then the other
NLP solvers the driver offers (:mod:`.solver_comparison`), same run.

Every IPOPT variant solves the same pool_m0 case from the same starts with the same
attitude pre-fit; rows give the set-up time (building the NLP and the solver), the
multistart's wall time, the objective reached (relative to the default's), the share of
starts at the best and the mean iterations. Times are ratios to the default measured
in the same run. The tables are also written as markdown (``solvers.md``), which
``--readme`` puts between the solver-table markers of a page (docs/benchmarks.md).
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import Target, json_from_child, machine, print_targets, save_figure, timed_calibration
from .solver_comparison import CASES, bench_solver_comparison, comparison_lines
from ..solvers.multistart import SolverOptions

README_BEGIN = "<!-- solver-table: begin (written by adcpdyn bench solvers --readme docs/benchmarks.md) -->"
README_END = "<!-- solver-table: end -->"


def variants(linear: dict, compiler: bool) -> dict:
    """Named SolverOptions to compare with the default (Gauss-Newton Hessian for this size)."""
    base = SolverOptions()
    out = {"default (auto: GN, mumps, SX)": base,
           "limited-memory Hessian": dataclasses.replace(base, hessian="limited-memory"),
           "exact Hessian": dataclasses.replace(base, hessian="exact"),
           "no NLP scaling": dataclasses.replace(base, scaling=False),
           "warm-started multistart": dataclasses.replace(base, warm_start=True),
           "MX graph (no expand)": dataclasses.replace(base, expand=False)}
    for name, info in linear.items():
        if info["available"] and name != base.linear_solver:
            out[f"linear solver {name}"] = dataclasses.replace(base, linear_solver=name)
    if compiler:
        out[JIT] = dataclasses.replace(base, jit=True)
    return out


JIT = "jit-compiled (gcc -O1)"


def _row(case, fit, starts, seed, opts: SolverOptions) -> dict:
    r, setup, solve = timed_calibration(case, fit=fit, n_starts=starts, seed=seed, solver=opts)
    ms = r.multistart
    return {"options": dataclasses.asdict(opts), "setup_s": setup, "solve_s": solve,
            "objective": r.objective, "success": r.success, "fraction_at_best": ms.fraction_at_best,
            "iterations_mean": float(np.mean([s.iterations for s in ms.starts])),
            "start_time_mean_s": float(np.mean([s.time_s for s in ms.starts]))}


def _child(starts: int, seed: int, options: str) -> None:
    """Entry of a variant run in its own process (compilation may outlast its time limit)."""
    from ..cases.scenario import get_scenario
    from ..estimators.attitude_fit import fit_attitude
    from ..cases.simulation import simulate

    case = simulate(get_scenario("pool_m0"), seed=seed)
    print(json.dumps(_row(case, fit_attitude(case, max_modes=3), starts, seed, SolverOptions(**json.loads(options)))))


def _row_in_child(starts, seed, opts: SolverOptions, time_limit_s: float) -> dict | None:
    """The variant's row from a child process, or None when it fails or outlasts the limit
    (the child's whole process group, compiler included, is then killed)."""
    code = f"from adcpdyn.benchmarks.solvers import _child; _child({starts}, {seed}, {json.dumps(json.dumps(dataclasses.asdict(opts)))})"
    with tempfile.TemporaryDirectory(prefix="adcpdyn_jit_") as cwd:  # the C source and objects land here
        return json_from_child(code, time_limit_s, cwd=cwd)[0]


def bench_solvers(starts: int, seed: int = 1, jit: bool = True, jit_time_limit_s: float = 300.0,
                  compare_starts: int = 8, compare_slowdown: float = 50.0, compare_cases=None) -> dict:
    """Each IPOPT variant on pool_m0 (seed ``seed``), the 32-start multistart target, then every
    offered solver on pool_m0 and a 4-transect survey (``compare_starts`` starts each;
    :func:`~adcpdyn.benchmarks.solver_comparison.bench_solver_comparison`)."""
    from ..cases.scenario import get_scenario
    from ..estimators.attitude_fit import fit_attitude
    from ..cases.simulation import simulate
    from ..solvers.linear_solvers import available_linear_solvers

    case = simulate(get_scenario("pool_m0"), seed=seed)
    fit = fit_attitude(case, max_modes=3)
    linear = available_linear_solvers()
    compiler = shutil.which("gcc") or shutil.which("cc")
    notes = [f"linear solver {n}: {i['note']}" for n, i in linear.items() if not i["available"]]
    if not compiler:
        notes.append("no C compiler found: code generation not measured")
    elif not jit:
        notes.append("code generation not measured in quick mode (compile time; see the full run)")
    rows = {}
    for name, opts in variants(linear, bool(compiler) and jit).items():
        if name != JIT:
            rows[name] = _row(case, fit, starts, seed, opts)
            continue
        row = _row_in_child(starts, seed, opts, jit_time_limit_s)  # own process: compile time is bounded
        if row is None:
            notes.append(f"{JIT}: set-up (C compilation) did not finish within {jit_time_limit_s:.0f} s, against a "
                         f"default solve of {rows[next(iter(rows))]['solve_s']:.1f} s: code generation does not pay here")
        else:
            rows[name] = row
    base = rows[next(iter(rows))]
    for row in rows.values():
        row["objective_rel_to_default"] = (row["objective"] - base["objective"]) / max(abs(base["objective"]), 1e-300)
        row["solve_time_ratio"] = row["solve_s"] / base["solve_s"]
    fastest = min((n for n in rows if rows[n]["success"] and abs(rows[n]["objective_rel_to_default"]) < 1e-6
                   and rows[n]["fraction_at_best"] >= 0.9), key=lambda n: rows[n]["solve_s"])
    ms32 = {}
    for name in dict.fromkeys([next(iter(rows)), fastest]):
        r, setup, solve = timed_calibration(case, fit=None, n_starts=32, seed=seed,
                                            solver=SolverOptions(**rows[name]["options"]))
        ms32[name] = {"setup_s": setup, "solve_s": solve, "wall_s": setup + solve,
                      "fraction_at_best": r.multistart.fraction_at_best, "objective": r.objective}
    comparison = bench_solver_comparison(compare_starts, seed=seed, slowdown=compare_slowdown,
                                         cases=compare_cases or tuple(CASES))
    return {"suite": "solvers", "machine": machine(), "date": time.strftime("%Y-%m-%d"), "case": "pool_m0", "seed": seed,
            "starts": starts,
            "linear_solvers": linear, "notes": notes, "rows": rows, "fastest": fastest, "multistart_32": ms32,
            "comparison": comparison}


def ipopt_lines(res: dict) -> list:
    """The IPOPT-settings table and its notes as text lines."""
    lines = [f"solvers benchmark: pool_m0 seed {res['seed']}, {res['starts']} starts, same pre-fit and starts; "
             "times from one run on a shared machine (noisy: compare the ratios)",
             f"{'variant':<38}{'setup s':>8}{'solve s':>8}{'ratio':>7}{'rel obj':>10}{'at best':>8}{'iter':>7}{'ok':>4}"]
    for name, r in res["rows"].items():
        lines.append(f"{name:<38}{r['setup_s']:>8.2f}{r['solve_s']:>8.2f}{r['solve_time_ratio']:>7.2f}"
                     f"{r['objective_rel_to_default']:>10.1e}{r['fraction_at_best']:>8.2f}{r['iterations_mean']:>7.1f}"
                     f"{'yes' if r['success'] else 'no':>4}")
    lines += [f"  note: {note}" for note in res["notes"]]
    lines.append("\n32-start multistart on pool_m0 (fresh problem: set-up includes the attitude pre-fit)")
    lines += [f"  {name:<38} set-up {m['setup_s']:.2f} s, solve {m['solve_s']:.2f} s, at best {m['fraction_at_best']:.2f}"
              for name, m in res["multistart_32"].items()]
    return lines


def markdown_solvers(res: dict, command: str) -> str:
    """Both tables as markdown, with the command, date and machine that produced them."""
    m = res["machine"]
    c = res["comparison"]
    out = [f"Written by `{command}` on {res.get('date', '?')} ({m['cpus']} CPUs shared with other work, "
           f"CasADi {m['casadi']}, Python {m['python']}); times are one run's: compare the ratios.", "",
           "IPOPT settings:", "", "```", *ipopt_lines(res), "",
           *[f"[{'met' if t['met'] else 'NOT met'}] {t['target']}: {t['value']:.4g}" for t in res.get("targets", [])],
           "```", "",
           f"The NLP solvers of the multistart driver (`SolverOptions(method=...)`), each in a process of its own, one "
           f"start at a time on one BLAS thread, stopped after twice IPOPT's process time plus {c['slowdown']:g}x its "
           f"solve time; rel obj against the best "
           f"objective of any solver whose solution meets the constraints and bounds to {c['feasible']:g}; at best: "
           f"share of starts within {c['objective_rtol']:g} of it; g viol in metres (lever-arm constraints), box viol "
           "in each unknown's unit; iter: the solver's own count (least_squares: Jacobian evaluations; n/a: not reported); "
           "t/IPOPT: solve time over IPOPT's; status as each solver words it (fatrop: its return code, 0 = converged).",
           ""]
    out += comparison_lines(c, markdown=True)
    return "\n".join(out) + "\n"


def print_solvers(res: dict) -> None:
    print("\n".join(ipopt_lines(res)))
    print("\nNLP solvers of the multistart driver (each in its own process, one start at a time)")
    print("\n".join(comparison_lines(res["comparison"])))
    targets = []
    for name, m in res["multistart_32"].items():
        targets.append(Target(f"32-start multistart on pool_m0 < 2 s, solve only [{name}]", m["solve_s"], m["solve_s"] < 2.0))
        targets.append(Target(f"32-start multistart on pool_m0 < 2 s, set-up + solve [{name}]", m["wall_s"], m["wall_s"] < 2.0))
    print_targets(res, targets)


def figure_solvers(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(res["rows"])
    setup = [res["rows"][n]["setup_s"] for n in names]
    solve = [res["rows"][n]["solve_s"] for n in names]
    comp = res["comparison"]["cases"]
    solvers = list(dict.fromkeys(k for case in comp.values() for k in case["rows"]))
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(15, 0.3 * max(len(names), len(solvers)) + 2.0))
    y = np.arange(len(names))
    ax.barh(y, setup, color="C7", label="set-up (NLP + solver build)")
    ax.barh(y, solve, left=setup, color="C0", label=f"{res['starts']}-start multistart")
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("wall time (s; one run, shared 2-core machine)")
    ax.legend(fontsize=8)
    ax.set_title(f"IPOPT variants on pool_m0 seed {res['seed']}")
    y = np.arange(len(solvers))
    for k, (key, case) in enumerate(comp.items()):
        ratio = [case["rows"].get(n, {}).get("solve_ratio_to_ipopt", np.nan) for n in solvers]
        ok = [bool(case["rows"].get(n, {}).get("success")) and case["rows"][n].get("fraction_at_best", 0) > 0
              for n in solvers]
        bars = bx.barh(y + 0.4 * k - 0.2, ratio, height=0.4, color=f"C{k}", label=key)
        for bar, good in zip(bars, ok):
            if not good:
                bar.set_hatch("//")
        for yi, n in zip(y, solvers):
            if "error" in case["rows"].get(n, {}):
                bx.text(1.05, yi + 0.4 * k - 0.2, "not measured (time limit or crash)", va="center", fontsize=8,
                        color=f"C{k}")
    bx.axvline(1.0, color="k", lw=0.8)
    bx.set_xscale("log")
    bx.set_yticks(y, solvers, fontsize=8)
    bx.invert_yaxis()
    bx.set_xlabel("solve time / IPOPT's (ratio; hatched: failed, or no start at the best)")
    bx.legend(fontsize=8)
    bx.set_title(f"NLP solvers, {res['comparison']['starts']} starts")
    fig.tight_layout()
    save_figure(fig, path)
