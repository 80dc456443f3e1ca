"""``adcpdyn bench scale``: calibration time and peak memory against the number of pings.

Each size runs in a child process (:mod:`.scale_worker`) with a time limit; sizes stop
once one fails or when the growth fitted so far predicts the next one beyond the time
or memory budget (the skip and its reason are recorded). The growth exponent is a
log-log least-squares fit over the measured sizes. The growth between the two largest sizes is
measured again on their saved cases, calibrated in fresh processes by turns (:data:`REPEATS` each),
each size's fastest taken: one pass's two times lie minutes apart on a host whose speed wanders
(that exponent read 0.72, 1.12, 1.19 and 1.27 in four passes of one code).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from .common import Target, machine, print_targets, run_worker, save_figure
from .scale_worker import HESSIAN, PING_INTERVAL_S, SCENARIO

LINEAR_TOLERANCE = 0.1  # exponent up to 1.1 counts as linear growth (timing noise)
DEFAULT_STARTS = 24  # the largest size is calibrated again as `adcpdyn calibrate` would: its default multistart
REPEATS = 3  # the two largest sizes' saved cases calibrated again this many times each, by turns


def growth_exponent(n, y) -> tuple[float, float]:
    """(exponent b, prefactor a) of y = a n^b by least squares in log-log."""
    b, log_a = np.polyfit(np.log(np.asarray(n, float)), np.log(np.asarray(y, float)), 1)
    return float(b), float(np.exp(log_a))


def bench_scale(sizes, seed: int = 1, time_limit_s: float = 600.0, memory_limit_mb: float = 8000.0,
                repeats: int = REPEATS) -> dict:
    with tempfile.TemporaryDirectory(prefix="adcpdyn-scale-") as folder:
        return _bench_scale(sizes, seed, time_limit_s, memory_limit_mb, repeats, Path(folder))


def _bench_scale(sizes, seed: int, time_limit_s: float, memory_limit_mb: float, repeats: int, folder: Path) -> dict:
    rows, skipped, saved = [], [], {}
    for n in sizes:
        if len(rows) >= 2:
            bt, at = growth_exponent([r["n_pings"] for r in rows], [r["calibration_s"] for r in rows])
            bm, am = growth_exponent([r["n_pings"] for r in rows], [r["peak_rss_mb"] for r in rows])
            t_pred, m_pred = at * n**bt, am * n**bm
            if t_pred > time_limit_s or m_pred > memory_limit_mb:
                skipped.append({"n_pings": n, "reason": f"predicted {t_pred:.0f} s and {m_pred:.0f} MB from the sizes "
                                f"measured (limits {time_limit_s:.0f} s, {memory_limit_mb:.0f} MB)"})
                continue
        saved[n] = folder / f"{n}.h5"
        row, why = run_worker("scale_worker", [n, seed] + ([SCENARIO, DEFAULT_STARTS] if n >= 10**5 else [])
                              + ["--save", saved[n]], time_limit_s)
        if row is None:
            skipped.append({"n_pings": n, "reason": why})
            break
        rows.append(row)
        print(f"  {rows[-1]['n_pings']:>7d} pings: {rows[-1]['calibration_s']:.2f} s, {rows[-1]['peak_rss_mb']:.0f} MB",
              flush=True)
    res = {"suite": "scale", "machine": machine(), "scenario": SCENARIO, "ping_interval_s": list(PING_INTERVAL_S),
           "seed": seed, "sizes_requested": list(sizes), "time_limit_s": time_limit_s,
           "memory_limit_mb": memory_limit_mb, "rows": rows, "skipped": skipped,
           "calibration": f"one start (its per-row Jacobians on the free cores), {HESSIAN} Hessian, "
                          "default CalibrationConfig otherwise"}
    if len(rows) >= 2:
        n = [r["n_pings"] for r in rows]
        keys = ("calibration_s", "setup_s", "solve_s", "peak_rss_mb")
        res["exponents"] = {k: growth_exponent(n, [r[k] for r in rows])[0] for k in keys}
        # the growth that matters is where the sizes are large: the slope between the two largest
        res["exponents_largest_pair"] = {k: growth_exponent(n[-2:], [r[k] for r in rows[-2:]])[0] for k in keys}
        res["largest_pair_repeated"] = repeated_pair(rows[-2:], [saved[s] for s in sizes if s in saved][-2:],
                                                     repeats, time_limit_s)
    return res


def repeated_pair(pair: list, paths: list, repeats: int, time_limit_s: float) -> dict:
    """The two rows' saved cases calibrated again in fresh processes, by turns, ``repeats`` times each:
    every time, each size's fastest, and the growth exponent of those (None where a run failed)."""
    times = {r["n_pings"]: [] for r in pair}
    for _ in range(repeats):
        for r, path in zip(pair, paths):
            t, why = run_worker("scale_worker", ["--time", path], time_limit_s)
            if t is None:
                return {"repeats": repeats, "failed": f"{r['n_pings']} pings: {why}"}
            times[r["n_pings"]].append(t["calibration_s"])
    n = list(times)
    fastest = [min(times[k]) for k in n]
    return {"repeats": repeats, "n_pings": n, "calibration_s": [times[k] for k in n], "fastest_s": fastest,
            "exponent": growth_exponent(n, fastest)[0]}


