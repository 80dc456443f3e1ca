"""``adcpdyn bench diagnosis``: the diagnosis on real instrument files, clean and with the field's
errors injected on their recorded channels (:mod:`adcpdyn.estimators.diagnosis.field_errors`),
each diagnosed with the clean file's own calibration, for both bases (navigation ``knots`` and
``random_walk``) in the same run.

Per file, error, size and base: the verdict, whether the injected error's effect is named (top-1),
the held-out gap and its z, the effect's estimate, and the wall time. Clean files count a false
alarm when any effect is named. Files come from ``ADCPDYN_REAL_DATA`` (default ../shared/data/real);
a missing file is listed, not an error; ``ADCPDYN_BENCH_NAVIGATION`` (``knots`` or ``random_walk``)
runs one base only.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from .common import Target, machine, print_targets, real_cases, real_dir, save_figure

FILES = ("RiverPro_test01.PD0", "winriver01.PD0", "winriver02_transect.PD0")
NAVIGATIONS = ("knots", "random_walk")


def bench_diagnosis(quick: bool) -> dict:
    """Every file through ``api.field_selftest`` (the same code as ``diagnose --field-selftest``),
    calibrated once on itself, for each base."""
    from .. import api

    rows, missing = [], []
    sizes = _sizes(quick)
    for name, path, case in real_cases(FILES[:1] if quick else FILES, missing):
        tic = time.perf_counter()
        calibration = api.calibrate(case, n_starts=8)
        calib_s = time.perf_counter() - tic
        for nav in [n for n in NAVIGATIONS if os.environ.get("ADCPDYN_BENCH_NAVIGATION", n) == n]:
            res = api.field_selftest(case, calibration, navigation=nav, sizes=sizes)
            for r in res["rows"]:
                rows.append({"file": name, "pings": case.pings.n, "navigation": nav, "calibration_s": calib_s,
                             **{k: v for k, v in r.items() if k != "statement"}})
                print(f"{name:>26s} {r['error']:>22s} {r['size']:6.2f} {nav:>11s} -> {r['verdict']:<28s} "
                      f"gap {r['gap']:7.3f} z {r['gap_z']:8.1f}  {r['seconds']:5.1f} s", flush=True)
    return {"machine": machine(), "rows": rows, "missing": missing, "summary": _summary(rows),
            "speed": [] if quick else [long_transect_speed()]}


def _sizes(quick: bool) -> dict:
    """The field errors' typical sizes, the largest alone in quick mode."""
    from ..estimators.diagnosis.field_errors import FIELD_ERRORS

    return {e: (spec[2][-1:] if quick else spec[2]) for e, spec in FIELD_ERRORS.items()}


SURVEY_FILE = "winriver02_transect.PD0"
SURVEY_WINDOWS_S = ((None, 230.0), (230.0, None))  # the README's survey: the transect's two halves as two runs


def bench_diagnosis_survey(quick: bool) -> dict:
    """``adcpdyn bench diagnosis-survey``: a real survey, the README's (winriver02 cut at 230 s into two
    runs), calibrated jointly on itself and put through ``api.field_selftest`` as one survey (each error
    in both runs, the bed one velocity downstream), on the random-walk base. The
    rows and summary are :func:`bench_diagnosis`'s, so its printer, table and limits paragraph serve."""
    from .. import api
    from ..estimators.diagnosis.field_errors import survey_course

    rows, missing, survey = [], [], {}
    path = real_dir() / SURVEY_FILE
    if not path.exists():
        missing.append(str(path))
    else:
        stem = SURVEY_FILE.split(".")[0]
        cases = [api.import_file(path, start_s=a, end_s=b, name=f"{stem}_{k + 1}").case
                 for k, (a, b) in enumerate(SURVEY_WINDOWS_S)]
        label = f"{stem} survey ({' + '.join(f'{a or 0:g}-{b:g} s' if b else f'{a:g} s-end' for a, b in SURVEY_WINDOWS_S)})"
        survey = {"file": SURVEY_FILE, "label": label, "windows_s": [list(w) for w in SURVEY_WINDOWS_S],
                  "pings": [c.pings.n for c in cases],
                  "courses_deg": [float(np.degrees(survey_course(c))) for c in cases]}
        sizes = _sizes(quick)
        tic = time.perf_counter()
        calibration = api.calibrate(cases, n_starts=8)
        calib_s = time.perf_counter() - tic
        res = api.field_selftest(cases, calibration, navigation="random_walk", sizes=sizes)
        for r in res["rows"]:
            rows.append({"file": label, "pings": sum(survey["pings"]), "navigation": "random_walk", "calibration_s": calib_s,
                         **{k: v for k, v in r.items() if k != "statement"}})
            print(f"{'survey':>26s} {r['error']:>22s} {r['size']:6.2f} {'random_walk':>11s} -> {r['verdict']:<28s} "
                  f"gap {r['gap']:7.3f} z {r['gap_z']:8.1f}  {r['seconds']:5.1f} s", flush=True)
    return {"machine": machine(), "rows": rows, "missing": missing, "summary": _summary(rows), "speed": [],
            "survey": survey}


