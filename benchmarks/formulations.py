"""``adcpdyn bench formulations``: paper / exact / minimal / free on the same cases and seeds."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import Target, machine, print_targets, save_figure

SCENARIOS = ("pool_m0", "pool_diag")
KEYS = ("tangential_radial_rms_m_s", "lever_arm_rms_error_m", "max_constraint_violation", "iterations_mean",
        "time_s", "fraction_at_best", "success")


def bench_formulations(seeds: int, starts: int) -> dict:
    """Every formulation on each scenario and noise seed (one case per seed, shared by all)."""
    from ..cases.scenario import get_scenario
    from ..estimators.calibration.config import CalibrationConfig
    from ..estimators.calibration.formulation_compare import compare_formulations
    from ..cases.simulation import simulate

    out = {"suite": "formulations", "machine": machine(), "seeds": list(range(1, seeds + 1)), "starts": starts,
           "scenarios": {}}
    for scenario in SCENARIOS:
        per_seed = []
        for seed in range(1, seeds + 1):
            case = simulate(get_scenario(scenario), seed=seed)
            rows = compare_formulations(case, CalibrationConfig(n_starts=starts, seed=seed))
            per_seed.append({"seed": seed, "rows": {f: {k: r[k] for k in KEYS + ("objective", "n_unobservable", "n_weak")}
                                                     for f, r in rows.items()}})
        forms = list(per_seed[0]["rows"])
        summary = {f: {k: float(np.median([s["rows"][f][k] for s in per_seed])) for k in KEYS} for f in forms}
        out["scenarios"][scenario] = {"median": summary, "per_seed": per_seed}
    return out


def print_formulations(res: dict) -> None:
    print(f"formulations benchmark: {len(res['seeds'])} seeds, {res['starts']} starts per solve (medians over seeds)")
    print(f"{'scenario':<10}{'formulation':<12}{'tang mm/s':>10}{'lever mm':>9}{'max viol':>10}{'iter':>7}"
          f"{'time s':>8}{'at best':>8}{'success':>8}")
    for sc, block in res["scenarios"].items():
        for f, s in block["median"].items():
            print(f"{sc:<10}{f:<12}{1e3 * s['tangential_radial_rms_m_s']:>10.3f}{1e3 * s['lever_arm_rms_error_m']:>9.2f}"
                  f"{s['max_constraint_violation']:>10.1e}{s['iterations_mean']:>7.1f}{s['time_s']:>8.2f}"
                  f"{s['fraction_at_best']:>8.2f}{s['success']:>8.2f}")
    j = res["scenarios"]["pool_m0"]["median"]
    targets = [Target(f"pool_m0 {f}: tangential radial RMS <= 3 mm/s (median over seeds)",
                      1e3 * s["tangential_radial_rms_m_s"], 1e3 * s["tangential_radial_rms_m_s"] <= 3.0)
               for f, s in j.items()]
    print_targets(res, targets)


def figure_formulations(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(12, 3.8))
    scen = list(res["scenarios"])
    forms = list(res["scenarios"][scen[0]]["median"])
    width = 0.8 / len(scen)
    for k, sc in enumerate(scen):
        med = res["scenarios"][sc]["median"]
        x = np.arange(len(forms)) + k * width
        ax[0].bar(x, [1e3 * med[f]["tangential_radial_rms_m_s"] for f in forms], width, label=sc)
        ax[1].bar(x, [med[f]["time_s"] for f in forms], width, label=sc)
        ax[2].bar(x, [med[f]["fraction_at_best"] for f in forms], width, label=sc)
    for k, (a, title, label) in enumerate(zip(ax, ("tangential radial velocity error", "wall time per calibration",
                                                   "starts that reached the best"),
                                              ("RMS error (mm/s)", "wall time (s)", "share of starts (fraction)"))):
        a.set_xticks(np.arange(len(forms)) + width * (len(scen) - 1) / 2, forms)
        a.set_xlabel("lever-arm formulation")
        a.set_ylabel(label)
        a.set_title(f"({'abc'[k]}) {title}", fontsize=10)
    ax[2].set_ylim(0, 1)
    ax[0].legend(fontsize=9, title="scenario", title_fontsize=9)
    n = len(res["seeds"])
    fig.suptitle(f"formulations: medians over {n} seed{'s' if n != 1 else ''}, {res['starts']} starts")
    fig.tight_layout()
    save_figure(fig, path)
