"""correct (one case or many, on Dask too) and compare (every correction method on one case)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ...estimators.correction.correct_case import CORRECTION_METHODS
from ..terminal import say, warn


def load_calibration(path):
    """The --calibration CALIB.json read, validated and typed (None without one)."""
    from ...api import read_calibration

    return None if path is None else read_calibration(path)


def batch_out(args) -> Path:
    """--out of many cases: a folder (created when its parent exists), checked before any work."""
    from ...cases.atomic import check_output_folder

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} is a file; with many cases --out names a folder (one output per case)")
    return check_output_folder(out)


def run_batch_table(args, jobs, columns) -> int:
    """Run jobs (serial or Dask), print one row per case, write ``summary.json`` in --out."""
    from ...batch import resolve_scheduler, run_batch, write_summary

    out = Path(args.out)
    tic = time.perf_counter()
    scheduler = resolve_scheduler(args.scheduler, len(jobs))
    rows = run_batch(jobs, scheduler=scheduler, n_workers=args.workers)
    wall = time.perf_counter() - tic
    name_w = max(len(Path(r["case"]).stem) for r in rows) + 2
    print(f"{'case':<{name_w}}{'status':<10}" + "".join(f"{label:>{w}}" for label, _, w, _ in columns) + f"{'time s':>8}")
    for r in rows:
        status = "error" if r["error"] else ("ok" if r["success"] else "failed")
        line = f"{Path(r['case']).stem:<{name_w}}{status:<10}"
        if r["error"]:
            line += f"  {r['error']}"
        else:
            line += "".join(f"{fmt(r[key]):>{w}}" for _, key, w, fmt in columns) + f"{r['time_s']:>8.2f}"
        print(line)
    write_summary(rows, out / "summary.json")
    n_err = sum(bool(r["error"]) for r in rows)
    n_fail = sum(not r["error"] and not r["success"] for r in rows)
    where = f"{scheduler!r}" + (" (auto: in this process for 1-2 cases)" if args.scheduler == "auto" and scheduler == "none"
                                else " (auto)" if args.scheduler == "auto" else "")
    print(f"{len(rows)} cases on scheduler {where} in {wall:.1f} s: {len(rows) - n_err - n_fail} ok, "
          f"{n_fail} not converged, {n_err} errors; wrote {out}/ (one output per case) and {out / 'summary.json'}")
    return 2 if n_err else (1 if n_fail else 0)


def cmd_correct(args) -> int:
    from ...api import correct
    from ...cases.atomic import check_output_file
    from ...cases.collect import collect_case_paths, is_many

    if args.attribution and (is_many(args.case) or Path(args.out).suffix.lower() != ".nc"):
        raise ValueError(f"--attribution: only with one case and --out OUT.nc (netCDF), got --out {args.out}")
    if is_many(args.case):
        from ...batch import CorrectJob, check_scheduler

        check_scheduler(args.scheduler)
        if args.method not in CORRECTION_METHODS:
            raise ValueError(f"--method: expected one of {list(CORRECTION_METHODS)}, got {args.method!r}")
        paths, out = collect_case_paths(args.case), batch_out(args)
        load_calibration(args.calibration)  # a bad file is one error here, not one per case
        calib = str(Path(args.calibration).resolve()) if args.calibration else None
        jobs = [CorrectJob(str(p), str((out / f"{p.stem}_{args.method}.h5").resolve()), args.method, calib, args.timing,
                           args.reference, args.accept_other_instrument) for p in paths]
        return run_batch_table(args, jobs, [("pings", "pings", 8, str), ("speed m/s", "mean_horizontal_speed_m_s", 11, "{:.4f}".format),
                                       ("3-beam", "three_beam", 8, str), ("lost", "lost", 6, str)])
    args.case = args.case[0]
    if Path(args.out).suffix.lower() not in (".h5", ".nc"):
        raise ValueError(f"--out: expected OUT.h5 (the corrected file) or OUT.nc (CF netCDF), got {args.out!r}")
    check_output_file(args.out, args.case, args.calibration)
    command = (f"adcpdyn correct {args.case} --method {args.method} --timing {args.timing} --reference {args.reference}"
               + (f" --calibration {args.calibration}" if args.calibration else "")
               + (f" --attribution {args.attribution}" if args.attribution else "") + f" --out {args.out}")
    result = correct(args.case, args.method, args.calibration, timing=args.timing, reference=args.reference,
                     out=args.out, history=command, accept_other_instrument=args.accept_other_instrument,
                     attribution=args.attribution)
    for w in result.provenance.warnings:
        warn(f"{w}")
    v = result.vessel_velocity_m_s
    speed = np.hypot(v[:, 0], v[:, 1])
    say(f"wrote {args.out}: method {result.method}, {len(v)} pings, "
        f"mean horizontal speed {np.nanmean(speed) if np.isfinite(speed).any() else float('nan'):.4f} m/s, "
        f"{int(np.sum(result.beams_used == 3))} three-beam pings, {int(np.sum(result.beams_used < 3))} lost")
    if result.water_velocity_m_s is not None:
        w = result.water_velocity_m_s
        say(f"water: {w.shape[1]} cells, {int(np.isfinite(w[..., 0]).sum())} of {w[..., 0].size} cell velocities, "
            f"referenced to {'the bottom track' if result.provenance.water_reference == 'bt' else 'the GNSS'}")
    if result.provenance.installation_note:
        warn(f"{result.provenance.installation_note}")
    if result.provenance.moving_bed_note:
        say(f"note: {result.provenance.moving_bed_note}")
    return 0


def cmd_compare(args) -> int:
    """Every correction method on one case: the paper's metrics table and figures."""
    from ...api import compare
    from ...cases.atomic import check_output_folder

    if args.out:
        check_output_folder(args.out)
    comparison = compare(args.case, args.calibration, out=args.out, fmt=args.format,
                         accept_other_instrument=args.accept_other_instrument)
    for w in comparison.warnings:
        warn(f"{w}")
    print(f"{comparison.case}: vessel velocity against {comparison.against_text}")
    print(comparison.format_table())
    for m, why in comparison.not_run.items():
        print(f"{m}: not run: {why}")
    if comparison.files:
        print("saved " + ", ".join(str(f) for f in reversed(comparison.files)))
    return 0