def print_diagnosis_survey(res: dict) -> None:
    sv = res.get("survey") or {}
    if sv:
        print(f"\na real survey: {sv['label']}, {' + '.join(map(str, sv['pings']))} pings, courses over ground "
              + ", ".join(f"{c:.1f}" for c in sv["courses_deg"]) + " deg; calibrated jointly on itself, diagnosed jointly")
    print_diagnosis(res)


LONG_TRANSECT_S = 1950.0  # river_survey at 0.5-0.8 s per ping: about 3000 pings


def long_transect_speed(duration_s: float = LONG_TRANSECT_S, seed: int = 4) -> dict:
    """Wall time of one diagnosis (random-walk base) of a long simulated river transect calibrated on
    itself: the speed target's 3000 pings, which no real file here has with bottom track and GNSS."""
    import dataclasses

    from .. import api
    from ..cases.scenario import get_scenario
    from ..cases.simulation import simulate

    sc = get_scenario("river_survey")
    case = simulate(dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=duration_s)), seed=seed)
    calibration = api.calibrate(case, n_starts=8)
    tic = time.perf_counter()
    r = api.diagnose(case, calibration, navigation="random_walk")
    seconds = time.perf_counter() - tic
    print(f"{'river_survey (simulated)':>26s} {case.pings.n:6d} pings random_walk -> {r.verdict:<28s} {seconds:5.1f} s",
          flush=True)
    return {"case": f"river_survey, {duration_s:g} s, seed {seed}", "pings": case.pings.n, "verdict": r.verdict,
            "truth": [e["name"] for e in case.truth.effects] if case.truth is not None else [], "seconds": seconds}


def _summary(rows: list) -> dict:
    """Per base: the field self-test's summary over all files' rows (top-1, smallest size detected
    per error), the clean files' false alarms and gaps, and the slowest diagnosis."""
    from ..estimators.diagnosis.field_selftest import summarise

    out = {}
    for nav in NAVIGATIONS:
        mine = [r for r in rows if r["navigation"] == nav]
        if not mine:  # a base not run (ADCPDYN_BENCH_NAVIGATION) is not reported as scoring nothing
            continue
        clean = [r for r in mine if r["error"] == "clean"]
        s = summarise(mine)
        del s["clean_verdict"]  # one per file here: the false alarms below
        out[nav] = {**s, "false_alarms": int(sum(r["verdict"] != "none" for r in clean)), "clean_files": len(clean),
                    "clean_gaps": {r["file"]: r["gap"] for r in clean},
                    "own_effects": {r["file"]: r.get("own_effects", []) for r in clean if r.get("own_effects")},
                    # per error and file: the clean run's detection limit (the error's unit)
                    "limits": {e: {r["file"]: r.get("detection_limits", {}).get(e) for r in clean} for e in s["per_error"]},
                    "max_seconds": max((r["seconds"] for r in mine), default=None)}
    return out


