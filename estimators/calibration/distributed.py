"""A calibration's starts spread over a Dask cluster (:mod:`...solvers.cluster`): every worker
builds the problem once from the runs and the options (CasADi Functions are not sent between
processes), solves its share of the starts, and the shares combine as one multistart
(:func:`...solvers.multistart.combine_starts`): the same records, groups and best as in one
process.
"""

from __future__ import annotations

import dataclasses
import uuid

import numpy as np

from ...solvers.cluster import SERIAL, dask_client
from ...solvers.multistart import MultistartResult, combine_starts, run_starts

_BUILT: dict = {}  # in a worker process: the problem of the calibration it is solving starts of, by token


def _solve_share(token: str, build, cases, fits, config, x0s: np.ndarray, indices: np.ndarray) -> list:
    """On a worker: the problem for ``token`` (``build(cases, config, fit=fits)`` on first use, from
    the runs and their attitude pre-fits; the previous one dropped), and its starts ``x0s`` (rows
    ``indices`` of the whole design) solved one after another."""
    problem = _BUILT.get(token)
    if problem is None:
        _BUILT.clear()
        problem = _BUILT[token] = build(cases, config, fit=fits)
    lbz, ubz = problem.lbx / problem.scale, problem.ubx / problem.scale
    return run_starts(problem.solver, x0s, lbz, ubz, problem.lbg, problem.ubg, problem.parameters(), progress=False,
                      indices=indices)


def distributed_multistart(problem, x0s: np.ndarray) -> MultistartResult:
    """The multistart of ``problem`` (a :class:`.problem.CalibrationProblem` whose config names a
    scheduler) from the starts ``x0s``, one share per worker; each worker builds its own problem of
    the same class (sent by reference, as its import path)."""
    config = dataclasses.replace(problem.config, scheduler=SERIAL, workers=1)  # a worker solves its share alone
    token = uuid.uuid4().hex
    x0s = np.atleast_2d(x0s)
    with dask_client(problem.config.scheduler, problem.config.workers, max_workers=len(x0s)) as client:
        n = max(1, min(len(client.scheduler_info()["workers"]), len(x0s)))
        [cases] = client.scatter([problem.cases], broadcast=True)
        fits = list(problem.fits)  # the attitude pre-fits travel (kilobytes): the workers need not redo them
        futures = [client.submit(_solve_share, token, type(problem), cases, fits, config, x0s[ix], ix, pure=False)
                   for ix in np.array_split(np.arange(len(x0s)), n)]
        done = [d for f in futures for d in f.result()]
    return combine_starts(done, x0s.shape[1])
