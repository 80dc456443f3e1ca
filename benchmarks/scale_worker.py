"""One size of ``adcpdyn bench scale``, run in its own process so that its peak memory is its own.

``python -m adcpdyn.benchmarks.scale_worker N_PINGS SEED [SCENARIO [STARTS]]`` prints one JSON line (the scenario's
run stretched to about N_PINGS pings at its own ping rate; ``pool_m0`` at ~5 Hz by default; with STARTS, calibrated
again with that many starts and the defaults otherwise).
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


def measure(n_pings: int, seed: int, scenario: str = SCENARIO, starts: int | None = None) -> dict:
    """Simulate, then calibrate (one start, one worker) and time each step; peak RSS in MB. With
    ``starts``: then calibrated again as a user's default would (that many starts, the default
    workers and Hessian, a long run's starts screened on a share of its pings), timed in
    ``default_*``."""
    from ..estimators.statistics.evaluation import calibration_errors
    from ..cases.simulation import simulate
    from .common import timed_calibration
    from ..solvers.multistart import SolverOptions

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tic = time.perf_counter()
    case = simulate(long_run(n_pings, scenario), seed=seed)
    sim = time.perf_counter() - tic
    r, setup, solve = timed_calibration(case, n_starts=1, seed=seed, workers=1, solver=SolverOptions(hessian=HESSIAN))
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


if __name__ == "__main__":
    print(json.dumps(measure(int(sys.argv[1]), int(sys.argv[2]), *sys.argv[3:4], *map(int, sys.argv[4:5]))))