def markdown_table(res: dict) -> str:
    """The table of docs/diagnosis.md: per error and size, each file's and base's first verdict (bold when the
    injected error's effect is named first), from the rows as measured."""
    cols = list(dict.fromkeys((r["file"], r["navigation"]) for r in res["rows"]))
    trials = list(dict.fromkeys((r["error"], r["size"]) for r in res["rows"]))
    cell = {(r["file"], r["navigation"], r["error"], r["size"]): r for r in res["rows"]}
    lines = ["| error, size (first verdict; **bold** = the injected error's effect named first) | "
             + " | ".join(f"{f.split('.')[0]} {n}" for f, n in cols) + " |", "|---|" + "---|" * len(cols)]
    for error, size in trials:
        row = []
        for f, n in cols:
            r = cell.get((f, n, error, size))
            text = "" if r is None else r["verdict"]
            if r is not None and not r["hit"] and r.get("detection_limit_reason"):
                text += " (under the file's limit: read against its own delay peak)"
            elif r is not None and not r["hit"] and r.get("outcome", "").startswith("under the file's detection limit"):
                text += (f" (under the file's limit{', over' if r.get('detection_limit_beyond') else ''} "
                         f"{r['detection_limit']:.2g}{' ' + r['unit'] if r['unit'] else ''})")
            elif r is not None and not r["hit"] and r.get("outcome", "").startswith(("below", "not tried", "outscored", "no gap")):
                text += f" ({r['outcome'].split(' (')[0].split(':')[0]})"
            row.append(f"**{text}**" if r is not None and r["hit"] and error != "clean" else text)
        lines.append(f"| {error} {size:g} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def limits_paragraph(res: dict, navigation: str = "random_walk") -> str:
    """docs/diagnosis.md's paragraph of the clean files' detection limits and of the misses, from the rows
    as measured: per error each file's limit ('over' where not even the largest size searched shows, or
    read against the file's own delay peak), then the misses under and above their file's limit, and
    how many named errors' estimates lie within two standard errors of the size written in."""
    from ..estimators.diagnosis.field_selftest import COVER_Z

    rows = [r for r in res["rows"] if r["navigation"] == navigation]
    files = list(dict.fromkeys(r["file"] for r in rows))
    clean = {r["file"]: r for r in rows if r["error"] == "clean"}
    injected = [r for r in rows if r["error"] != "clean"]
    parts = []
    for error in dict.fromkeys(r["error"] for r in injected):
        cells = []
        for f in files:
            mine = [r for r in injected if r["file"] == f and r["error"] == error]
            limit = clean.get(f, {}).get("detection_limits", {}).get(error)
            if limit is None or not mine:
                cells.append("-")
                continue
            r = mine[0]
            cell = f"{'over ' if r.get('detection_limit_beyond') else ''}{limit:.3g}"
            if r.get("detection_limit_reason"):
                peak = clean[f].get("attitude_delay_profile", {}).get("peak_s")
                cell += f" (own delay peak at {peak:+.2f} s)" if peak is not None else " (own delay peak)"
            cells.append(cell)
        unit = next(r["unit"] for r in injected if r["error"] == error)
        parts.append(f"{error} {', '.join(cells)}{' ' + unit if unit else ''}")
    missed = [r for r in injected if not r["hit"]]
    under = [r for r in missed if r.get("detection_limit") is not None and r["size"] < r["detection_limit"]]
    above = [r for r in missed if r not in under]

    def listed(rs):
        return "; ".join(f"{r['file'].split('.')[0]} {r['error']} {r['size']:g}" for r in rs) or "none"

    named = [r for r in injected if r["hit"] and r.get("estimate_z") is not None]
    off = [r for r in named if r["estimate_z"] > COVER_Z]
    covered = (f" Of the {len(named)} named with a standard error, {len(named) - len(off)} estimates lie within "
               f"{COVER_Z:g} standard errors of the size written in; beyond: "
               + ("; ".join(f"{r['file'].split('.')[0]} {r['error']} {r['size']:g} ({r['estimate_z']:.1f} SE)" for r in off)
                  or "none") + ".") if named else ""
    return (f"Limits of the clean files ({', '.join(f.split('.')[0] for f in files)}; the error's unit): "
            + "; ".join(parts) + f". Of the {len(missed)} misses, {len(under)} are under their file's limit ("
            + listed(under) + f"); above it: {listed(above)}." + covered)


def print_diagnosis(res: dict) -> None:
    from ..estimators.diagnosis.field_selftest import COVER_Z

    print("\ndiagnosis on real files, field errors injected on the recorded channels, clean file's calibration")
    for nav, s in res["summary"].items():
        print(f"  {nav:>11s}: top-1 {100 * (s['top1'] or 0):.0f} % ({100 * (s['top1_detectable'] or 0):.0f} % of the "
              f"{s['n_detectable']} of {s['n_injected']} not under their file's detection limit), false alarms "
              f"{s['false_alarms']} of {s['clean_files']} clean files, slowest {s['max_seconds'] or 0:.1f} s")
        for e, v in s["per_error"].items():
            limits = ", ".join(f"{f.split('.')[0]} {'-' if x is None else f'{x:.3g}'}" for f, x in s["limits"].get(e, {}).items())
            print(f"      {e:>22s}: top-1 {100 * v['top1']:.0f} %, smallest detected {v['smallest_detected']}; "
                  f"detection limits {limits}")
        c = s.get("covered") or {}
        if c.get("named_with_se"):
            print(f"      named with a standard error: {c['within']} of {c['named_with_se']} estimates within {COVER_Z:g} SE "
                  f"of the size written in (the farthest {c['max_z']:.1f} SE off)")
        print("      clean gaps: " + ", ".join(f"{f} {g:.3f}" for f, g in s["clean_gaps"].items()))
        for f, own in s.get("own_effects", {}).items():
            print(f"      {f}: its own {', '.join(own)} (found on top of its calibration, held in every run's diagnosis, "
                  "as the calibration's own runs are diagnosed)")
    for m in res["missing"]:
        print(f"  missing: {m}")
    print("\n" + markdown_table(res) + "\n")
    if "random_walk" in res["summary"]:
        print(limits_paragraph(res) + "\n")
    best = max((s["top1"] or 0) for s in res["summary"].values()) if res["summary"] else 0
    alarms = sum(s["false_alarms"] for s in res["summary"].values())
    short = [r["seconds"] for r in res["rows"] if r["pings"] <= 300 and r["navigation"] == "random_walk"]
    targets = [Target("real files, injected field errors: top-1 >= 90 % (best base), share", best, best >= 0.9),
               Target("clean real files: false alarms, all bases (target 0)", alarms, alarms == 0)]
    if short:
        targets.append(Target("real transects of <= 300 pings, one diagnosis (random walk): slowest < 20 s",
                              max(short), max(short) < 20.0))
    for sp in res.get("speed", []):
        print(f"speed: {sp['case']}, {sp['pings']} pings, calibrated on itself (truth {', '.join(sp['truth'])}: in "
              f"the calibration): diagnosis {sp['seconds']:.1f} s, verdict {sp['verdict']}")
        targets.append(Target(f"a {sp['pings']}-ping transect diagnosed (random walk) < 60 s", sp["seconds"],
                              sp["seconds"] < 60.0))
    print_targets(res, targets)


def figure_diagnosis(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    errors = list(dict.fromkeys(r["error"] for r in res["rows"] if r["error"] != "clean"))
    navigations = [nav for nav in NAVIGATIONS if any(r["navigation"] == nav for r in res["rows"])]  # only what ran
    width = 0.8 / max(len(navigations), 1)
    for k, nav in enumerate(navigations):
        hits = [np.mean([r["hit"] for r in res["rows"] if r["navigation"] == nav and r["error"] == e] or [0]) for e in errors]
        ax.bar(np.arange(len(errors)) + width * k, hits, width=width, label=nav)
    ax.set_xticks(np.arange(len(errors)) + width * (len(navigations) - 1) / 2, errors, rotation=20, fontsize=9)
    ax.set_xlabel("injected error (its unit in its name)")
    ax.set_ylabel("named first (fraction of files and sizes)")
    ax.set_ylim(0, 1)
    ax.legend(title="base navigation", fontsize=9, title_fontsize=9)
    ax.set_title("diagnosis on real files, injected field errors")
    fig.tight_layout()
    save_figure(fig, path)
