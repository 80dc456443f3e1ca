"""``adcpdyn bench solvers``: IPOPT settings and graph forms on one calibration, same run.

Every variant solves the same pool_m0 case from the same starts with the same
attitude pre-fit; rows give the set-up time (building the NLP and the solver), the
multistart's wall time, the objective reached (relative to the default's), the share of
starts at the best and the mean iterations. Times are ratios to the default measured
in the same run.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .common import Target, machine, print_targets, save_figure, timed_calibration
from ..solvers.multistart import SolverOptions


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
        proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                cwd=cwd, start_new_session=True)
        try:
            out, _ = proc.communicate(timeout=time_limit_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            return None
    return json.loads(out.strip().splitlines()[-1]) if proc.returncode == 0 and out.strip() else None


def bench_solvers(starts: int, seed: int = 1, jit: bool = True, jit_time_limit_s: float = 300.0) -> dict:
    """Each variant on pool_m0 (seed ``seed``), then the 32-start multistart target."""
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
    return {"suite": "solvers", "machine": machine(), "case": "pool_m0", "seed": seed, "starts": starts,
            "linear_solvers": linear, "notes": notes, "rows": rows, "fastest": fastest, "multistart_32": ms32}


def print_solvers(res: dict) -> None:
    print(f"solvers benchmark: pool_m0 seed {res['seed']}, {res['starts']} starts, same pre-fit and starts; "
          "times from one run on a shared machine (noisy: compare the ratios)")
    print(f"{'variant':<38}{'setup s':>8}{'solve s':>8}{'ratio':>7}{'rel obj':>10}{'at best':>8}{'iter':>7}{'ok':>4}")
    for name, r in res["rows"].items():
        print(f"{name:<38}{r['setup_s']:>8.2f}{r['solve_s']:>8.2f}{r['solve_time_ratio']:>7.2f}"
              f"{r['objective_rel_to_default']:>10.1e}{r['fraction_at_best']:>8.2f}{r['iterations_mean']:>7.1f}"
              f"{'yes' if r['success'] else 'no':>4}")
    for note in res["notes"]:
        print(f"  note: {note}")
    print("\n32-start multistart on pool_m0 (fresh problem: set-up includes the attitude pre-fit)")
    for name, m in res["multistart_32"].items():
        print(f"  {name:<38} set-up {m['setup_s']:.2f} s, solve {m['solve_s']:.2f} s, at best {m['fraction_at_best']:.2f}")
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
    fig, ax = plt.subplots(figsize=(9, 0.45 * len(names) + 1.5))
    y = np.arange(len(names))
    ax.barh(y, setup, color="C7", label="set-up (NLP + solver build)")
    ax.barh(y, solve, left=setup, color="C0", label=f"{res['starts']}-start multistart")
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("seconds (one run, shared 2-core machine)")
    ax.legend(fontsize=8)
    ax.set_title(f"IPOPT variants on pool_m0 seed {res['seed']}")
    fig.tight_layout()
    save_figure(fig, path)
