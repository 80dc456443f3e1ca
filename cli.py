"""adcpdyn: attitude dynamic correction for vessel-mounted Janus ADCPs (simulate, import, calibrate, correct,
compare, diagnose, export). Every command is also a Python function: ``import adcpdyn`` (docs/api.md)."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

DEFAULT_CASES = ("pool_m1", "pool_m2")
TIMINGS = ("deep", "shallow", "exact")  # correct --timing
FIGURE_FORMATS = ("png", "pdf", "svg")

EXIT_STATUS = """exit status:
  0    success
  1    a solve failed or did not converge (calibrate, diagnose; a batch with a case not
       converged); the output is still written and says so
  2    bad input: an unreadable or invalid file, an impossible value or option; one line on
       stderr names the field (a batch: some case failed, the others are written)
  130  interrupted (Ctrl-C: 128 + SIGINT); no partial file is left
  141  the output's reader stopped reading (a pipe into `head`: 128 + SIGPIPE); nothing said
  143  terminated (128 + SIGTERM); no partial file is left
"""

# ---------------------------------------------------------------------------------- progress on stderr
_LIVE_FD: int | None = None  # the real stderr while descriptor 2 is held (see _HeldStderr)


def progress_enabled() -> bool:
    """Progress lines on stderr: when it is a terminal, or as ``ADCPDYN_PROGRESS=1|0`` says (stdout stays clean)."""
    from .progress import progress_enabled as enabled

    return enabled(_LIVE_FD if _LIVE_FD is not None else 2)


from .text import noise_levels_line, prose  # noqa: E402  (noise levels with units; lines wrapped to the tables' width)


def warn(text: str) -> None:
    """A warning on stderr (stdout keeps the results a script reads), wrapped to the tables' width."""
    print(prose(f"warning: {text}"), file=sys.stderr)


def say(line: str, indent: str = "    ") -> None:
    """A line of results on stdout, wrapped to the tables' width (continuation lines indented)."""
    print(prose(line, indent=indent))


class _Progress:
    """One stderr line per step, with the seconds since the command started: ``adcpdyn VERB: [  12.3 s] TEXT``."""

    def __init__(self, verb: str):
        self.verb, self.t0, self.on = verb, time.perf_counter(), progress_enabled()

    def __call__(self, text: str) -> None:
        if not self.on:
            return
        line = f"adcpdyn {self.verb}: [{time.perf_counter() - self.t0:7.1f} s] {text}\n".encode("utf-8", "replace")
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        with contextlib.suppress(OSError):
            os.write(_LIVE_FD if _LIVE_FD is not None else 2, line)


class _DiagnosisProgress(_Progress):
    """The diagnosis's labels (``effect`` in round 1, ``chosen+effect`` later) as round, effect and time."""

    def __init__(self, verb: str, n_runs: int):
        super().__init__(verb)
        self.fitted = 0
        self(f"fitting the base model ({n_runs} run{'s' if n_runs > 1 else ''}) and its held-out residuals")

    def fitted_model(self, label: str) -> None:
        if self.fitted == 0:
            self("base model fitted; trying the catalog's effects")
        self.fitted += 1
        parts = label.split("+")
        on_top = f" on top of {'+'.join(parts[:-1])}" if len(parts) > 1 else ""
        self(f"round {len(parts)}: fitted {parts[-1]}{on_top} (model {self.fitted})")


def _read(path):
    from .cases.io import read_case

    return read_case(path)


def cmd_scenarios(args) -> int:
    from .cases.scenario import load_scenarios

    from .cases.survey import survey_names

    surveys = set(survey_names())
    for name, sc in load_scenarios().items():
        label = " [survey: simulate --runs K for K transects]" if name in surveys else ""
        say(f"{name:<20} {sc.platform.name:<14} {sc.run.description}{label}", indent=" " * 36)
    return 0


def cmd_cache(args) -> int:
    from .solvers import compiled

    folder = compiled.cache_dir()
    if args.clear:
        print(f"{folder}: removed {compiled.clear()} compiled model(s)")
        return 0
    found = compiled.entries()
    size_mb = sum(p.stat().st_size for p in found) / 1e6
    cc = compiled.compiler() or "none found (models are evaluated interpreted)"
    print(f"cache of compiled per-ping models: {folder} (set ${compiled.CACHE_ENV} to move it)")
    print(f"C compiler: {cc}; {len(found)} model(s), {size_mb:.2f} MB")
    for p in found[:args.list]:
        print(f"  {p.name}  {p.stat().st_size / 1e3:.0f} kB")
    return 0


def cmd_simulate(args) -> int:
    from .cases.io import write_case
    from .cases.scenario import get_scenario
    from .cases.atomic import check_output_file
    from .cases.simulation import simulate

    survey_options = {"--compass-deg": args.compass_deg, "--bed-speed": args.bed_speed, "--bed-profile": args.bed_profile}
    if args.runs is None:
        given = [k for k, v in survey_options.items() if v is not None]
        if given:
            raise ValueError(f"{given[0]}: only with --runs (a survey's transects)")
        check_output_file(args.out)
        case = simulate(get_scenario(args.scenario), seed=args.seed)
        write_case(case, args.out)
        print(f"wrote {args.out}: {case.pings.n} pings, {case.attitude.time_s.size} attitude samples")
        return 0
    return _simulate_survey(args)


def _simulate_survey(args) -> int:
    """``--runs K``: the survey's K transects, ``OUT/NAME_run01.h5`` ..., and what they share."""
    from .cases.atomic import check_output_folder
    from .cases.io import write_case
    from .cases.survey import is_survey, simulate_survey, survey_names

    if not is_survey(args.scenario):
        raise ValueError(f"--runs: scenario {args.scenario!r} is not a survey; surveys: {survey_names()}")
    out = check_output_folder(args.out)
    compass = None if args.compass_deg is None else tuple(np.deg2rad(args.compass_deg))
    cases = simulate_survey(args.scenario, args.runs, args.seed, compass_rad=compass, bed_speed_m_s=args.bed_speed,
                            bed_profile=args.bed_profile)
    out.mkdir(parents=True, exist_ok=True)
    for case in cases:
        path = out / f"{case.name}.h5"
        write_case(case, path)
        info = json.loads(case.truth.extra_attrs["survey"])
        print(f"wrote {path}: {case.pings.n} pings, course {np.rad2deg(info['course_over_ground_rad']) % 360:.1f} deg, "
              f"crab {np.rad2deg(info['crab_angle_rad']):+.1f} deg, UTC start {case.time_origin_utc}, effective heading "
              f"misalignment {np.rad2deg(float(case.truth.extra_attrs['effective_heading_misalignment_rad'])):+.2f} deg")
    effects = {e["name"]: e["params"] for e in cases[0].truth.effects}
    abc = effects["compass_deviation"]
    bed = effects["moving_bed"]
    print(f"shared: compass A {np.rad2deg(abc['A_rad']):+.2f}, B {np.rad2deg(abc['B_rad']):+.2f}, "
          f"C {np.rad2deg(abc['C_rad']):+.2f} deg; moving bed {np.hypot(bed['velocity_north_m_s'], bed['velocity_east_m_s']):.3f} "
          f"m/s ({bed.get('profile', 'uniform')}), north {bed['velocity_north_m_s']:+.3f}, east {bed['velocity_east_m_s']:+.3f} m/s")
    return 0


