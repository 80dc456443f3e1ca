"""demo (the main job on the built-in default cases) and bench (the benchmark suites)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...estimators.correction.correct_case import CORRECTION_METHODS, correct_case
from ..terminal import say, warn
from .cases import read
from .correction import load_calibration


def cmd_demo(args) -> int:
    """The paper's pipeline on built-in cases: calibrate on pool_m0, correct pool_m1 and pool_m2."""
    from ...cases.corrected import write_correction
    from ...cases.io import write_case
    from ...cases.scenario import get_scenario
    from ...cases.summary import summarise
    from ...estimators.calibration.config import CalibrationConfig
    from ...estimators.calibration.problem import CalibrationProblem
    from ...estimators.statistics.evaluation import calibration_errors
    from ...estimators.statistics.metrics import format_table, velocity_metrics
    from ...models.rotations import euler_matrix
    from ...cases.simulation import simulate
    from ...plots import attitude_fit_figure, radius_vectors_figure, velocity_figure

    from ...cases.atomic import check_output_folder

    out = check_output_folder(args.out)
    out.mkdir(exist_ok=True)
    cases = {}
    for name in (args.calibration_scenario, *args.scenario):
        case = simulate(get_scenario(name), seed=args.seed)
        write_case(case, out / f"{name}.h5")
        cases[name] = read(out / f"{name}.h5")

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
    calibration = load_calibration(out / "calibration.json")
    summary = {"calibration": err}
    for name in args.scenario:
        case = cases[name]
        vt = case.truth.vessel_velocity_m_s
        results = {m: correct_case(case, m, calibration) for m in CORRECTION_METHODS}
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
    from ...cases.atomic import atomic_path

    with atomic_path(out / "metrics.json") as tmp, open(tmp, "w") as fh:
        json.dump(summary, fh, indent=2)
    fmt = args.format
    print()
    say(f"saved in {out}/: calibration.json, attitude_fit.{fmt}, radius_vectors.{fmt}, "
        + ", ".join(f"{n}_velocity.{fmt}" for n in args.scenario) + ", metrics.json, corrected and case files")
    return 0


def cmd_bench(args) -> int:
    from ...cases.atomic import check_output_folder
    from ...benchmarks.suites import run

    check_output_folder(args.out)
    run(args.suite, args.quick, Path(args.out), readme=Path(args.readme) if args.readme else None)
    return 0
