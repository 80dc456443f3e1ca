"""One measurement of ``adcpdyn bench surveyday``, in its own process so that its peak memory and
its cores are its own.

``python -m adcpdyn.benchmarks.survey_day_worker RUNS PLACEMENT [diagnose]`` prints one JSON line.
PLACEMENT: ``one_core`` (this process pinned to one CPU, one solver thread; the parent sets the
BLAS thread counts to 1), ``here`` (this process as configured by default: two solver threads,
the BLAS threads the library chooses) or ``dask`` (the starts on a LocalCluster of two
single-threaded worker processes, :mod:`adcpdyn.estimators.calibration.distributed`).
"""

from __future__ import annotations

import dataclasses
import json
import os
import resource
import sys
import time

PINGS_PER_TRANSECT = 500
PING_INTERVAL_S = (0.27, 0.33)  # river_survey's ~150-s transects at ~3.3 Hz: about 500 pings each
SURVEY, SEED = "river_survey", 1
PLACEMENTS = {"one_core": {"workers": 1}, "here": {}, "dask": {"scheduler": "local", "workers": 2}}


def transects(runs: int, seed: int = SEED) -> list:
    """``runs`` transects of the simulated river survey at about 500 pings each."""
    from ..cases.simulation import simulate
    from ..cases.survey import survey_scenarios

    out = []
    for k, sc in enumerate(survey_scenarios(SURVEY, runs, seed)):
        out.append(simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, ping_interval_s=PING_INTERVAL_S)),
                            seed=seed + k))
    return out


def measure(runs: int, placement: str, diagnose: bool = False) -> dict:
    """Simulate the transects, calibrate them jointly (default options but the placement), and with
    ``diagnose`` diagnose them jointly with that calibration; seconds of each step and the peak RSS."""
    import numpy as np

    from .. import api
    from .survey import _truth

    if placement == "one_core" and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    tic = time.perf_counter()
    cases = transects(runs)
    simulate_s = time.perf_counter() - tic
    tic = time.perf_counter()
    r = api.calibrate(cases, **PLACEMENTS[placement])
    calibration_s = time.perf_counter() - tic
    truth = _truth(cases)["misalignment_rad"]
    out = {"runs": runs, "placement": placement, "pings": int(sum(c.pings.n for c in cases)), "simulate_s": simulate_s,
           "calibration_s": calibration_s, "success": bool(r.success), "starts": len(r.multistart.starts),
           "fraction_at_best": r.multistart.fraction_at_best,
           "misalignment_error_deg": float(np.degrees(np.angle(np.exp(1j * (r.heading_misalignment_rad - truth))))),
           "misalignment_se_deg": float(np.degrees(r.heading_misalignment_se_rad)),
           "cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()}
    if diagnose:
        tic = time.perf_counter()
        d = api.diagnose(cases, r)
        out.update(diagnosis_s=time.perf_counter() - tic, verdict=d.verdict,
                   truth_effects=sorted({e["name"] for c in cases for e in c.truth.effects}))
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


if __name__ == "__main__":
    print(json.dumps(measure(int(sys.argv[1]), sys.argv[2], len(sys.argv) > 3 and sys.argv[3] == "diagnose")))