def cmd_import(args) -> int:
    """A real instrument file (TRDI PD0, Nortek AD2CP) into a case file, with its audit trail."""
    from .cases.atomic import check_output_file
    from .cases.importers import Window, import_file, resalted, write_imported

    path = Path(args.file)
    check_output_file(args.out, path)
    case, attrs = import_file(path, Window(start_s=args.start, end_s=args.end, every=args.every))
    if args.salinity_psu is not None:
        case, attrs = resalted(case, attrs, args.salinity_psu)
    write_imported(case, attrs, args.out, source=path)
    prov = attrs["/provenance"]
    say(f"wrote {args.out}: {case.pings.n} pings over {case.pings.time_s[-1]:.1f} s, BT from "
        f"{prov['coordinate_system_found']} coordinates, attitude frame {case.attitude.frame}, "
        f"{int(np.sum(np.all(np.isfinite(case.pings.bt_radial_m_s), axis=1)))} pings with 4 valid beams")
    if "clock_offset_s" in prov:
        say(f"GNSS: {prov['gnss']}; clock offset GNSS - ADCP {prov['clock_offset_s']:+.2f} s "
            f"(coarse {prov['clock_offset_coarse_s']:+.2f} s, speed correlation {prov['clock_offset_correlation']:.3f})")
        if "bt_vs_gnss_speed_ratio_bt_over_gnss" in prov:
            say(f"BT vs GNSS: speed ratio {prov['bt_vs_gnss_speed_ratio_bt_over_gnss']:.3f}, course offset (GNSS - BT) "
                f"{prov['bt_vs_gnss_course_offset_gnss_minus_bt_deg']:+.1f} +- {prov['bt_vs_gnss_course_offset_se_deg']:.1f} deg "
                f"over {prov['bt_vs_gnss_n']} samples")
    else:
        say(f"GNSS: {prov.get('gnss', 'none')}")
    warning = attrs.get("/attitude", {}).get("attitude_warning")
    if warning:
        warn(f"attitude: {warning}")
    if prov.get("reader_messages"):
        warn(prov["reader_messages"])
    if "sound_speed_changed" in prov:
        say(f"sound speed: {prov['sound_speed_changed']}")
    return 0


def cmd_info(args) -> int:
    from .cases.coverage import restrict_to_coverage
    from .cases.validation import case_warnings
    from .cases.summary import summarise

    case = _read(args.case)
    print(summarise(case))
    for w in case_warnings(case):
        warn(f"{w}")
    try:
        note = restrict_to_coverage(case, source=str(args.case))[1]
    except ValueError as exc:  # info still describes the file; the verbs that use the attitude will refuse it
        note = f"{exc} (correct, compare, calibrate and diagnose refuse this case)"
    if note:
        warn(f"{note}")
    return 0


def _prepare(path, say: bool = True):
    """Read a case for a verb that uses the attitude: its warnings (printed when ``say``) and the
    case restricted to what the attitude record covers (never extrapolated)."""
    from .cases.coverage import restrict_to_coverage
    from .cases.validation import case_warnings

    case = _read(path)
    notes = case_warnings(case)
    case, note = restrict_to_coverage(case, source=str(path))
    if note:
        notes.append(note)
    if say:
        for w in notes:
            warn(f"{w}")
    return case, notes


from .estimators.correction.correct_case import CORRECTION_METHODS  # noqa: E402
from .estimators.correction.correct_case import correct_case as _correct  # noqa: E402
from .solvers.nlp_methods import METHODS  # noqa: E402


def _load_calibration(path):
    """The --calibration CALIB.json read, validated and typed (None without one)."""
    from .api import read_calibration

    return None if path is None else read_calibration(path)


def _batch_out(args) -> Path:
    """--out of many cases: a folder (created when its parent exists), checked before any work."""
    from .cases.atomic import check_output_folder

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} is a file; with many cases --out names a folder (one output per case)")
    return check_output_folder(out)


