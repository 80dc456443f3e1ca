"""``adcpdyn bench navigation``: the calibration on real instrument files with the vessel's velocity
as knots (a piecewise-linear curve) and as a random walk (a velocity per ping, its intensity and
the noise levels from the data), measured in the same run.

Per file: the heading misalignment and its standard error, the noise levels and the wall time of
each base (each file calibrated on itself); a survey of two windows of winriver02_transect
calibrated jointly (the README's); and whether the standard errors cover the spread of the
misalignment between windows of one transect: chi2 / (windows - 1) of the window estimates about their
weighted mean, 1 when the SEs are honest, with the compass deviation and bed left out (each window then
estimates one constant offset, whatever its heading and bed) and, on knots, with the calibration's defaults
(the moving-bed test deciding each window's bed). Files come from ``ADCPDYN_REAL_DATA`` (default ../shared/data/real); a
missing file is listed, not an error.
"""

from __future__ import annotations

import time

import numpy as np

from .common import Target, machine, print_targets, real_cases, real_dir, save_figure

FILES = ("RiverPro_test01.PD0", "winriver01.PD0", "winriver02_transect.PD0")
NAVIGATIONS = ("knots", "random_walk")
COVERED_CHI2 = 2.0  # chi2 / dof of the window estimates beyond which their SEs do not cover their spread
SURVEY = ("winriver02_transect.PD0", 230.0)  # the README's survey: the transect cut at 230 s
WINDOWS = {"RiverPro_test01.PD0": (2, None), "winriver01.PD0": (3, None),
           "winriver02_transect.PD0": (3, 370.0)}  # (windows, end s): winriver02's bottom track is lost after 375 s


OFF, DEFAULTS = "bed and deviation off", "defaults"
# the window check's calibrations: every window estimating one constant offset (bed and compass deviation left out),
# and the calibration's defaults (the moving-bed test deciding each window's bed)
WINDOW_OPTIONS = {OFF: {"compass_deviation": "off", "moving_bed": "off"}, DEFAULTS: {}}


def spread_chi2(m: np.ndarray, s: np.ndarray) -> float:
    """chi2 / dof of estimates ``m`` with SEs ``s`` about their inverse-variance mean; a window whose estimate is
    not determined (infinite SE) counts in neither; NaN with fewer than two determined."""
    ok = np.isfinite(m) & np.isfinite(s) & (s > 0)
    if ok.sum() < 2:
        return float("nan")
    w = 1.0 / s[ok] ** 2
    mean = np.sum(w * m[ok]) / np.sum(w)
    return float(np.sum(w * (m[ok] - mean) ** 2) / (ok.sum() - 1))


def _calibrate(cases, nav: str, starts: int, **options) -> tuple:
    from ..estimators.calibration.config import CalibrationConfig
    from ..estimators.calibration.problem import calibrate_runs

    tic = time.perf_counter()
    r = calibrate_runs(cases, CalibrationConfig(n_starts=starts, navigation=nav, **options))
    return r, time.perf_counter() - tic


def _row(r, seconds: float) -> dict:
    return {"misalignment_deg": float(np.degrees(r.heading_misalignment_rad)),
            "misalignment_se_deg": float(np.degrees(r.heading_misalignment_se_rad)),
            "bed_se_m_s": None if r.moving_bed_velocity_se_m_s is None else np.asarray(r.moving_bed_velocity_se_m_s).tolist(),
            "noise": {k: v for k, v in r.noise_sigma.items() if v is not None}, "status": r.multistart.status,
            "seconds": seconds}