def print_scale(res: dict) -> None:
    print(f"scale benchmark: {res['scenario']} stretched to long runs at ~{2 / sum(res['ping_interval_s']):.0f} Hz, "
          f"seed {res['seed']}; {res['calibration']}; each size in its own process (one run, noisy: the two largest again below, by turns)")
    print(f"{'pings':>8}{'simulate s':>11}{'set-up s':>10}{'solve s':>9}{'calib s':>9}{'peak MB':>9}{'iter':>6}"
          f"{'tang mm/s':>10}")
    for r in res["rows"]:
        print(f"{r['n_pings']:>8d}{r['simulate_s']:>11.2f}{r['setup_s']:>10.2f}{r['solve_s']:>9.2f}"
              f"{r['calibration_s']:>9.2f}{r['peak_rss_mb']:>9.0f}{r['iterations']:>6d}"
              f"{1e3 * r['tangential_radial_rms_m_s']:>10.3f}")
    for s in res["skipped"]:
        print(f"  {s['n_pings']} pings not run: {s['reason']}")
    ex = res.get("exponents", {})
    last = res.get("exponents_largest_pair", {})
    if ex:
        print("growth exponents, all sizes (log-log least squares): " + ", ".join(f"{k} {v:.2f}" for k, v in ex.items()))
        print("growth exponents, two largest sizes:                 " + ", ".join(f"{k} {v:.2f}" for k, v in last.items()))
    pair = res.get("largest_pair_repeated") or {}
    if "exponent" in pair:
        print(f"  two largest again, {pair['repeats']} times each by turns in fresh processes: "
              + "; ".join(f"{n} pings " + ", ".join(f"{t:.2f}" for t in ts) + " s" for n, ts in
                          zip(pair["n_pings"], pair["calibration_s"]))
              + f": growth exponent of the fastest {pair['exponent']:.2f}")
    elif pair:
        print(f"  two largest again: not measured ({pair['failed']})")
    big = [r for r in res["rows"] if r["n_pings"] >= 10**5]
    for r in [r for r in big if "default_calibration_s" in r]:
        print(f"  {r['n_pings']} pings with the default {r['default_starts']} starts: {r['default_calibration_s']:.2f} s "
              f"(set-up {r['default_setup_s']:.2f} s, solve {r['default_solve_s']:.2f} s; objective / one start's "
              f"{r['default_objective_ratio']:.9f}; peak {r['default_peak_rss_mb']:.0f} MB): {r['default_message']}")
    t = big[0]["calibration_s"] if big else float("nan")
    label = "calibration of 1e5 pings < 10 s" + ("" if big else " (1e5 not run: see above)")
    b = pair.get("exponent", float("nan"))
    peak = big[0]["peak_rss_mb"] if big else float("nan")
    print_targets(res, [Target(label, t, bool(big) and t < 10.0),
                        Target("calibration of 1e5 pings: peak memory < 2 GB (MB; the process's, its simulation included)",
                               peak, bool(big) and peak < 2000.0),
                        Target(f"calibration cost grows no faster than linearly (exponent between the two largest sizes, "
                               f"fastest of {pair.get('repeats', REPEATS)} by turns, <= {1 + LINEAR_TOLERANCE:.1f})", b,
                               bool(np.isfinite(b)) and b <= 1 + LINEAR_TOLERANCE)])


def figure_scale(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import ScalarFormatter

    n = np.array([r["n_pings"] for r in res["rows"]], float)
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for k, label in (("calibration_s", "calibration"), ("setup_s", "set-up (NLP, solver)"), ("solve_s", "solve")):
        exponent = res.get("exponents", {}).get(k, np.nan)
        ax[0].loglog(n, [r[k] for r in res["rows"]], "o-", label=f"{label} (growth exponent {exponent:.2f})")
    if n.size:
        ax[0].loglog(n, n / n[0] * res["rows"][0]["calibration_s"], "k:", label="linear from the smallest")
    ax[0].axhline(10.0, color="r", lw=0.8, ls="--", label="target at 1e5 pings: 10 s")
    ax[0].set_xlabel("run length (pings)")
    ax[0].set_ylabel("wall time (s)")
    ax[0].set_title("(a) calibration time", fontsize=10)
    ax[0].legend(fontsize=8)
    ax[1].loglog(n, [r["peak_rss_mb"] for r in res["rows"]], "o-",
                 label=f"peak RSS (growth exponent {res.get('exponents', {}).get('peak_rss_mb', np.nan):.2f})")
    ax[1].set_xlabel("run length (pings)")
    ax[1].set_ylabel("peak resident memory (MB)")
    ax[1].yaxis.set_major_formatter(ScalarFormatter())  # 200, 400 MB rather than 2 x 10^2
    ax[1].yaxis.set_minor_formatter(ScalarFormatter())
    ax[1].set_title("(b) peak memory of the worker", fontsize=10)
    ax[1].legend(fontsize=8)
    fig.suptitle(f"calibration cost against run length ({res['scenario']} at ~5 Hz)")
    fig.tight_layout()
    save_figure(fig, path)