def _run_batch(args, jobs, columns) -> int:
    """Run jobs (serial or Dask), print one row per case, write ``summary.json`` in --out."""
    from .batch import resolve_scheduler, run_batch, write_summary

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
    from .api import correct
    from .cases.atomic import check_output_file
    from .cases.collect import collect_case_paths, is_many

    if args.attribution and (is_many(args.case) or Path(args.out).suffix.lower() != ".nc"):
        raise ValueError(f"--attribution: only with one case and --out OUT.nc (netCDF), got --out {args.out}")
    if is_many(args.case):
        from .batch import CorrectJob, check_scheduler

        check_scheduler(args.scheduler)
        if args.method not in CORRECTION_METHODS:
            raise ValueError(f"--method: expected one of {list(CORRECTION_METHODS)}, got {args.method!r}")
        paths, out = collect_case_paths(args.case), _batch_out(args)
        _load_calibration(args.calibration)  # a bad file is one error here, not one per case
        calib = str(Path(args.calibration).resolve()) if args.calibration else None
        jobs = [CorrectJob(str(p), str((out / f"{p.stem}_{args.method}.h5").resolve()), args.method, calib, args.timing,
                           args.reference, args.accept_other_instrument) for p in paths]
        return _run_batch(args, jobs, [("pings", "pings", 8, str), ("speed m/s", "mean_horizontal_speed_m_s", 11, "{:.4f}".format),
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


def cmd_export(args) -> int:
    """A case, or a corrected file with its case, as CF-1.8 / ACDD-1.3 / IOOS-1.2 netCDF (xarray, h5netcdf)."""
    from .cases.atomic import check_output_file
    from .cases.netcdf import export_file

    if Path(args.out).suffix.lower() != ".nc":
        raise ValueError(f"--out: expected a netCDF file name ending in .nc, got {args.out!r}")
    check_output_file(args.out, args.input, args.case)
    ds = export_file(args.input, args.out, case_path=args.case, attribution=args.attribution,
                     history="adcpdyn export " + " ".join([args.input, "--out", args.out]
                                                          + (["--case", args.case] if args.case else [])
                                                          + (["--attribution", args.attribution] if args.attribution
                                                             else [])))
    what = f"method {ds.attrs['processing_method']}, " if "processing_method" in ds.attrs else ""
    water = f"{ds.sizes['depth']} cells, " if "depth" in ds.sizes else "no water profile, "
    dated = "time" in ds.coords
    say(f"wrote {args.out}: {what}{ds['case_time'].size} pings, {water}time "
        f"{'UTC' if dated else 'in case-clock seconds (no UTC origin)'}, {ds.attrs['Conventions']} (h5netcdf)")
    return 0


def cmd_compare(args) -> int:
    """Every correction method on one case: the paper's metrics table and figures."""
    from .api import compare
    from .cases.atomic import check_output_folder

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


def _calibration_config(args, formulation=None, one=True):
    """The CalibrationConfig of the flags; ``one``: a single calibration, whose starts go where
    --scheduler/--workers say (with many cases those flags place the cases, each solved in its worker)."""
    from .estimators.calibration.problem import CalibrationConfig

    if args.bed_knots is not None and args.moving_bed != "section":
        raise ValueError(f"--bed-knots {args.bed_knots}: sets the values of --moving-bed section, not of --moving-bed "
                         f"{args.moving_bed} (drop it, or use --moving-bed section)")
    prior_deg = getattr(args, "compass_deviation_prior_deg", None)
    if prior_deg is not None and args.compass_deviation != "auto":
        raise ValueError(f"--compass-deviation-prior-deg {prior_deg:g}: the prior of --compass-deviation auto, not of "
                         f"--compass-deviation {args.compass_deviation} (drop it, or use --compass-deviation auto)")
    prior = {} if prior_deg is None else {"compass_deviation_prior_rad": float(np.deg2rad(prior_deg))}
    from .solvers.multistart import SolverOptions

    declination = None if args.declination_deg is None else float(np.deg2rad(args.declination_deg))
    # one calibration (one run, or --joint): --scheduler says where its starts are solved (auto: here)
    scheduler = getattr(args, "scheduler", "auto") if one else "none"
    placement = {"scheduler": "none" if scheduler == "auto" else scheduler}
    if one and getattr(args, "workers", None):
        placement["workers"] = args.workers
    return CalibrationConfig(**placement, formulation=formulation or args.formulation, n_starts=args.starts, seed=args.seed,
                             method=args.method, timing=args.timing, tangential=args.tangential,
                             jacobian=args.jacobian, compile=args.compile, attitude=args.attitude,
                             moving_bed=args.moving_bed,
                             navigation=args.navigation, moving_bed_section_knots=args.bed_knots or 3, compass_deviation=args.compass_deviation,
                             **prior,
                             standard_errors=args.standard_errors, magnetic_declination_rad=declination,
                             solver=SolverOptions(method=args.solver))


def _print_calibration(result, title: str) -> None:
    """What a calibration found, with standard errors, in the field's words."""
    ms = result.multistart
    deg = np.rad2deg
    say(f"{title}: {result.config.method} calibration, formulation {result.formulation}, {result.timing}-water model, "
        f"{result.jacobian} Jacobian, beams' attitude from the {result.attitude_source}")
    say(f"solver: {ms.message}; objective {result.objective:.6g}; max constraint violation "
        f"{result.max_constraint_violation:.2e}; solver time {ms.time_s:.2f} s summed over the starts")
    if result.instrument is not None:
        say(f"instrument: {result.instrument.label()}")
    label = "head-frame lever arms (m)" if result.attitude_frame == "transducer" else "radius vectors, body frame (m)"
    if not np.isfinite(result.lever_arms_sensor_se_m).any():
        say(f"{label}: not determined (the warnings say why)")
    else:
        say(label + "  [value +- se]")
    for i in range(4 if np.isfinite(result.lever_arms_sensor_se_m).any() else 0):
        cells = "  ".join(f"{v:+.4f} +- {s:.4f}" if np.isfinite(s) else "  (not determined)  "
                          for v, s in zip(result.lever_arms_sensor_m[i], result.lever_arms_sensor_se_m[i]))
        say(f"  r{i + 1}: {cells}")
    if_moves = {c["pair"][0]: c for c in result.confounded if "se_if_bed_moves_rad" in c}

    def bed_fixed(name: str) -> str:  # the moving-bed test could not decide: the pair's other reading, in the headline
        c = if_moves.get(name)
        return "" if c is None else (f" with the bed fixed [moving-bed test undetermined; with the bed free "
                                     f"{deg(c['value_if_bed_moves_rad']):+.4f} +- {deg(c['se_if_bed_moves_rad']):.4f}]")

    yaw = bed_fixed("installation_yaw")

    if np.isfinite(result.heading_misalignment_se_rad):
        say(f"heading misalignment against the reference (deg): {deg(result.heading_misalignment_rad):+.4f} "
            f"+- {deg(result.heading_misalignment_se_rad):.4f}{bed_fixed('heading_misalignment')} (true heading = "
            f"sensor heading + misalignment; head sensor: written as the installation yaw, installation pitch and roll "
            f"not determined)")
    if result.compass_deviation_rad is not None:
        b, c = deg(result.compass_deviation_rad)
        sb, sc = deg(result.compass_deviation_se_rad)
        say(f"compass deviation (deg): {b:+.3f} +- {sb:.3f} sin(heading) {c:+.3f} +- {sc:.3f} cos(heading)")
    if result.magnetic_declination_rad is not None:
        err = result.compass_error_rad
        say(f"magnetic declination (deg): {deg(result.magnetic_declination_rad):+.2f} ({result.magnetic_declination_note})"
            + ("" if err is None else f"; compass error = misalignment - declination: {deg(err):+.2f} deg"))
    if result.installation_determined:
        say("installation yaw/pitch/roll (deg): " + ", ".join(
            f"{deg(v):+.4f} +- {deg(s):.4f}" for v, s in zip(result.installation_ypr_rad, result.installation_ypr_se_rad))
            + (f" (yaw{yaw})" if yaw else ""))
    if result.moving_bed != "off":
        fmt = lambda v, s: ("not determined" if v is None or not np.all(np.isfinite(s)) else
                            f"north {v[0]:+.4f} +- {s[0]:.4f}, east {v[1]:+.4f} +- {s[1]:.4f}")
        say(f"moving bed ({result.moving_bed}, m/s): {fmt(result.moving_bed_velocity_m_s, result.moving_bed_velocity_se_m_s)}")
        if len(result.runs) > 1:
            for run in result.runs:
                say(f"  {run.case}: {fmt(run.moving_bed_velocity_m_s, run.moving_bed_velocity_se_m_s)}")
    test = result.moving_bed_test
    if test:
        say(f"moving-bed test: {test['decision']} ({test['reason']})"
            + ("; solved again without a bed" if test["decision"] == "fixed" else ""))
    inflation = result.standard_errors.get("inflation_over_white", {})
    if inflation:
        worst = max(inflation, key=inflation.get)
        say(f"standard errors: {result.standard_errors['method']} (Newey-West lags {result.standard_errors['lags']}); "
            f"largest inflation over white noise x{inflation[worst]:.2f} ({worst})")
    say(noise_levels_line(result.noise_sigma))
    for w in result.warnings:
        warn(f"{w}")


def cmd_calibrate(args) -> int:
    from .api import calibrate
    from .cases.atomic import check_output_file
    from .cases.collect import collect_case_paths, is_many

    if is_many(args.case) and not args.joint:
        from .batch import CalibrateJob, check_scheduler

        check_scheduler(args.scheduler)
        config = _calibration_config(args, one=False)
        paths, out = collect_case_paths(args.case), _batch_out(args)
        jobs = [CalibrateJob(str(p), str((out / f"{p.stem}.json").resolve()), config) for p in paths]
        return _run_batch(args, jobs, [("objective", "objective", 12, "{:.6g}".format),
                                       ("max viol", "max_constraint_violation", 10, "{:.1e}".format),
                                       ("at best", "fraction_at_best", 9, "{:.2f}".format)])
    if args.joint and args.method == "two-stage":
        raise ValueError("--method two-stage: the paper's two-stage baseline calibrates one run in two steps; --joint "
                         "is the one-NLP calibration of several runs (drop one of them)")
    if Path(args.out).suffix.lower() != ".json":
        raise ValueError(f"--out: expected a CALIB.json file name ending in .json (calibrate writes JSON), got {args.out!r}")
    from .batch import check_scheduler

    check_scheduler(args.scheduler)  # in the user's flag's words, before the config's own check
    paths = collect_case_paths(args.case) if args.joint else [args.case[0]]
    check_output_file(args.out, *paths)
    config = _calibration_config(args)
    result = calibrate(paths if args.joint else paths[0], config, progress=_Progress("calibrate"))
    names = [c["name"] for c in result.provenance["cases"]]
    title = f"{len(names)} runs ({', '.join(names)}), one NLP" if args.joint else names[0]
    result.to_json(args.out)
    _print_calibration(result, title)
    print(f"wrote {args.out}")
    return 0 if result.success else 1


def cmd_compare_formulations(args) -> int:
    from .cases.atomic import check_output_file
    from .estimators.calibration.formulation_compare import compare_formulations, format_rows

    if args.out:
        check_output_file(args.out, args.case)
    case, _ = _prepare(args.case)
    rows = compare_formulations(case, _calibration_config(args))
    print(format_rows(rows))
    if args.out:
        from .benchmarks.common import write_json

        write_json(rows, Path(args.out))
    return 0


def cmd_demo(args) -> int:
    """The paper's pipeline on built-in cases: calibrate on pool_m0, correct pool_m1 and pool_m2."""
    from .cases.corrected import write_correction
    from .cases.io import write_case
    from .cases.scenario import get_scenario
    from .cases.summary import summarise
    from .estimators.calibration.problem import CalibrationConfig, CalibrationProblem
    from .estimators.statistics.evaluation import calibration_errors
    from .estimators.statistics.metrics import format_table, velocity_metrics
    from .models.rotations import euler_matrix
    from .cases.simulation import simulate
    from .plots import attitude_fit_figure, radius_vectors_figure, velocity_figure

    from .cases.atomic import check_output_folder

    out = check_output_folder(args.out)
    out.mkdir(exist_ok=True)
    cases = {}
    for name in (args.calibration_scenario, *args.scenario):
        case = simulate(get_scenario(name), seed=args.seed)
        write_case(case, out / f"{name}.h5")
        cases[name] = _read(out / f"{name}.h5")

    # 1. calibration run (the paper's Measurement 0)
    calib_case = cases[args.calibration_scenario]
    print(summarise(calib_case))
    calib = CalibrationProblem(calib_case, CalibrationConfig(formulation="exact", n_starts=args.starts,
                                                              seed=args.seed)).solve()
    calib.to_json(out / "calibration.json")
    ms = calib.multistart
    print()
    say(f"joint calibration ({calib.formulation}): {ms.message}; solver time {ms.time_s:.2f} s summed over the starts")
    label = "head" if calib.attitude_frame == "transducer" else "body"
    for i in range(4):
        print(f"  r{i + 1} ({label} frame, m): " + "  ".join(
            f"{v:+.4f} +- {s:.4f}" for v, s in zip(calib.lever_arms_sensor_m[i], calib.lever_arms_sensor_se_m[i])))
    for w in calib.warnings:
        warn(f"{w}")
    err = calibration_errors(calib_case, calib)
    print(f"  tangential radial velocity along the true motion: {1e3 * err['tangential_radial_rms_m_s']:.2f} mm/s RMS "
          f"error (signal {1e3 * err['tangential_radial_signal_rms_m_s']:.1f} mm/s)")
    truth = calib_case.truth.radius_vectors_m
    if calib.attitude_frame == "transducer":
        truth = truth @ np.asarray(euler_matrix(*calib_case.truth.installation_ypr_rad))
    attitude_fit_figure(calib_case, calib.attitude, out / f"attitude_fit.{args.format}")
    radius_vectors_figure(calib.lever_arms_sensor_m, calib.lever_arms_sensor_se_m, truth, label, out / f"radius_vectors.{args.format}")

    # 2. measurement runs: every correction method against truth (the paper's Tables 8 and 12)
    calibration = _load_calibration(out / "calibration.json")
    summary = {"calibration": err}
    for name in args.scenario:
        case = cases[name]
        vt = case.truth.vessel_velocity_m_s
        results = {m: _correct(case, m, calibration) for m in CORRECTION_METHODS}
        for m, r in results.items():
            write_correction(r, out / f"{name}_{m}.h5", source_case=str(out / f"{name}.h5"))
        table = {m: velocity_metrics(r.time_s, r.vessel_velocity_m_s, vt) for m, r in results.items()}
        table["truth"] = velocity_metrics(case.pings.time_s, vt, vt)
        print(f"\n{name}: vessel velocity against truth (lever arms from the {args.calibration_scenario} calibration)")
        print(format_table(table))
        a, r_, o = (table[k]["error_sd_m_s"] for k in ("asc", "rootfinder", "oracle"))
        print(f"  rootfinder error SD {1e3 * r_:.2f} mm/s = {r_ / o:.2f} x the oracle's; closes "
              f"{100 * (a - r_) / (a - o):.0f}% of the ASC-to-oracle gap")
        summary[name] = table
        velocity_figure(case.pings.time_s, {m: results[m].vessel_velocity_m_s for m in ("asc", "adc", "oracle")}, vt,
                        f"{name} (seed {args.seed}): static vs dynamic correction", out / f"{name}_velocity.{args.format}")
    from .cases.atomic import atomic_path

    with atomic_path(out / "metrics.json") as tmp, open(tmp, "w") as fh:
        json.dump(summary, fh, indent=2)
    fmt = args.format
    print()
    say(f"saved in {out}/: calibration.json, attitude_fit.{fmt}, radius_vectors.{fmt}, "
        + ", ".join(f"{n}_velocity.{fmt}" for n in args.scenario) + ", metrics.json, corrected and case files")
    return 0


def cmd_diagnose(args) -> int:
    if args.selftest and args.case:
        raise ValueError(f"diagnose: --selftest {args.selftest} simulates its own cases; {' '.join(args.case)} would be "
                         "ignored (drop it, or use --field-selftest to test your file)")
    if args.out and not args.selftest and Path(args.out).suffix.lower() != ".json":
        raise ValueError(f"--out: expected a file name ending in .json (DIAG.json; the .md and figure go beside it), "
                         f"got {args.out!r}")
    if args.given and (args.selftest or args.field_selftest):
        raise ValueError("diagnose: --given names a run's own effects; --selftest and --field-selftest find them "
                         "themselves (drop --given)")
    if args.selftest:
        return _diagnose_selftest(args)
    if args.field_selftest:
        return _diagnose_field_selftest(args)
    from .api import diagnose
    from .estimators.diagnosis.report import terminal_text, write_report

    paths = _diagnosis_paths(args, "diagnose: expected CASE.h5 and --out DIAG.json (or --selftest N)",
                             "diagnose them together (one boat, shared and per-run effects)")
    progress = _DiagnosisProgress("diagnose", len(paths))
    result = diagnose(paths if args.joint else paths[0], args.calibration, effects=args.effects, attitude=args.attitude,
                      navigation=args.navigation, given=args.given, progress=progress.fitted_model,
                      accept_other_instrument=args.accept_other_instrument)
    progress(f"done: verdict {result.verdict}")
    for w in result.base.get("case_warnings", []):
        warn(f"{w}")
    written = write_report(result, args.out, fmt=args.format)
    print(terminal_text(result))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0 if result.base["success"] else 1


def _diagnosis_paths(args, usage: str, joint: str) -> list:
    """The case paths a diagnosis reads (several only with --joint: ``joint`` says what for), its
    --out checked against them; ``usage`` is the one-line error without a case or --out."""
    from .cases.atomic import check_output_file
    from .cases.collect import collect_case_paths, is_many

    if not args.case or not args.out:
        raise ValueError(usage)
    if is_many(args.case) and not args.joint:
        raise ValueError(f"diagnose: {' '.join(args.case)}: several cases (a folder, a glob or more than one file): add "
                         f"--joint to {joint}")
    paths = collect_case_paths(args.case) if args.joint else [args.case[0]]
    check_output_file(args.out, *paths, args.calibration)
    return paths


def _diagnose_field_selftest(args) -> int:
    from .api import field_selftest
    from .estimators.diagnosis.field_selftest import format_field_selftest

    paths = _diagnosis_paths(args, "diagnose: --field-selftest expects CASE.h5 (several with --joint: a survey) and "
                             "--out SELFTEST.json", "self-test them as one survey")
    res = field_selftest(paths if args.joint else paths[0], args.calibration, navigation=args.navigation, effects=args.effects,
                         accept_other_instrument=args.accept_other_instrument,
                         attitude=args.attitude, out=args.out, fmt=args.format,
                         progress=_Progress("diagnose"))
    for n in res["notes"]:
        warn(n)
    print(format_field_selftest(res))
    print(f"wrote {args.out} and its .md and figure beside it")
    return 0


def _diagnose_selftest(args) -> int:
    from tqdm import tqdm

    from .cases.atomic import atomic_path, check_output_file
    from .estimators.calibration.result import jsonable
    from .api import _diagnosis_config
    from .estimators.diagnosis.selftest import draw_cases, format_summary, run_one, summarise

    if args.out:
        check_output_file(args.out)
    config = _diagnosis_config(args.effects, navigation=args.navigation)
    platforms = tuple(args.platforms) if args.platforms else None
    draws = draw_cases(args.selftest, args.seed, config.effects, **({"platforms": platforms} if platforms else {}))
    rows = []
    for label, params, seed, platform, slow, ar1 in tqdm(draws, desc="self-test", unit="case", disable=not progress_enabled()):
        rows.append(run_one(label, params, seed, platform, config, slow, ar1, calibrated=args.selftest_calibrated))
        r = rows[-1]
        tqdm.write(f"{platform:>14s} {r['expected']:>26s} -> {r['verdict']:<34s} gap {r['gap_before']:.3f} -> "
                   f"{r['gap_after']:.3f}  where {r['where_top']}  ({r['seconds']:.0f} s)")
    summary = summarise(rows, list(config.effects))
    print(format_summary(summary))
    if args.out:
        with atomic_path(args.out) as tmp:
            with open(tmp, "w") as fh:
                json.dump(jsonable({"seed": args.seed, "n": args.selftest, "platforms": platforms or "all",
                                     "calibrated": args.selftest_calibrated,
                                     "config": {"effects": list(config.effects), "bic_margin": config.bic_margin,
                                                "min_shrink": config.min_shrink, "gap_z": config.gap_z,
                                                "min_gap": config.min_gap},
                                     "summary": summary, "cases": rows}), fh, indent=2)
        print(f"wrote {args.out}")
    return 0


def cmd_bench(args) -> int:
    from .cases.atomic import check_output_folder
    from .benchmarks.suites import run

    check_output_folder(args.out)
    run(args.suite, args.quick, Path(args.out), readme=Path(args.readme) if args.readme else None)
    return 0


def _int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}")
        return value
    return parse


def _angle_deg(text: str) -> float:
    value = _finite(text)
    if not -180.0 <= value <= 180.0:
        raise argparse.ArgumentTypeError(f"expected an angle in degrees within +-180, got {text!r}")
    return value


def _deviation_prior_deg(text: str) -> float:
    value = _finite(text)
    if not 0.0 < value <= np.rad2deg(0.5):
        raise argparse.ArgumentTypeError(f"expected a standard deviation in degrees within (0, 28.6], got {text!r}")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


_count, _seed = _int_at_least(1), _int_at_least(0)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block): ``adcpdyn VERB: error: ...``."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see `{self.prog} --help`)\n")


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Each option's default in its help (when it has one), epilogs kept as written."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("%(default)" not in text and action.option_strings and action.default not in (None, False, argparse.SUPPRESS)
                and not action.required):
            text += " (default: %(default)s)"
        return text


