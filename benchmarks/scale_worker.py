"""One size of ``adcpdyn bench scale``, run in its own process so that its peak memory is its own.

``python -m adcpdyn.benchmarks.scale_worker N_PINGS SEED`` prints one JSON line.
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


def long_run(n_pings: int):
    """pool_m0 stretched to about ``n_pings`` pings at ~5 Hz (same platform, motion and noise)."""
    from ..cases.scenario import get_scenario

    sc = get_scenario(SCENARIO)
    run = dataclasses.replace(sc.run, duration_s=n_pings * sum(PING_INTERVAL_S) / 2, ping_interval_s=PING_INTERVAL_S)
    return dataclasses.replace(sc, run=run)


def measure(n_pings: int, seed: int) -> dict:
    """Simulate, then calibrate (one start, one worker) and time each step; peak RSS in MB."""
    from ..estimators.statistics.evaluation import calibration_errors
    from ..cases.simulation import simulate
    from .common import timed_calibration
    from ..solvers.multistart import SolverOptions

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tic = time.perf_counter()
    case = simulate(long_run(n_pings), seed=seed)
    sim = time.perf_counter() - tic
    r, setup, solve = timed_calibration(case, n_starts=1, seed=seed, workers=1, solver=SolverOptions(hessian=HESSIAN))
    return {"n_pings": case.pings.n, "seed": seed, "simulate_s": sim, "setup_s": setup, "solve_s": solve,
            "calibration_s": setup + solve, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "rss_before_mb": rss0, "success": r.success, "iterations": r.multistart.iterations,
            "tangential_radial_rms_m_s": calibration_errors(case, r)["tangential_radial_rms_m_s"]}


if __name__ == "__main__":
    print(json.dumps(measure(int(sys.argv[1]), int(sys.argv[2]))))
