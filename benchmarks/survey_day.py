"""``adcpdyn bench surveyday``: a day's survey, 20 simulated river transects of about 500 pings
(1e4 pings), calibrated jointly and diagnosed jointly: wall time and peak memory, on one core and
on Dask, and the growth of the joint calibration's time in the number of transects.

Each measurement runs in a child process (:mod:`.survey_day_worker`): ``one_core`` pins it to one
CPU with one solver thread and single-threaded BLAS; ``here`` is the default placement (two solver
threads); ``dask`` solves the starts on a LocalCluster of two single-threaded workers. Default
calibration options otherwise (24 starts, moving bed auto).
"""

from __future__ import annotations

import numpy as np

from .common import Target, machine, print_targets, run_worker, save_figure
from .scale import LINEAR_TOLERANCE, growth_exponent
from .survey_day_worker import PINGS_PER_TRANSECT, PING_INTERVAL_S, SURVEY

ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
TARGET_CALIBRATION_S, TARGET_DIAGNOSIS_S = 60.0, 300.0


def _run(runs: int, placement: str, diagnose: bool = False, time_limit_s: float = 1800.0) -> dict:
    env = {**(ONE_THREAD if placement == "one_core" else {}), "ADCPDYN_PROGRESS": "0"}
    row, why = run_worker("survey_day_worker", [runs, placement] + (["diagnose"] if diagnose else []), time_limit_s, env)
    if row is None:
        return {"runs": runs, "placement": placement, "error": why}
    print(f"  {runs:3d} transects ({row['pings']:6d} pings), {placement:>8s}: calibration {row['calibration_s']:6.1f} s"
          + (f", diagnosis {row['diagnosis_s']:6.1f} s ({row['verdict']})" if diagnose else "")
          + f", peak {row['peak_rss_mb']:5.0f} MB, misalignment error {row['misalignment_error_deg']:+.3f} deg "
            f"(SE {row['misalignment_se_deg']:.3f})", flush=True)
    return row


def bench_survey_day(quick: bool) -> dict:
    """Joint calibration on one core at growing numbers of transects (the exponent), then the full day
    by default placement and on Dask, then the joint diagnosis of the day."""
    sizes = (2, 4) if quick else (2, 5, 10, 20)
    day = sizes[-1]
    rows = [_run(n, "one_core") for n in sizes]
    rows += [_run(day, "here"), _run(day, "dask"), _run(day, "here", diagnose=True)]
    ok = [r for r in rows if r["placement"] == "one_core" and "error" not in r]
    res = {"suite": "surveyday", "machine": machine(), "survey": SURVEY, "ping_interval_s": list(PING_INTERVAL_S),
           "pings_per_transect": PINGS_PER_TRANSECT, "sizes": list(sizes), "rows": rows}
    if len(ok) >= 2:
        res["exponent_runs"] = growth_exponent([r["runs"] for r in ok], [r["calibration_s"] for r in ok])[0]
        res["exponent_runs_largest_pair"] = growth_exponent([r["runs"] for r in ok[-2:]], [r["calibration_s"] for r in ok[-2:]])[0]
    return res


def _day(res: dict, placement: str, diagnose: bool = False) -> dict | None:
    day = res["sizes"][-1]
    return next((r for r in res["rows"] if r["runs"] == day and r["placement"] == placement and "error" not in r
                 and ("diagnosis_s" in r) == diagnose), None)


def print_survey_day(res: dict) -> None:
    print(f"\nsurvey day: {SURVEY}, transects of ~{res['pings_per_transect']} pings, joint calibration (default options) "
          "and joint diagnosis")
    print(f"{'transects':>9} {'pings':>7} {'placement':>9} {'calib s':>8} {'diag s':>7} {'peak MB':>8} {'err deg':>8} {'SE deg':>7}")
    for r in res["rows"]:
        if "error" in r:
            print(f"{r['runs']:>9} {'':>7} {r['placement']:>9}  {r['error']}")
            continue
        print(f"{r['runs']:>9} {r['pings']:>7} {r['placement']:>9} {r['calibration_s']:>8.1f} "
              f"{r.get('diagnosis_s', float('nan')):>7.1f} {r['peak_rss_mb']:>8.0f} {r['misalignment_error_deg']:>+8.3f} "
              f"{r['misalignment_se_deg']:>7.3f}")
    one, here, dask, diag = _day(res, "one_core"), _day(res, "here"), _day(res, "dask"), _day(res, "here", True)
    if one and dask and here:
        print(f"speed-up over one core, {res['sizes'][-1]} transects: Dask LocalCluster (2 workers) "
              f"{one['calibration_s'] / dask['calibration_s']:.2f}x, default placement {one['calibration_s'] / here['calibration_s']:.2f}x")
    b = res.get("exponent_runs")
    targets = [
        Target(f"{res['sizes'][-1]}-transect joint calibration on one core < {TARGET_CALIBRATION_S:.0f} s",
               one["calibration_s"] if one else float("nan"), bool(one and one["calibration_s"] < TARGET_CALIBRATION_S)),
        Target(f"joint calibration time grows in transects with exponent <= {1 + LINEAR_TOLERANCE:.1f} (one core, "
               f"{res['sizes'][0]}-{res['sizes'][-1]})", float("nan") if b is None else b, bool(b is not None and b <= 1 + LINEAR_TOLERANCE)),
        Target(f"{res['sizes'][-1]}-transect joint diagnosis < {TARGET_DIAGNOSIS_S:.0f} s",
               diag["diagnosis_s"] if diag else float("nan"), bool(diag and diag["diagnosis_s"] < TARGET_DIAGNOSIS_S)),
    ]
    res["targets"] = [t.to_dict() for t in targets]
    print_targets(res, targets)


def figure_survey_day(res: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in res["rows"] if r["placement"] == "one_core" and "error" not in r]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
    if ok:
        n = np.array([r["runs"] for r in ok])
        ax[0].loglog(n, [r["calibration_s"] for r in ok], "o-", label="one core")
        ax[0].loglog(n, ok[0]["calibration_s"] * n / n[0], "k:", label="linear")
        ax[1].plot(n, [r["peak_rss_mb"] / 1024 for r in ok], "o-", label="one core")
    for placement, marker in (("here", "s"), ("dask", "^")):
        r = _day(res, placement)
        if r:
            ax[0].loglog([r["runs"]], [r["calibration_s"]], marker, label={"here": "default (2 threads)", "dask": "Dask, 2 workers"}[placement])
    ax[0].set_xticks(res["sizes"], [str(s) for s in res["sizes"]])
    ax[0].minorticks_off()
    ax[0].set_xlabel("transects (~500 pings each)")
    ax[0].set_ylabel("joint calibration (s)")
    ax[0].legend(fontsize=8)
    ax[1].set_xticks(res["sizes"], [str(s) for s in res["sizes"]])
    ax[1].set_xlabel("transects (~500 pings each)")
    ax[1].set_ylabel("peak memory (GB)")
    fig.suptitle(f"survey day: {SURVEY}, joint calibration", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