def build_parser() -> argparse.ArgumentParser:
    from . import __version__
    from .api import CORRECTION_METHODS, REFERENCES

    p = _Parser(prog="adcpdyn", description=__doc__, epilog=EXIT_STATUS, formatter_class=_HelpFormatter)
    p.add_argument("--version", action="version", version=f"adcpdyn {__version__}")
    sub = p.add_subparsers(dest="command", required=True, title="commands", metavar="command")

    def command(name, help, func):
        s = sub.add_parser(name, help=help, description=help[0].upper() + help[1:] + ".", epilog=EXIT_STATUS,
                           formatter_class=_HelpFormatter)
        s.set_defaults(func=func)
        return s

    def figure_format(s):
        s.add_argument("--format", default="png", choices=FIGURE_FORMATS, help="file format of the figures")

    def accept_other_instrument_option(s):
        s.add_argument("--accept-other-instrument", action="store_true",
                       help="apply a calibration whose CALIB.json names another instrument (refused by default)")

    def attribution_option(s):
        s.add_argument("--attribution", metavar="ORG.toml",
                       help="netCDF: who made and distributes the data (creator_*, publisher_*, institution, license, "
                            "naming_authority, infoUrl, ...: ACDD-1.3/IOOS-1.2 attribute names; "
                            "docs/examples/attribution.toml); default: the file named by the environment variable "
                            "ADCPDYN_ATTRIBUTION, when set, else 'not stated'. The file is named in the export with "
                            "its SHA-256")

    command("scenarios", "list the built-in scenarios", cmd_scenarios)

    s = command("cache", "where the compiled per-ping models are kept, how many, and how to empty it", cmd_cache)
    s.add_argument("--clear", action="store_true", help="delete them (they are built again when needed)")
    s.add_argument("--list", type=_seed, default=10, metavar="N", help="name the N newest")

    s = command("simulate", "simulate a scenario into a case file (a survey's transects with --runs)", cmd_simulate)
    s.add_argument("scenario", help="a built-in scenario (`adcpdyn scenarios`)")
    s.add_argument("--seed", type=_seed, default=0, help="noise seed")
    s.add_argument("--out", required=True, help="CASE.h5; with --runs a folder (NAME_run01.h5, ...)")
    s.add_argument("--runs", type=_count,
                   help="a survey's number of transects (alternating banks; seeds SEED, SEED+1, ...)")
    s.add_argument("--compass-deg", type=_finite, nargs=3, metavar=("A", "B", "C"),
                   help="survey: fix the compass deviation (heading reads psi + A + B sin psi + C cos psi); default drawn")
    s.add_argument("--bed-speed", type=_finite, help="survey: fix the moving bed's speed downstream, m/s; default drawn")
    s.add_argument("--bed-profile", choices=["uniform", "parabolic"], help="survey: bed speed across the section")

    s = command("import", "import a TRDI PD0 or Nortek AD2CP file into a case file", cmd_import)
    s.add_argument("file", help="instrument file (.PD0, .000, .ENS, .ENR, .ad2cp, ...)")
    s.add_argument("--out", required=True, help="CASE.h5 (never the input file)")
    s.add_argument("--start", type=_finite, help="first ping to keep, seconds from the file's first ping")
    s.add_argument("--end", type=_finite, help="last ping to keep, seconds from the file's first ping")
    s.add_argument("--salinity-psu", type=_finite, help="the water's salinity (ppt) where the instrument's setting was "
                   "wrong: its sound speed recomputed from the recorded temperature, every radial and range rescaled")
    s.add_argument("--every", type=_count, default=1, help="keep every n-th ping (decimation for long files)")

    s = command("info", "summarise a case file", cmd_info)
    s.add_argument("case", help="CASE.h5")

    def batch_options(s):
        s.add_argument("--scheduler", default="auto",
                       help="many cases: auto (in this process for 1-2 cases, else a Dask LocalCluster), local (a "
                            "LocalCluster), none (one after another here) or a scheduler address tcp://HOST:PORT; "
                            "calibrate of one case or --joint: where its starts are solved (auto: here)")
        s.add_argument("--workers", type=_count, default=None, help="many cases: LocalCluster worker processes "
                       "(default: one per CPU, at most one per case); one calibration: threads here, or "
                       "LocalCluster processes with --scheduler local")

    s = command("correct", "correct every ping of a case (or of many: files, a folder or a glob)", cmd_correct)
    s.add_argument("case", nargs="+", help="case file(s), folder(s) or glob pattern(s)")
    batch_options(s)
    s.add_argument("--method", default="asc", choices=CORRECTION_METHODS,
                   help="asc: static (installation angles or heading misalignment); adc, paper_literal, rootfinder: "
                        "dynamic, with the calibration's lever arms; oracle: a simulated case's truth")
    s.add_argument("--timing", default="deep", choices=TIMINGS,
                   help="travel-time model of the dynamic methods: deep (Eqs. 66-70), shallow, or exact (rootfinder, "
                        "oracle: travel time with the moving transducer)")
    s.add_argument("--calibration", help="CALIB.json from `adcpdyn calibrate`")
    accept_other_instrument_option(s)
    s.add_argument("--reference", default="bt", choices=REFERENCES,
                   help="water velocities referenced to the bottom track (bt) or to the GNSS velocity (gnss)")
    s.add_argument("--out", required=True, help="output file (OUT.h5, or OUT.nc for CF netCDF); with many cases, a folder")
    attribution_option(s)

    s = command("export", "a case or a corrected file as CF-1.8 / ACDD-1.3 / IOOS-1.2 netCDF (ENU, UTC time, "
                          "xarray-ready)", cmd_export)
    s.add_argument("input", help="CASE.h5 or the output of `adcpdyn correct` (OUT.h5)")
    s.add_argument("--case", help="a corrected file's case (default: the case it names)")
    s.add_argument("--out", required=True, help="OUT.nc")
    attribution_option(s)

    s = command("compare", "every correction method on one case: metrics table and figures", cmd_compare)
    s.add_argument("case", help="CASE.h5 (with /truth, or a GNSS reference)")
    s.add_argument("--calibration", help="CALIB.json from `adcpdyn calibrate` (without one: asc and oracle only)")
    accept_other_instrument_option(s)
    s.add_argument("--out", help="folder for the table (JSON) and figure")
    figure_format(s)

    def calibration_options(s):
        s.add_argument("--formulation", default="exact", choices=["paper", "exact", "minimal", "free"],
                       help="lever-arm constraints: paper (Janus conditions relaxed), exact (equalities), minimal "
                            "(r_i = Lambda T_i + P), free (twelve coordinates)")
        s.add_argument("--starts", type=_count, default=24, help="multistart size")
        s.add_argument("--seed", type=_seed, default=0, help="seed of the start design")
        s.add_argument("--method", default="joint", choices=["joint", "two-stage"],
                       help="joint (one NLP) or two-stage (the paper's)")
        s.add_argument("--timing", default="auto", choices=["auto", "shallow", "deep", "exact"],
                       help="bottom-track model (auto: by the round-trip time)")
        s.add_argument("--tangential", default="consistent", choices=["consistent", "paper_literal"],
                       help="tangential velocity dLambda/dt r (consistent) or the printed Omega r")
        s.add_argument("--attitude", default="auto", choices=["auto", "model", "samples"],
                       help="the beams' attitude: model (damped-mode model fitted jointly), samples (the sensor's "
                            "samples, for runs no motion model follows) or auto")
        s.add_argument("--jacobian", default="auto", choices=["auto", "symbolic", "assembled"],
                       help="symbolic (whole problem differentiated by CasADi) or assembled (per row, long runs)")
        s.add_argument("--compile", default="auto", choices=["auto", "always", "never"],
                       help="the assembled problem's per-ping model as machine code from the per-machine cache "
                            "(`adcpdyn cache`; built by the C compiler the first time, same numbers): auto when the runs "
                            "hold 500 pings or more together (the Jacobian then assembled), always "
                            "(with --jacobian assembled) or never")
        s.add_argument("--navigation", default="knots", choices=["knots", "random_walk", "auto"],
                       help="the vessel's velocity: knots (piecewise-linear), random_walk (a velocity at every ping, "
                            "its random-walk intensity and the noise levels from the data) or auto (random_walk for "
                            "a run under way whose beams take the sensor's samples, as a real file's do)")
        s.add_argument("--moving-bed", default="auto", choices=["auto", "off", "constant", "section"],
                       help="bed moving under the bottom track: auto (with a moving reference a constant bed, kept only "
                            "when a test says it moves), off (a bed verified fixed), constant, or section (a function "
                            "of the position along the section)")
        s.add_argument("--bed-knots", type=_int_at_least(2), default=None,
                       help="--moving-bed section: values across the section (default 3)")
        s.add_argument("--compass-deviation", default="auto", choices=["auto", "on", "off"],
                       help="head sensor: add B sin(heading) + C cos(heading) to the misalignment (auto: with a prior, "
                            "when the headings span enough)")
        s.add_argument("--compass-deviation-prior-deg", type=_deviation_prior_deg, default=None,
                       help="--compass-deviation auto: the one-cycle deviation left after the compass's own calibration, "
                            "one standard deviation of B and of C in degrees (default 1: the prior N(0, 1 deg^2) each)")
        s.add_argument("--standard-errors", default="hac", choices=["hac", "white"],
                       help="hac (Newey-West sandwich, coloured residuals) or white")
        s.add_argument("--declination-deg", type=_angle_deg,
                       help="magnetic declination at the site (east positive), when the cases carry no position and date")
        s.add_argument("--solver", default="ipopt", choices=list(METHODS),
                       help="NLP solver of the multistart (ipopt; CasADi's SQP, interior-point and augmented-Lagrangian "
                            "plugins; scipy least_squares on the residuals): `adcpdyn bench solvers` compares them")

    s = command("calibrate", "estimate attitude model, lever arms and installation angles (one or many cases)",
                cmd_calibrate)
    s.add_argument("case", nargs="+", help="case file(s), folder(s) or glob pattern(s)")
    calibration_options(s)
    batch_options(s)
    s.add_argument("--joint", action="store_true",
                   help="several runs of one boat at one site in ONE NLP (shared lever arms, installation or heading "
                        "misalignment, moving bed); --out is then one CALIB.json")
    s.add_argument("--out", required=True, help="CALIB.json; with many cases (not --joint), a folder (CASE.json each, summary.json)")

    s = command("compare-formulations", "calibrate with every constraint formulation and tabulate",
                cmd_compare_formulations)
    s.add_argument("case", help="CASE.h5")
    calibration_options(s)
    s.add_argument("--out", help="optional JSON of the table")

    s = command("diagnose", "where the sim-to-real gap lies, which unmodelled effect causes it, how far it shrinks",
                cmd_diagnose)
    s.add_argument("case", nargs="*", help="CASE.h5 (omit with --selftest); with --joint several runs, folders or globs")
    s.add_argument("--joint", action="store_true",
                   help="several runs of one boat together: shared effects (compass, beams, sound speed, latency, lever "
                        "arms) and per-run ones (moving bed, heave, forced roll); whole runs held out too")
    s.add_argument("--calibration", help="CALIB.json from `adcpdyn calibrate` (its platform quantities pinned in the base)")
    accept_other_instrument_option(s)
    s.add_argument("--out", help="DIAG.json (DIAG.md and a figure are written beside it)")
    s.add_argument("--effects", nargs="+", metavar="EFFECT", help="catalog effects to try (default: all)")
    s.add_argument("--attitude", default="auto", choices=["auto", "model", "samples"],
                   help="the beams' attitude: model (damped-mode motion model), samples (the sensor's samples, runs no "
                        "model follows) or auto")
    s.add_argument("--given", nargs="+", default=(), metavar="EFFECT",
                   help="effects the run is known to carry (e.g. what its clean run named): fitted first and kept, "
                        "the candidates judged on top of them")
    s.add_argument("--navigation", default="auto", choices=["auto", "random_walk", "knots"],
                   help="the base's vessel velocity: random_walk (a velocity at every ping, its random-walk intensity "
                        "from the data: a real boat's speed changes between fixes are motion), knots (a smooth curve) "
                        "or auto: random_walk where the beams take the attitude sensor's samples (every real file), knots where a "
                        "motion model follows the attitude or the reference is stationary")
    s.add_argument("--field-selftest", action="store_true",
                   help="what this file can detect: the field's errors (compass offset, attitude and reference latency, "
                        "moving bed, sound speed, tilt low-pass, heave) injected at typical sizes into its recorded "
                        "channels, each diagnosed blind with its calibration (--calibration, else calibrated on itself); "
                        "with --effects only the errors those can name; with --joint a survey's runs, each error in "
                        "every run, diagnosed jointly")
    s.add_argument("--selftest", type=_count, metavar="N", help="blind self-test on N simulated cases")
    s.add_argument("--seed", type=_seed, default=0, help="seed of the self-test draws")
    s.add_argument("--selftest-calibrated", action="store_true",
                   help="self-test in the paper's workflow: each platform calibrated on an effect-free run of its own, "
                        "each case diagnosed with that calibration")
    s.add_argument("--platforms", nargs="+", choices=["launch_vessel", "launch_head", "pool", "survey_ship", "river"],
                   help="self-test platforms to draw from (default: all)")
    figure_format(s)

    s = command("bench", "benchmarks with their targets", cmd_bench)
    s.add_argument("suite", choices=["calibration", "correction", "formulations", "solvers", "scale", "survey", "surveyday", "diagnosis",
                                     "diagnosis-survey", "compliance", "navigation"],
                   help="which benchmark")
    s.add_argument("--quick", action="store_true", help="fewer seeds")
    s.add_argument("--out", default="benchmarks/results", help="folder of the results")
    s.add_argument("--readme", metavar="FILE", help="solvers suite: put its tables between FILE's solver-table markers "
                                                    "(docs/benchmarks.md)")

    s = command("demo", "the main job on the built-in default case", cmd_demo)
    s.add_argument("--scenario", nargs="+", default=list(DEFAULT_CASES), help="measurement runs to correct")
    s.add_argument("--calibration-scenario", default="pool_m0", help="calibration run")
    s.add_argument("--starts", type=_count, default=24, help="multistart size")
    s.add_argument("--seed", type=_seed, default=1, help="noise seed")
    s.add_argument("--out", default="demo_out", help="output folder")
    figure_format(s)
    return p


