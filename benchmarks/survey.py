"""``adcpdyn bench survey``: the joint calibration of river surveys (several transects by one boat
at one site, compass error and moving bed), its cost against the number of runs, its accuracy
against the truth, and whether its standard errors cover its errors under coloured noise.

Three parts, each from the same code path as ``calibrate --joint``:

* scale: 1..6 transects of ~400 pings (``river_survey`` pinging at ~2.7 Hz), 24 starts: set-up
  and solve time against the number of runs, growth exponent;
* accuracy: surveys drawn by seed (2-6 transects, compass error 8-25 deg with +-1 deg
  deviation, bed 0.1-0.35 m/s): the joint misalignment against the runs' mean effective
  heading correction, every run's bed velocity, and each single transect calibrated alone
  (within 3 SE of the truth, or reported undetermined: with the bed undetermined, the reading with
  the bed free printed beside the headline within 3 of its SE);
* coverage: two-transect surveys with AR(1) bottom-track and GNSS noise (lag-1 0.7 and 0.5)
  and the scenario's drawn compass deviation: the share of seeds whose misalignment and bed
  errors are within 3 standard errors, for the reported SEs (Newey-West, compass-deviation
  prior) and for the white-noise ones;
* heading coverage: surveys of 2 and 4 transects with a compass-grade heading noise (1 deg): the
  share of errors within 3 SE and the RMS of error/SE, misalignment and every run's bed, with the
  compass deviation as the survey draws it (+-1 deg, narrower than the calibration's prior: the SEs
  must not be small, RMS <= 1.3) and drawn from the prior (over which they are calibrated: RMS
  0.7-1.3).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from .common import Target, machine, print_targets, save_figure

FAST_PINGS_S = (0.30, 0.45)  # ping interval giving ~400 pings per 150-s transect
BT_AR1, REFERENCE_AR1 = 0.7, 0.5
COMPASS_HEADING_NOISE_DEG = 1.0  # a magnetic compass's reading noise (TRDI quotes +-2 deg accuracy, 0.5-1 deg noise)


def _transects(runs: int, seed: int, fast: bool = False, noise: dict | None = None, **options) -> list:
    from ..cases.survey import survey_scenarios
    from ..cases.simulation import simulate

    cases = []
    for k, sc in enumerate(survey_scenarios("river_survey", runs, seed, **options)):
        run = sc.run
        if fast:
            run = dataclasses.replace(run, ping_interval_s=FAST_PINGS_S)
        if noise:
            run = dataclasses.replace(run, noise=dataclasses.replace(run.noise, **noise))
        cases.append(simulate(dataclasses.replace(sc, run=run), seed=seed + k))
    return cases


def _truth(cases) -> dict:
    eff = np.array([float(c.truth.extra_attrs["effective_heading_misalignment_rad"]) for c in cases])
    beds = np.array([np.nanmean(c.truth.moving_bed_velocity_m_s, axis=0)[:2] for c in cases])
    return {"misalignment_rad": float(np.angle(np.mean(np.exp(1j * eff)))), "per_run_misalignment_rad": eff,
            "bed_m_s": beds}


def _solve(cases, starts: int, seed: int = 0):
    from ..estimators.calibration.config import CalibrationConfig
    from ..estimators.calibration.problem import CalibrationProblem

    tic = time.perf_counter()
    problem = CalibrationProblem(cases if len(cases) > 1 else cases[0], CalibrationConfig(n_starts=starts, seed=seed))
    setup = time.perf_counter() - tic
    tic = time.perf_counter()
    r = problem.solve()
    return r, setup, time.perf_counter() - tic


def _scores(r, truth: dict, run_index=None) -> dict:
    """Errors and standard errors of the misalignment (deg) and of each run's bed (m/s)."""
    true_d = truth["misalignment_rad"] if run_index is None else truth["per_run_misalignment_rad"][run_index]
    d_err = float(np.rad2deg(np.angle(np.exp(1j * (r.heading_misalignment_rad - true_d)))))
    d_se = float(np.rad2deg(r.heading_misalignment_se_rad))
    white = d_se / r.standard_errors.get("inflation_over_white", {}).get("heading_misalignment", 1.0)
    beds = truth["bed_m_s"] if run_index is None else truth["bed_m_s"][[run_index]]
    bed_err, bed_se = [], []
    for run, true_bed in zip(r.runs, beds):
        v, s = run.moving_bed_velocity_m_s, run.moving_bed_velocity_se_m_s
        bed_err.append((np.asarray(v) - true_bed).tolist() if v is not None else [np.nan, np.nan])
        bed_se.append(np.asarray(s).tolist() if s is not None else [np.inf, np.inf])
    infl = r.standard_errors.get("inflation_over_white", {})
    bed_white = [[s / infl.get(f"moving_bed_{a}", 1.0) for s, a in zip(se, ("north", "east"))] for se in bed_se]
    free = next((c for c in r.confounded if c["pair"][0] == "heading_misalignment" and "value_if_bed_moves_rad" in c), None)
    if_moves = None if free is None else {  # the bed undetermined: the headline's other reading, with the bed free
        "error_deg": float(np.rad2deg(np.angle(np.exp(1j * (free["value_if_bed_moves_rad"] - true_d))))),
        "se_deg": float(np.rad2deg(free["se_if_bed_moves_rad"]))}
    return {"misalignment_error_deg": d_err, "misalignment_se_deg": d_se, "misalignment_white_se_deg": white,
            "misalignment_if_bed_moves": if_moves,
            "bed_error_m_s": bed_err, "bed_se_m_s": bed_se, "bed_white_se_m_s": bed_white,
            "confounded": [c["pair"] for c in r.confounded], "success": r.success, "status": r.multistart.status}