def bench_navigation(quick: bool) -> dict:
    from .. import api

    starts = 4 if quick else 8
    files, windows, survey, missing = [], [], [], []
    for name, path, case in real_cases(FILES[:1] if quick else FILES, missing):
        for nav in NAVIGATIONS:
            files.append({"file": name, "pings": case.pings.n, "navigation": nav, **_row(*_calibrate([case], nav, starts))})
            print(f"{name:>26s} {nav:>11s}: misalignment {files[-1]['misalignment_deg']:+.3f} +- "
                  f"{files[-1]['misalignment_se_deg']:.3f} deg  {files[-1]['seconds']:.1f} s", flush=True)
        n_win, end = WINDOWS[name]
        end = end or float(case.pings.time_s[-1] - case.pings.time_s[0])
        edges = np.linspace(0.0, end, n_win + 1)
        parts = [api.import_file(path, start_s=float(a), end_s=float(b)).case for a, b in zip(edges[:-1], edges[1:])]
        for nav, options in [(nav, OFF) for nav in NAVIGATIONS] + [("knots", DEFAULTS)]:
            est = [_calibrate([p], nav, starts, **WINDOW_OPTIONS[options])[0] for p in parts]
            m = np.degrees([r.heading_misalignment_rad for r in est])
            s = np.degrees([r.heading_misalignment_se_rad for r in est])
            windows.append({"file": name, "navigation": nav, "options": options, "windows_s": edges.tolist(),
                            "misalignment_deg": m.tolist(), "se_deg": s.tolist(), "chi2_per_dof": spread_chi2(m, s),
                            "bed": [r.moving_bed_velocity_se_m_s is not None for r in est]})
            print(f"{name:>26s} {nav:>11s} {options}: windows {' '.join(f'{a:+.2f}+-{b:.2f}' for a, b in zip(m, s))}, "
                  f"chi2/dof {windows[-1]['chi2_per_dof']:.2f}", flush=True)
    name, cut = SURVEY
    path = real_dir() / name
    if not quick and path.exists():
        runs = [api.import_file(path, end_s=cut, name="w2a").case, api.import_file(path, start_s=cut, name="w2b").case]
        for nav in NAVIGATIONS:
            survey.append({"runs": [f"{name} [0, {cut:g}] s", f"{name} [{cut:g}, end] s"], "navigation": nav,
                           **_row(*_calibrate(runs, nav, 24))})
            print(f"{'survey w2a + w2b':>26s} {nav:>11s}: misalignment {survey[-1]['misalignment_deg']:+.3f} +- "
                  f"{survey[-1]['misalignment_se_deg']:.3f} deg  {survey[-1]['seconds']:.1f} s", flush=True)
    return {"machine": machine(), "files": files, "windows": windows, "survey": survey, "missing": missing}


def markdown_table(res: dict) -> str:
    """The per-file and survey rows, then the window check, as markdown (docs/calibration.md)."""
    lines = ["| run | base | misalignment (deg) | noise bt, reference (m/s) | walk (m/s/sqrt(s)) | time (s) |",
             "|---|---|---:|---|---:|---:|"]
    for r in res["files"] + res["survey"]:
        label = r.get("file") or f"survey: {SURVEY[0]} cut at {SURVEY[1]:g} s, 2 runs jointly"
        n = r["noise"]
        lines.append(f"| {label} | {r['navigation']} | {r['misalignment_deg']:+.2f} +- {r['misalignment_se_deg']:.2f} | "
                     f"{n.get('bt', np.nan):.4f}, {n.get('reference', np.nan):.4f} | "
                     f"{n['motion']:.3f} | {r['seconds']:.1f} |" if "motion" in n else
                     f"| {label} | {r['navigation']} | {r['misalignment_deg']:+.2f} +- {r['misalignment_se_deg']:.2f} | "
                     f"{n.get('bt', np.nan):.4f}, {n.get('reference', np.nan):.4f} | - | {r['seconds']:.1f} |")
    lines += ["", "| file | base | windows calibrated with | windows: misalignment +- SE (deg) | chi2 / dof |",
              "|---|---|---|---|---:|"]
    for w in res["windows"]:
        est = ", ".join(f"{a:+.2f} +- {b:.2f}" + (" (bed kept)" if bed else "")
                        for a, b, bed in zip(w["misalignment_deg"], w["se_deg"], w["bed"]))
        lines.append(f"| {w['file']} | {w['navigation']} | {w['options']} | {est} | {w['chi2_per_dof']:.2f} |")
    return "\n".join(lines)


def print_navigation(res: dict) -> None:
    print("\n" + markdown_table(res))
    for m in res["missing"]:
        print(f"missing: {m}")
    print_targets(res, [Target(f"{w['file']} {w['navigation']}{', defaults' if w['options'] == DEFAULTS else ''}: the "
                               f"windows' spread covered by their SEs (chi2/dof <= {COVERED_CHI2})", w["chi2_per_dof"],
                               w["chi2_per_dof"] <= COVERED_CHI2)
                        for w in res["windows"]])


def figure_navigation(res: dict, path) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 3.6), constrained_layout=True)
    rows = res["files"] + res["survey"]
    labels = list(dict.fromkeys((r.get("file") or "survey w2a + w2b").replace(".PD0", "") for r in rows))
    for k, nav in enumerate(NAVIGATIONS):
        se = [next((r["misalignment_se_deg"] for r in rows if (r.get("file") or "survey w2a + w2b").replace(".PD0", "") == lab
                    and r["navigation"] == nav), np.nan) for lab in labels]
        ax.bar(np.arange(len(labels)) + (k - 0.5) * 0.38, se, 0.38, label=nav)
    ax.set_xticks(np.arange(len(labels)), labels)
    ax.set_ylabel("misalignment standard error (deg)")
    ax.set_title("Calibration on real files: knots vs a velocity per ping")
    ax.legend(frameon=False)
    save_figure(fig, path)
