"""diagnose: one case, a survey (--joint), the self-tests (--selftest, --field-selftest)."""

from __future__ import annotations

import json
from pathlib import Path


from ..terminal import DiagnosisProgress, Progress, progress_enabled, warn


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
    if args.ignore_own_effects and (args.given or args.selftest or args.field_selftest or not args.calibration):
        other = ("--given (given effects are fitted, nothing is held)" if args.given else
                 "--selftest / --field-selftest (they find and hold the runs' own effects themselves)"
                 if args.selftest or args.field_selftest else "no --calibration (nothing to hold)")
        raise ValueError(f"--ignore-own-effects: drops what a calibration's own runs showed when calibrated; "
                         f"with {other} it has nothing to do (drop it)")
    if args.selftest:
        return _diagnose_selftest(args)
    if args.field_selftest:
        return _diagnose_field_selftest(args)
    from ...api import diagnose
    from ...estimators.diagnosis.report import terminal_text, write_report

    paths = _diagnosis_paths(args, "diagnose: expected CASE.h5 and --out DIAG.json (or --selftest N)",
                             "diagnose them together (one boat, shared and per-run effects)")
    progress = DiagnosisProgress("diagnose", len(paths))
    result = diagnose(paths if args.joint else paths[0], args.calibration, effects=args.effects, attitude=args.attitude,
                      navigation=args.navigation, given=args.given, progress=progress.fitted_model,
                      hold_own_effects=not args.ignore_own_effects,
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
    from ...cases.atomic import check_output_file
    from ...cases.collect import collect_case_paths, is_many

    if not args.case or not args.out:
        raise ValueError(usage)
    if is_many(args.case) and not args.joint:
        raise ValueError(f"diagnose: {' '.join(args.case)}: several cases (a folder, a glob or more than one file): add "
                         f"--joint to {joint}")
    paths = collect_case_paths(args.case) if args.joint else [args.case[0]]
    check_output_file(args.out, *paths, args.calibration)
    return paths


def _diagnose_field_selftest(args) -> int:
    from ...api import field_selftest
    from ...estimators.diagnosis.field_selftest import terminal_field_selftest

    paths = _diagnosis_paths(args, "diagnose: --field-selftest expects CASE.h5 (several with --joint: a survey) and "
                             "--out SELFTEST.json", "self-test them as one survey")
    res = field_selftest(paths if args.joint else paths[0], args.calibration, navigation=args.navigation, effects=args.effects,
                         accept_other_instrument=args.accept_other_instrument,
                         attitude=args.attitude, out=args.out, fmt=args.format,
                         progress=Progress("diagnose"))
    for n in res["notes"]:
        warn(n)
    print(terminal_field_selftest(res))
    print(f"wrote {args.out} and its .md and figure beside it")
    return 0


def _diagnose_selftest(args) -> int:
    from tqdm import tqdm

    from ...cases.atomic import atomic_path, check_output_file
    from ...estimators.calibration.result import jsonable
    from ...api import _diagnosis_config
    from ...estimators.diagnosis.selftest import draw_cases, format_summary, run_one, summarise

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