def bench_survey(sizes, surveys: int, coverage_seeds: int, starts: int = 24, heading_seeds: int = 20) -> dict:
    out = {"suite": "survey", "machine": machine(), "starts": starts, "sizes": list(sizes)}
    # ---- scale: one survey of the largest size, its first K transects
    cases = _transects(max(sizes), 1, fast=True)
    truth_all = _truth(cases)
    rows = []
    for K in sizes:
        r, setup, solve = _solve(cases[:K], starts)
        truth = {"misalignment_rad": float(np.angle(np.mean(np.exp(1j * truth_all["per_run_misalignment_rad"][:K])))),
                 "per_run_misalignment_rad": truth_all["per_run_misalignment_rad"][:K], "bed_m_s": truth_all["bed_m_s"][:K]}
        rows.append({"runs": K, "pings": int(sum(c.pings.n for c in cases[:K])), "setup_s": setup, "solve_s": solve,
                     "total_s": setup + solve, "unknowns": len(r.x), "fraction_at_best": r.multistart.fraction_at_best,
                     "jacobian": r.jacobian, **_scores(r, truth)})
    out["scale"] = rows
    # ---- accuracy over drawn surveys
    rng = np.random.default_rng(2026)
    acc = []
    for s in range(1, surveys + 1):
        K = int(rng.integers(2, 7))
        cases = _transects(K, 100 + s)
        truth = _truth(cases)
        r, setup, solve = _solve(cases, starts)
        singles = []
        for k in range(min(2, K)):
            rs, _, _ = _solve([cases[k]], 8)
            singles.append(_scores(rs, truth, k))
        acc.append({"survey_seed": 100 + s, "runs": K, "time_s": setup + solve,
                    "compass_A_deg": float(np.rad2deg(next(e["params"]["A_rad"] for e in cases[0].truth.effects
                                                           if e["name"] == "compass_deviation"))),
                    "bed_speed_m_s": float(np.linalg.norm(truth["bed_m_s"][0])),
                    "joint": _scores(r, truth), "singles": singles})
    out["accuracy"] = acc
    # ---- coverage under coloured noise: two-transect surveys (standard errors small enough for the colour to matter)
    cov = _coverage_rows(2, [300 + seed for seed in range(1, coverage_seeds + 1)],
                         {"bt_ar1": BT_AR1, "reference_ar1": REFERENCE_AR1})
    out["coverage"] = {"bt_ar1": BT_AR1, "reference_ar1": REFERENCE_AR1, "rows": cov}
    out["heading_coverage"] = heading_coverage(heading_seeds)
    out["heading_coverage_prior"] = heading_coverage(heading_seeds, deviation_from_prior=True)
    return out


def heading_coverage(seeds: int, heading_deg: float = COMPASS_HEADING_NOISE_DEG, runs=(2, 4),
                     deviation_from_prior: bool = False) -> dict:
    """Coverage under a compass-grade heading noise (the noise is in the regressors: the beams'
    rotation and the compass deviation's argument): surveys of 2 and 4 transects, each seed's
    misalignment and every run's bed error over its reported SE. The compass deviation's B and C
    as the survey draws them (uniform in +-1 deg), or with ``deviation_from_prior`` from the
    calibration's own prior N(0, ``compass_deviation_prior_rad``^2) (:func:`prior_compass`): the
    SEs of a regularised estimate carry its prior, and are calibrated over truths drawn from it."""
    noise = {"heading_rad": float(np.deg2rad(heading_deg))}
    rows = [{"runs": K, **row} for K in runs
            for row in _coverage_rows(K, [500 + s for s in range(1, seeds + 1)], noise, deviation_from_prior)]
    return {"heading_deg": heading_deg, "deviation": "prior" if deviation_from_prior else "survey", "rows": rows}


