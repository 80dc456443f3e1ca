"""Many cases at once: one job per case file, run serially or on Dask (``dask.distributed``).

A job carries only paths and frozen option dataclasses; the worker reads the case and
builds every CasADi Function itself (Functions are not sent between processes). Each
job writes its own output atomically and returns a small summary; a case that fails
reports its one-line error and does not stop the others.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

from .estimators.calibration.config import CalibrationConfig
from .solvers.cluster import LOCAL, SERIAL, check_address, dask_client

AUTO = "auto"
IN_PROCESS_MAX_JOBS = 2  # auto: a LocalCluster costs seconds to start; one or two cases run here


@dataclass(frozen=True)
class CalibrateJob:
    """Calibrate one case file into one CALIB.json."""

    case_path: str
    out_path: str
    config: CalibrationConfig


@dataclass(frozen=True)
class CorrectJob:
    """Correct one case file with one method into one corrected file."""

    case_path: str
    out_path: str
    method: str
    calibration_path: str | None = None
    timing: str = "deep"
    reference: str = "bt"  # water velocities referenced to the bottom track or the GNSS
    accept_other_instrument: bool = False  # apply a calibration that names another instrument


def _calibrate(job: CalibrateJob) -> dict:
    from .api import calibrate

    r = calibrate(job.case_path, job.config)  # the case's own warnings first in r.warnings
    r.to_json(job.out_path)
    ms = r.multistart
    notes = [w for c in r.provenance.get("cases", []) for w in c.get("warnings", [])]
    return {"success": r.success, "objective": r.objective, "max_constraint_violation": r.max_constraint_violation,
            "fraction_at_best": ms.fraction_at_best, "iterations": ms.iterations, "graph": r.graph,
            "lever_arms_sensor_m": r.lever_arms_sensor_m.tolist(), "installation_ypr_rad": r.installation_ypr_rad.tolist(),
            "warnings": len(r.warnings), "case_warnings": notes}


def _correct(job: CorrectJob) -> dict:
    import numpy as np

    from .api import correct
    from .cases.corrected import write_correction

    result = correct(job.case_path, job.method, job.calibration_path, timing=job.timing, reference=job.reference,
                     accept_other_instrument=job.accept_other_instrument)
    write_correction(result, job.out_path, source_case=job.case_path)  # the folder is made by the first write
    notes = list(result.provenance.warnings)
    v = result.vessel_velocity_m_s
    speed = np.hypot(v[:, 0], v[:, 1])
    return {"success": True, "method": result.method, "pings": len(v),
            "mean_horizontal_speed_m_s": float(np.nanmean(speed)) if np.isfinite(speed).any() else float("nan"),
            "three_beam": int(np.sum(result.beams_used == 3)), "lost": int(np.sum(result.beams_used < 3)),
            "warnings": notes}


def run_job(job) -> dict:
    """Run one job where it lands (a Dask worker or this process); never raises for bad input."""
    tic = time.perf_counter()
    row = {"case": job.case_path, "output": job.out_path}
    try:
        row.update(_calibrate(job) if isinstance(job, CalibrateJob) else _correct(job))
        row["error"] = None
    except (ValueError, OSError) as exc:  # one-line errors of a bad case; the batch goes on
        row.update(success=False, error=str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    row["time_s"] = time.perf_counter() - tic
    return row


def check_scheduler(scheduler: str) -> str:
    """``auto``, ``local``, ``none`` or a scheduler address (``tcp://host:port`` or ``host:port``)."""
    return check_address(scheduler, "--scheduler", extra=(AUTO,))


def resolve_scheduler(scheduler: str, n_jobs: int) -> str:
    """What ``auto`` means for ``n_jobs``: in this process (``none``) for at most
    :data:`IN_PROCESS_MAX_JOBS`, where starting a LocalCluster costs more than it saves, else
    ``local``; any other choice as given (an address is always used)."""
    scheduler = check_scheduler(scheduler)
    if scheduler == AUTO:
        return SERIAL if n_jobs <= IN_PROCESS_MAX_JOBS else LOCAL
    return scheduler


def _bar(total: int, progress: bool | None):
    from tqdm import tqdm

    from .progress import progress_bar_enabled

    return tqdm(total=total, unit="case", desc="cases", disable=not (progress_bar_enabled() if progress is None else progress))


def run_batch(jobs, scheduler: str = AUTO, n_workers: int | None = None, progress: bool | None = None) -> list[dict]:
    """Every job's summary, in job order.

    Parameters
    ----------
    jobs : list of CalibrateJob or CorrectJob
    scheduler : str
        ``auto`` (``none`` for one or two jobs, else ``local``: :func:`resolve_scheduler`),
        ``local`` (a LocalCluster of single-threaded worker processes: CasADi's symbolic
        graphs are not safe to build from several threads of one process), ``none``
        (serial, in this process) or the address of a running Dask scheduler.
    n_workers : int, optional
        Size of the LocalCluster (default: the number of CPUs, at most one per job).
    progress : bool, optional
        Progress bar on stderr (default: when stderr is a terminal).
    """
    jobs = list(jobs)
    scheduler = resolve_scheduler(scheduler, len(jobs))
    if not jobs:
        return []
    if scheduler == SERIAL:
        out = []
        with _bar(len(jobs), progress) as bar:
            for job in jobs:
                out.append(run_job(job))
                bar.update()
        return out
    from distributed import as_completed

    with dask_client(scheduler, n_workers, max_workers=len(jobs)) as client:
        futures = client.map(run_job, jobs, pure=False)
        order = {f.key: i for i, f in enumerate(futures)}
        out: list = [None] * len(jobs)
        with _bar(len(jobs), progress) as bar:
            for f in as_completed(futures):
                out[order[f.key]] = f.result()
                bar.update()
        return out


def write_summary(rows: list[dict], path) -> None:
    """The batch's summaries as JSON, atomically."""
    from .cases.atomic import atomic_path
    from .estimators.calibration.result import jsonable

    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(jsonable(rows), fh, indent=2)
