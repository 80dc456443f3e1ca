"""One size of ``adcpdyn bench scale``, run in its own process so that its peak memory is its own.

``python -m adcpdyn.benchmarks.scale_worker N_PINGS SEED [SCENARIO [STARTS]] [--save CASE.h5]`` prints one JSON line
(the scenario's run stretched to about N_PINGS pings at its own ping rate; ``pool_m0`` at ~5 Hz by default; with
STARTS, calibrated again with that many starts and the defaults otherwise; with ``--save``, the simulated case written
there). ``python -m adcpdyn.benchmarks.scale_worker --time CASE.h5`` calibrates a saved case as the first calibration
above does, in a fresh process without the simulation before it, and prints its times.
"""

from __future__ import annotations

import dataclasses
import json
import resource
import sys
import time

PING_INTERVAL_S = (0.19, 0.21)  # ~5 Hz
SCENARIO = "pool_m0"
HESSIAN = "gauss-newton"  # what "auto" picks for long runs; fixed so that every size solves the same way


def long_run(n_pings: int, scenario: str = SCENARIO):
    """pool_m0 stretched to about ``n_pings`` pings at ~5 Hz (same platform, motion and noise); another
    scenario stretched at its own ping rate."""
    from ..cases.scenario import get_scenario

    sc = get_scenario(scenario)
    interval = PING_INTERVAL_S if scenario == SCENARIO else tuple(sc.run.ping_interval_s)
    run = dataclasses.replace(sc.run, duration_s=n_pings * sum(interval) / 2, ping_interval_s=interval)
    return dataclasses.replace(sc, run=run)


def one_start(case, seed: int = 1) -> tuple:
    """(result, set-up s, solve s) of the bench's calibration: one start, one worker, the Gauss-Newton Hessian."""
    from .common import timed_calibration
    from ..solvers.multistart import SolverOptions

    return timed_calibration(case, n_starts=1, seed=seed, workers=1, solver=SolverOptions(hessian=HESSIAN))


def time_saved(path: str) -> dict:
    """The one-start calibration of a saved case, timed: its set-up, solve and iterations."""
    from ..cases.io import read_case

    r, setup, solve = one_start(read_case(path))
    return {"setup_s": setup, "solve_s": solve, "calibration_s": setup + solve, "iterations": r.multistart.iterations,
            "objective": r.objective}


def measure(n_pings: int, seed: int, scenario: str = SCENARIO, starts: int | None = None, save: str | None = None) -> dict:
    """Simulate, then calibrate (one start, one worker) and time each step; peak RSS in MB. With
    ``starts``: then calibrated again as a user's default would (that many starts, the default
    workers and Hessian, a long run's starts screened on a share of its pings), timed in
    ``default_*``. With ``save``: the simulated case written to that path (:func:`time_saved` times it again)."""
    from ..estimators.statistics.evaluation import calibration_errors
    from ..cases.io import write_case
    from ..cases.simulation import simulate
    from .common import timed_calibration

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tic = time.perf_counter()
    case = simulate(long_run(n_pings, scenario), seed=seed)
    sim = time.perf_counter() - tic
    if save:
        write_case(case, save)
    r, setup, solve = one_start(case, seed)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    default = {}
    if starts:
        d, d_setup, d_solve = timed_calibration(case, n_starts=starts, seed=seed)
        default = {"default_starts": starts, "default_setup_s": d_setup, "default_solve_s": d_solve,
                   "default_calibration_s": d_setup + d_solve, "default_message": d.multistart.message,
                   "default_objective_ratio": d.objective / r.objective,
                   "default_peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}
    return {**default, "n_pings": case.pings.n, "seed": seed, "simulate_s": sim, "setup_s": setup, "solve_s": solve,
            "calibration_s": setup + solve, "peak_rss_mb": peak,
            "rss_before_mb": rss0, "success": r.success, "iterations": r.multistart.iterations,
            "tangential_radial_rms_m_s": calibration_errors(case, r)["tangential_radial_rms_m_s"]}


def main(argv: list) -> dict:
    import argparse

    p = argparse.ArgumentParser(prog="python -m adcpdyn.benchmarks.scale_worker")
    p.add_argument("--time", metavar="CASE.h5", help="calibrate this saved case, timed, and nothing else")
    p.add_argument("--save", metavar="CASE.h5", help="write the simulated case here")
    p.add_argument("size", nargs="*", help="N_PINGS SEED [SCENARIO [STARTS]]")
    a = p.parse_args(argv)
    if a.time:
        return time_saved(a.time)
    if not 2 <= len(a.size) <= 4:
        p.error("expected N_PINGS SEED [SCENARIO [STARTS]]")
    return measure(int(a.size[0]), int(a.size[1]), *a.size[2:3], *map(int, a.size[3:4]), save=a.save)


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])))