def prior_compass(seed: int) -> tuple:
    """(A, B, C) of a survey's compass: A as river_survey's spec draws it (8-25 deg, either sign), B
    and C from the calibration's deviation prior."""
    from ..estimators.calibration.config import CalibrationConfig

    rng = np.random.default_rng(10_000 + seed)
    a = rng.uniform(np.deg2rad(8.0), np.deg2rad(25.0)) * rng.choice([-1.0, 1.0])
    b, c = rng.normal(0.0, CalibrationConfig().compass_deviation_prior_rad, 2)
    return float(a), float(b), float(c)


def _coverage_rows(runs: int, seeds, noise: dict, deviation_from_prior: bool = False) -> list:
    """Per survey seed (``runs`` transects with ``noise``, 8 starts): the errors and SEs
    (:func:`_scores`) and the time; with ``deviation_from_prior`` the compass of :func:`prior_compass`."""
    rows = []
    for seed in seeds:
        cases = _transects(runs, seed, noise=noise, **({"compass_rad": prior_compass(seed)} if deviation_from_prior else {}))
        r, setup, solve = _solve(cases, 8)
        rows.append({"seed": seed, "time_s": setup + solve, **_scores(r, _truth(cases))})
    return rows


def heading_coverage_summary(cov: dict) -> dict:
    """Per number of runs: the share of |error| <= 3 SE and the RMS of error/SE, misalignment and bed."""
    out = {}
    for K in sorted({r["runs"] for r in cov["rows"]}):
        rows = [r for r in cov["rows"] if r["runs"] == K]
        zm = np.array([r["misalignment_error_deg"] / r["misalignment_se_deg"] for r in rows])
        zb = np.concatenate([np.ravel(np.asarray(r["bed_error_m_s"], float) / np.asarray(r["bed_se_m_s"], float))
                             for r in rows])
        out[K] = {"surveys": len(rows), "misalignment_within_3se": float(np.mean(np.abs(zm) <= 3)),
                  "misalignment_rms_z": float(np.sqrt(np.mean(zm**2))), "bed_within_3se": float(np.mean(np.abs(zb) <= 3)),
                  "bed_rms_z": float(np.sqrt(np.mean(zb**2)))}
    return out


def _within(err, se, k=3.0) -> bool:
    err, se = np.atleast_1d(np.asarray(err, float)), np.atleast_1d(np.asarray(se, float))
    return bool(np.all(np.abs(err) <= k * se))


def _covered(rows, se_key: str, bed_se_key: str) -> float:
    hits = [_within(r["misalignment_error_deg"], r[se_key]) and _within(r["bed_error_m_s"], r[bed_se_key]) for r in rows]
    return float(np.mean(hits)) if hits else float("nan")


