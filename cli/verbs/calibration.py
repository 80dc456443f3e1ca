"""calibrate (one run, a survey with --joint, or many cases) and compare-formulations."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...text import noise_levels_line
from ..terminal import Progress, say, warn
from .cases import prepare
from .correction import batch_out, run_batch_table


def calibration_config(args, formulation=None, one=True):
    """The CalibrationConfig of the flags; ``one``: a single calibration, whose starts go where
    --scheduler/--workers say (with many cases those flags place the cases, each solved in its worker)."""
    from ...estimators.calibration.config import CalibrationConfig

    if args.bed_knots is not None and args.moving_bed != "section":
        raise ValueError(f"--bed-knots {args.bed_knots}: sets the values of --moving-bed section, not of --moving-bed "
                         f"{args.moving_bed} (drop it, or use --moving-bed section)")
    prior_deg = getattr(args, "compass_deviation_prior_deg", None)
    if prior_deg is not None and args.compass_deviation != "auto":
        raise ValueError(f"--compass-deviation-prior-deg {prior_deg:g}: the prior of --compass-deviation auto, not of "
                         f"--compass-deviation {args.compass_deviation} (drop it, or use --compass-deviation auto)")
    prior = {} if prior_deg is None else {"compass_deviation_prior_rad": float(np.deg2rad(prior_deg))}
    screen = getattr(args, "screen_pings", 2000)
    if screen != 0 and screen < 100:
        raise ValueError(f"--screen-pings {screen}: expected 0 (every start on all pings) or at least 100 pings")
    from ...solvers.multistart import SolverOptions

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
                             own_effects=getattr(args, "own_effects", "auto"), screen_pings=screen or None,
                             solver=SolverOptions(method=args.solver))


def _print_calibration(result, title: str) -> None:
    """What a calibration found, with standard errors, in the field's words."""
    ms = result.multistart
    deg = np.rad2deg
    say(f"{title}: {result.config.method} calibration, formulation {result.formulation}, {result.timing}-water model, "
        f"{result.jacobian} Jacobian" + (" (the graph of an earlier problem of this shape)" if result.graph == "kept" else "")
        + f", beams' attitude from the {result.attitude_source}")
    say(f"solver: {ms.message}; objective {result.objective:.6g}; max constraint violation "
        f"{result.max_constraint_violation:.2e}; solver time {ms.time_s:.2f} s summed over the starts")
    if result.instrument is not None:
        say(f"instrument: {result.instrument.label()}")
    label = "head-frame lever arms (m)" if result.attitude_frame == "transducer" else "radius vectors, body frame (m)"
    arms, arms_se = np.asarray(result.lever_arms_sensor_m), np.asarray(result.lever_arms_sensor_se_m)
    one_point = bool(np.all(arms == arms[0]))  # a transducer radius of 0 (not in the file) puts all four at P
    if not np.isfinite(arms_se).any():
        say(f"{label}: not determined (the warnings say why)")
    else:
        say(label + "  [value +- se]" + ("; the four transducers at one point (the case's transducer radius is 0)"
                                         if one_point else ""))
    for i in range(0 if not np.isfinite(arms_se).any() else 1 if one_point else 4):
        cells = "  ".join(f"{v:+.4f} +- {s:.4f}" if np.isfinite(s) else "  (not determined)  "
                          for v, s in zip(arms[i], arms_se[i]))
        say(f"  {'r1-r4' if one_point else f'r{i + 1}'}: {cells}")
    if_moves = {c["pair"][0]: c for c in result.confounded if "se_if_bed_moves_rad" in c}

    def bed_fixed(name: str) -> str:  # the bed tested and dropped: the pair's other reading, in the headline
        c = if_moves.get(name)
        decision = (result.moving_bed_test or {}).get("decision", "undetermined")
        return "" if c is None else (f" with the bed fixed [moving-bed test {decision}; with the bed free "
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
    own = result.own_effects
    if own is not None:
        say(own_effects_line(own))
    for w in result.warnings:
        warn(f"{w}")


def own_effects_line(own: dict) -> str:
    """What the runs showed diagnosed on top of the calibration, in one line, each unknown in its unit."""
    from ...estimators.diagnosis.report import parameter_text
    from ...models.effects import effect_of
    from ...estimators.diagnosis.statement import OTHER_BASE

    head = "own effects (these runs diagnosed on top of the calibration, held when they are diagnosed again): "
    if not own["effects"]:
        return head + "none"
    parts = []
    for effect in own["effects"]:
        mine = [parameter_text(n, v["value"], v["se"]) for n, v in own["unknowns"].items()
                if effect_of(n) == effect]
        parts.append(f"{effect} ({', '.join(mine)})")
    statement = own.get("statement") or ""
    other_base = statement[statement.find(OTHER_BASE):].split(" [base:")[0] if OTHER_BASE in statement else ""
    return head + "; ".join(parts) + (f" ({other_base})" if other_base else "")


def cmd_calibrate(args) -> int:
    from ...api import calibrate
    from ...cases.atomic import check_output_file
    from ...cases.collect import collect_case_paths, is_many

    if is_many(args.case) and not args.joint:
        from ...batch import CalibrateJob, check_scheduler

        check_scheduler(args.scheduler)
        config = calibration_config(args, one=False)
        paths, out = collect_case_paths(args.case), batch_out(args)
        jobs = [CalibrateJob(str(p), str((out / f"{p.stem}.json").resolve()), config) for p in paths]
        return run_batch_table(args, jobs, [("objective", "objective", 12, "{:.6g}".format),
                                       ("max viol", "max_constraint_violation", 10, "{:.1e}".format),
                                       ("at best", "fraction_at_best", 9, "{:.2f}".format)])
    if args.joint and args.method == "two-stage":
        raise ValueError("--method two-stage: the paper's two-stage baseline calibrates one run in two steps; --joint "
                         "is the one-NLP calibration of several runs (drop one of them)")
    if Path(args.out).suffix.lower() != ".json":
        raise ValueError(f"--out: expected a CALIB.json file name ending in .json (calibrate writes JSON), got {args.out!r}")
    from ...batch import check_scheduler

    check_scheduler(args.scheduler)  # in the user's flag's words, before the config's own check
    paths = collect_case_paths(args.case) if args.joint else [args.case[0]]
    check_output_file(args.out, *paths)
    config = calibration_config(args)
    result = calibrate(paths if args.joint else paths[0], config, progress=Progress("calibrate"))
    names = [c["name"] for c in result.provenance["cases"]]
    title = f"{len(names)} runs ({', '.join(names)}), one NLP" if args.joint else names[0]
    result.to_json(args.out)
    _print_calibration(result, title)
    print(f"wrote {args.out}")
    return 0 if result.success else 1


def cmd_compare_formulations(args) -> int:
    from ...cases.atomic import check_output_file
    from ...estimators.calibration.formulation_compare import compare_formulations, format_rows

    if args.out:
        check_output_file(args.out, args.case)
    case, _ = prepare(args.case)
    rows = compare_formulations(case, calibration_config(args))
    print(format_rows(rows))
    if args.out:
        from ...benchmarks.common import write_json

        write_json(rows, Path(args.out))
    return 0
