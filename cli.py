"""Command line: ``adcpdyn simulate | info | correct | scenarios | demo``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

DEFAULT_CASE = "pool_m1"


def _read(path):
    from .cases.io import read_case

    return read_case(path)


def cmd_scenarios(args) -> int:
    from .cases.scenario import load_scenarios

    for name, sc in load_scenarios().items():
        print(f"{name:<20} {sc.platform.name:<14} {sc.run.description}")
    return 0


def cmd_simulate(args) -> int:
    from .cases.io import write_case
    from .cases.scenario import get_scenario
    from .models.simulator import simulate

    case = simulate(get_scenario(args.scenario), seed=args.seed)
    write_case(case, args.out)
    print(f"wrote {args.out}: {case.pings.n} pings, {case.attitude.time_s.size} attitude samples")
    return 0


def cmd_info(args) -> int:
    from .cases.summary import summarise

    print(summarise(_read(args.case)))
    return 0


def _installation_from(calibration_path):
    if calibration_path is None:
        return None
    with open(calibration_path) as fh:
        calib = json.load(fh)
    if "installation_ypr_rad" not in calib:
        raise ValueError(f"{calibration_path}: installation_ypr_rad: missing; expected 3 angles in radians")
    return np.asarray(calib["installation_ypr_rad"], dtype=float)


def cmd_correct(args) -> int:
    from .cases.atomic import refuse_overwrite_input
    from .cases.corrected import write_correction
    from .estimators.asc import asc

    refuse_overwrite_input(args.out, args.case, args.calibration)
    case = _read(args.case)
    if args.method != "asc":
        raise ValueError(f"--method: {args.method!r} is not available yet; expected one of ['asc']")
    result = asc(case, _installation_from(args.calibration))
    write_correction(result, args.out, source_case=str(args.case))
    v = result.vessel_velocity_m_s
    print(f"wrote {args.out}: method {result.method}, {len(v)} pings, "
          f"mean horizontal speed {np.nanmean(np.hypot(v[:, 0], v[:, 1])):.4f} m/s, "
          f"{int(np.sum(result.beams_used == 3))} three-beam pings, {int(np.sum(result.beams_used < 3))} lost")
    return 0


def cmd_demo(args) -> int:
    """The main job on the built-in default case: simulate, ASC-correct, tabulate, plot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .cases.corrected import write_correction
    from .cases.io import write_case
    from .cases.scenario import get_scenario
    from .cases.summary import summarise
    from .estimators.asc import asc
    from .estimators.metrics import format_table, velocity_metrics
    from .models.simulator import simulate

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    case = simulate(get_scenario(args.scenario), seed=args.seed)
    case_path = out / f"{args.scenario}.h5"
    write_case(case, case_path)
    print(summarise(_read(case_path)))
    corr = asc(case)
    write_correction(corr, out / f"{args.scenario}_asc.h5", source_case=str(case_path))
    truth = case.truth.vessel_velocity_m_s
    table = {"asc": velocity_metrics(corr.time_s, corr.vessel_velocity_m_s, truth),
             "truth": velocity_metrics(corr.time_s, truth, truth)}
    print()
    print(format_table(table))
    with open(out / "metrics.json", "w") as fh:
        json.dump(table, fh, indent=2)

    t = corr.time_s
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(t, np.hypot(*corr.vessel_velocity_m_s[:, :2].T), "b.-", label="ASC")
    ax[0].plot(t, np.hypot(*truth[:, :2].T), "k--", label="truth")
    ax[0].set_ylabel("horizontal speed (m/s)")
    ax[0].legend()
    ax[1].plot(t, np.rad2deg(np.arctan2(corr.vessel_velocity_m_s[:, 1], corr.vessel_velocity_m_s[:, 0])), "b.", label="ASC")
    ax[1].plot(t, np.rad2deg(np.arctan2(truth[:, 1], truth[:, 0])), "k--", label="truth")
    ax[1].set_ylabel("direction (deg from north)")
    ax[1].set_xlabel("time (s)")
    fig.suptitle(f"{args.scenario} (seed {args.seed}): attitude static correction vs truth")
    fig.tight_layout()
    fig.savefig(out / "asc_vs_truth.png", dpi=120)
    print(f"\nsaved {out / 'asc_vs_truth.png'}, {out / 'metrics.json'}, {case_path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="adcpdyn", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("scenarios", help="list the built-in scenarios")
    s.set_defaults(func=cmd_scenarios)

    s = sub.add_parser("simulate", help="simulate a scenario into a case file")
    s.add_argument("scenario")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--out", required=True)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("info", help="summarise a case file")
    s.add_argument("case")
    s.set_defaults(func=cmd_info)

    s = sub.add_parser("correct", help="correct every ping of a case")
    s.add_argument("case")
    s.add_argument("--method", default="asc")
    s.add_argument("--calibration", help="CALIB.json with installation_ypr_rad")
    s.add_argument("--out", required=True)
    s.set_defaults(func=cmd_correct)

    s = sub.add_parser("demo", help="the main job on the built-in default case")
    s.add_argument("--scenario", default=DEFAULT_CASE)
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--out", default="demo_out")
    s.set_defaults(func=cmd_demo)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        # CaseFormatError is a ValueError; every user-facing error is one line.
        print(f"adcpdyn {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