def print_survey(res: dict) -> None:
    from .scale import growth_exponent

    rows = res["scale"]
    print(f"survey benchmark: river_survey transects of ~400 pings, {res['starts']} starts; times from one run on a "
          "shared machine (compare the ratios)")
    print(f"{'runs':>5}{'pings':>7}{'unknowns':>9}{'set-up s':>9}{'solve s':>9}{'total s':>9}{'at best':>8}"
          f"{'misalign err deg':>17}{'se':>7}{'bed err m/s':>12}")
    for r in rows:
        bed = np.nanmax(np.abs(r["bed_error_m_s"]))
        print(f"{r['runs']:>5}{r['pings']:>7}{r['unknowns']:>9}{r['setup_s']:>9.2f}{r['solve_s']:>9.2f}{r['total_s']:>9.2f}"
              f"{r['fraction_at_best']:>8.2f}{r['misalignment_error_deg']:>+17.3f}{r['misalignment_se_deg']:>7.3f}{bed:>12.4f}")
    runs = [r["runs"] for r in rows]
    b_all = growth_exponent(runs, [r["total_s"] for r in rows])[0] if len(rows) > 1 else float("nan")
    b_top = growth_exponent(runs[-2:], [r["total_s"] for r in rows[-2:]])[0] if len(rows) > 1 else float("nan")
    res["growth_exponent_all"], res["growth_exponent_largest"] = b_all, b_top
    print(f"growth exponent of the total time with the number of runs: all sizes {b_all:.2f}, two largest {b_top:.2f}")

    print(f"\naccuracy: {len(res['accuracy'])} drawn surveys (joint; first two transects alone)")
    print(f"{'seed':>5}{'runs':>5}{'A deg':>7}{'bed m/s':>8}{'joint err deg':>14}{'se':>7}{'max bed err':>12}{'time s':>8}"
          f"   single transects: err deg (se) [confounded; bed undetermined: with the bed free]")

    def single(s: dict) -> str:
        free = s.get("misalignment_if_bed_moves")
        return (f"{s['misalignment_error_deg']:+.2f} ({s['misalignment_se_deg']:.2f})"
                + (f" [free {free['error_deg']:+.2f} ({free['se_deg']:.2f})]" if free else " [named]" if s["confounded"] else ""))

    for a in res["accuracy"]:
        j = a["joint"]
        singles = "; ".join(single(s) for s in a["singles"])
        print(f"{a['survey_seed']:>5}{a['runs']:>5}{a['compass_A_deg']:>+7.1f}{a['bed_speed_m_s']:>8.3f}"
              f"{j['misalignment_error_deg']:>+14.3f}{j['misalignment_se_deg']:>7.3f}{np.nanmax(np.abs(j['bed_error_m_s'])):>12.4f}"
              f"{a['time_s']:>8.1f}   {singles}")
    cov = res["coverage"]["rows"]
    hac, white = _covered(cov, "misalignment_se_deg", "bed_se_m_s"), _covered(cov, "misalignment_white_se_deg", "bed_white_se_m_s")
    infl = [r["misalignment_se_deg"] / r["misalignment_white_se_deg"] for r in cov]
    print(f"\ncoverage: {len(cov)} two-transect surveys with AR(1) noise (bottom track {res['coverage']['bt_ar1']}, GNSS "
          f"{res['coverage']['reference_ar1']}): misalignment and bed errors within 3 SE in {100 * hac:.0f} % of seeds with "
          f"the reported SEs, {100 * white:.0f} % with white-noise SEs (misalignment SE inflation median x{np.median(infl):.2f})")
    heading = heading_coverage_summary(res["heading_coverage"]) if "heading_coverage" in res else {}
    for key, words in (("heading_coverage", "deviation as the survey draws it, +-1 deg"),
                       ("heading_coverage_prior", "deviation drawn from the calibration's prior")):
        for K, h in (heading_coverage_summary(res[key]) if key in res else {}).items():
            print(f"heading noise {res[key]['heading_deg']:g} deg, {K} transects, {h['surveys']} surveys ({words}): "
                  f"misalignment within 3 SE {100 * h['misalignment_within_3se']:.0f} % (RMS error/SE "
                  f"{h['misalignment_rms_z']:.2f}), beds {100 * h['bed_within_3se']:.0f} % (RMS {h['bed_rms_z']:.2f})")
    four = next((r for r in rows if r["runs"] == 4), None)
    acc = res["accuracy"]
    targets = []
    if four is not None:
        targets.append(Target("4 runs of ~400 pings, 24 starts, set-up + solve < 30 s", four["total_s"], four["total_s"] < 30.0))
    targets.append(Target("growth with the number of runs no worse than linear (exponent, two largest sizes, <= 1.1)",
                          b_top, b_top <= 1.1))
    if acc:
        ok_d = [abs(a["joint"]["misalignment_error_deg"]) <= 1.0 and _within(a["joint"]["misalignment_error_deg"],
                                                                               a["joint"]["misalignment_se_deg"]) for a in acc]
        ok_bed = [np.nanmax(np.abs(a["joint"]["bed_error_m_s"])) <= 0.05 for a in acc]
        singles = [s for a in acc for s in a["singles"]]
        ok_single = [_within(s["misalignment_error_deg"], s["misalignment_se_deg"]) or not np.isfinite(s["misalignment_se_deg"])
                     or (s.get("misalignment_if_bed_moves") is not None
                         and _within(s["misalignment_if_bed_moves"]["error_deg"], s["misalignment_if_bed_moves"]["se_deg"]))
                     for s in singles]
        targets += [Target("joint misalignment within 1 deg and 3 SE of the effective compass error (share of surveys)",
                           float(np.mean(ok_d)), all(ok_d)),
                    Target("every run's bed velocity within 0.05 m/s (share of surveys)", float(np.mean(ok_bed)), all(ok_bed)),
                    Target("single transects within 3 SE, or reported undetermined (bed undetermined: within 3 SE of "
                           "the reading with the bed free, printed beside) (share)", float(np.mean(ok_single)),
                           all(ok_single))]
    targets.append(Target("coverage under AR(1) noise: |error| <= 3 SE in >= 95 % of seeds", hac, hac >= 0.95))
    # The SEs of the compass deviation's B and C carry their stated prior, so they are calibrated over truths drawn
    # from it (RMS error/SE near 1 there); a compass better than the prior says leaves them conservative, never small.
    prior = heading_coverage_summary(res["heading_coverage_prior"]) if "heading_coverage_prior" in res else {}
    for K, h in heading.items():
        share = min(h["misalignment_within_3se"], h["bed_within_3se"])
        rms = (h["misalignment_rms_z"], h["bed_rms_z"])
        targets += [Target(f"heading noise, {K} transects: |error| <= 3 SE in >= 95 % (misalignment and beds, lower)",
                           share, share >= 0.95),
                    Target(f"heading noise, {K} transects, deviation narrower than the prior: RMS error/SE <= 1.3 "
                           "(misalignment, beds: larger)", max(rms), max(rms) <= 1.3)]
    for K, h in prior.items():
        share = min(h["misalignment_within_3se"], h["bed_within_3se"])
        rms = (h["misalignment_rms_z"], h["bed_rms_z"])
        targets += [Target(f"heading noise, {K} transects, deviation drawn from the prior: |error| <= 3 SE in >= 95 % "
                           "(misalignment and beds, lower)", share, share >= 0.95),
                    Target(f"heading noise, {K} transects, deviation drawn from the prior: RMS error/SE within 0.7-1.3 "
                           "(misalignment, beds: worse)", max(rms, key=lambda z: abs(np.log(z))),
                           all(0.7 <= z <= 1.3 for z in rms))]
    print_targets(res, targets)