class Terminated(BaseException):
    """SIGTERM as an exception, so that atomic writers remove their temporary files."""


def _terminate(signum, frame):
    raise Terminated(f"terminated by signal {signum}")


@contextlib.contextmanager
def _sigterm_as_exception():
    """Turn SIGTERM into :class:`Terminated` while a command runs (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


class _HeldStderr:
    """File descriptor 2 held in a temporary file while a command runs.

    Solver libraries (CasADi, IPOPT, LAPACK) write their own warnings straight to the
    descriptor. A command that succeeds gets them back afterwards, in order; one that
    ends in a one-line error drops them, so that the error is the only line.
    """

    def __init__(self):
        self._saved = self._sink = None

    def __enter__(self):
        global _LIVE_FD
        with contextlib.suppress(Exception):
            sys.stderr.flush()
        try:
            self._saved = os.dup(2)
            self._sink = tempfile.TemporaryFile()
            os.dup2(self._sink.fileno(), 2)
            _LIVE_FD = self._saved  # progress lines still reach the terminal (_Progress)
        except OSError:
            self._saved = self._sink = None
        return self

    def __exit__(self, *exc):
        global _LIVE_FD
        if self._saved is not None:
            with contextlib.suppress(Exception):
                sys.stderr.flush()
            os.dup2(self._saved, 2)
            os.close(self._saved)
            _LIVE_FD = None
        return False

    def replay(self) -> None:
        if self._sink is not None:
            self._sink.seek(0)
            data = self._sink.read()
            if data:
                with contextlib.suppress(Exception):
                    sys.stderr.flush()
                os.write(2, data)
            self._sink.close()

    def drop(self) -> None:
        if self._sink is not None:
            self._sink.close()


def _holds_stderr(args) -> bool:
    """Not for what shows progress on stderr: the self-test, benchmarks, many cases."""
    from .cases.collect import is_many

    if getattr(args, "selftest", None) or args.command in ("bench", "demo"):
        return False
    case = getattr(args, "case", None)
    return not (isinstance(case, list) and is_many(case))


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0) or an option error, said in one line by the parser (2)
        return int(exc.code or 0)
    held = _HeldStderr() if _holds_stderr(args) else contextlib.nullcontext()
    error = None
    try:
        with _sigterm_as_exception(), held:
            code = args.func(args)
    except BrokenPipeError:  # the reader stopped reading (`| head`): quiet, as a shell's SIGPIPE death
        with contextlib.suppress(OSError, ValueError):  # nothing more to flush at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 128 + signal.SIGPIPE
    except (ValueError, OSError) as exc:
        # CaseFormatError is a ValueError; every user-facing error is one line.
        error, code = f"adcpdyn {args.command}: error: {_one_line(exc)}", 2
    except Terminated as exc:
        error, code = f"adcpdyn {args.command}: {exc}; stopped (no partial file left)", 128 + signal.SIGTERM
    except KeyboardInterrupt:
        error, code = f"adcpdyn {args.command}: interrupted; stopped (no partial file left)", 128 + signal.SIGINT
    except BaseException:
        if isinstance(held, _HeldStderr):
            held.replay()
        raise
    if isinstance(held, _HeldStderr):
        held.drop() if error else held.replay()
    if error:
        print(error, file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
