"""Set-up of a calibration whose graph was built before (issue 25 item 1): each scenario's case set up
and solved ``repeats`` times in one process, with the kept-graph cache and without it (``ADCPDYN_MODEL_CACHE=0``),
alternated; the solves must not change.

``python -m adcpdyn.benchmarks.graph_reuse [scenario ...]`` prints one row per scenario and cache.
"""

from __future__ import annotations

import os
import sys
import warnings

SCENARIOS = ("pool_m1", "pool_m0")
CONFIG = {"n_starts": 8, "seed": 1, "workers": 1, "moving_bed": "off"}


def measure(scenario: str, repeats: int = 3) -> list[dict]:
    from ..cases.scenario import get_scenario
    from ..cases.simulation import simulate
    from ..estimators import model_cache
    from .common import timed_calibration

    case = simulate(get_scenario(scenario), seed=1)
    before = os.environ.get(model_cache.CACHE_ENV)  # the caller's setting, put back after
    rows = []
    for keep in ("0", str(model_cache.DEFAULT_SIZE)):
        os.environ[model_cache.CACHE_ENV] = keep
        model_cache.clear()
        times = []
        for _ in range(repeats):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r, setup, solve = timed_calibration(case, **CONFIG)
            times.append((setup, solve, r.graph, r.objective))
        rows.append({"scenario": scenario, "n_pings": case.pings.n, "cache": keep != "0", "setup_s": [t[0] for t in times],
                     "solve_s": [t[1] for t in times], "graph": [t[2] for t in times], "objective": [t[3] for t in times]})
    if before is None:
        os.environ.pop(model_cache.CACHE_ENV)
    else:
        os.environ[model_cache.CACHE_ENV] = before
    return rows


def main(argv=None) -> None:
    print(f"{'scenario':<10}{'pings':>6} {'cache':<6}{'set-up (s)':<22}{'solve (s)':<22}graph")
    for name in (argv or SCENARIOS):
        rows = measure(name)
        for row in rows:
            fmt = lambda v: " ".join(f"{x:.2f}" for x in v)
            print(f"{row['scenario']:<10}{row['n_pings']:>6} {'on' if row['cache'] else 'off':<6}{fmt(row['setup_s']):<22}"
                  f"{fmt(row['solve_s']):<22}{', '.join(row['graph'])}; objective spread "
                  f"{max(row['objective']) - min(row['objective']):.1e}")
        off, on = (r["objective"][0] for r in rows)
        print(f"{'':<16}set-up taken / built: {min(rows[1]['setup_s'][1:]) / min(rows[0]['setup_s']):.2f}; "
              f"objective with the cache - without: {on - off:.1e}")


if __name__ == "__main__":
    main(sys.argv[1:])