def figure_survey(res: dict, path: Path) -> None:
    """(a) joint calibration time against transects, (b) misalignment error of the joint and the
    single-transect calibrations per survey, (c) coverage histogram; count axes in whole numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .common import integer_ticks

    fig, ax = plt.subplots(1, 3, figsize=(13, 4.2))
    rows = res["scale"]
    runs = [r["runs"] for r in rows]
    ax[0].plot(runs, [r["setup_s"] for r in rows], "o-", label="set-up")
    ax[0].plot(runs, [r["solve_s"] for r in rows], "s-", label="solve")
    ax[0].plot(runs, [r["total_s"] for r in rows], "^-", label="total")
    ax[0].set_xlabel("transects in one NLP (count)")
    ax[0].set_ylabel("wall time (s)")
    integer_ticks(ax[0].xaxis)
    ax[0].set_title(f"(a) joint calibration time, {res.get('starts', 24)} starts", fontsize=10)
    ax[0].legend(fontsize=9)
    seeds = []
    for a in res["accuracy"]:
        j = a["joint"]
        seeds.append(a["survey_seed"])
        ax[1].errorbar(a["survey_seed"], j["misalignment_error_deg"], yerr=3 * j["misalignment_se_deg"], fmt="o",
                       color="C0", capsize=3, label="joint (all transects)" if len(seeds) == 1 else None)
        for k, s in enumerate(a["singles"]):
            ax[1].errorbar(a["survey_seed"] + 0.2 * (k + 1), s["misalignment_error_deg"], yerr=3 * s["misalignment_se_deg"],
                           fmt="x", color="C1", capsize=3, label="single transects" if len(seeds) == 1 and k == 0 else None)
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set_xticks(seeds)  # a survey's seed is a name: its singles sit just right of it
    ax[1].set_xlabel("survey seed")
    ax[1].set_ylabel("misalignment error (deg)")
    ax[1].set_title("(b) joint vs single-transect misalignment, bars 3 SE", fontsize=10)
    ax[1].legend(fontsize=9)
    cov = res["coverage"]["rows"]
    z = [r["misalignment_error_deg"] / r["misalignment_se_deg"] for r in cov]
    zw = [r["misalignment_error_deg"] / r["misalignment_white_se_deg"] for r in cov]
    ax[2].hist([zw, z], bins=15, label=["white-noise SE", "reported SE (HAC)"])
    for x in (-3, 3):
        ax[2].axvline(x, color="k", lw=0.5)
    ax[2].set_xlabel("misalignment error / SE (dimensionless)")
    ax[2].set_ylabel("surveys (count)")
    integer_ticks(ax[2].yaxis)
    ax[2].set_title("(c) coverage, AR(1) noise, two-transect surveys", fontsize=10)
    ax[2].legend(fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
