"""Benchmark helpers (the suites themselves run under `make bench`; targets are never asserted)."""

from __future__ import annotations

import numpy as np
import pytest

from adcpdyn.benchmarks.suites import run
from adcpdyn.benchmarks.scale import growth_exponent
from adcpdyn.solvers.linear_solvers import probe_linear_solver

TOL_EXPONENT = 1e-9


def test_growth_exponent_recovers_a_power_law():
    n = np.array([100, 1000, 10000])
    b, a = growth_exponent(n, 3.0 * n**1.3)
    assert abs(b - 1.3) < TOL_EXPONENT and abs(a - 3.0) < 1e-6


def test_largest_pair_is_timed_by_turns_and_its_fastest_taken(monkeypatch):
    """The two largest sizes' saved cases are calibrated alternately; each size's fastest gives the exponent,
    and a failed run is reported, not fitted."""
    from adcpdyn.benchmarks import scale

    order, times = [], {"a.h5": iter([2.0, 1.0, 1.5]), "b.h5": iter([9.0, 8.0, 4.0])}

    def worker(module, args, limit):
        assert module == "scale_worker" and args[0] == "--time"
        order.append(args[1])
        return {"calibration_s": next(times[args[1]])}, None

    monkeypatch.setattr(scale, "run_worker", worker)
    pair = scale.repeated_pair([{"n_pings": 100}, {"n_pings": 400}], ["a.h5", "b.h5"], 3, 60.0)
    assert order == ["a.h5", "b.h5"] * 3
    assert pair["fastest_s"] == [1.0, 4.0] and abs(pair["exponent"] - 1.0) < TOL_EXPONENT
    monkeypatch.setattr(scale, "run_worker", lambda *a: (None, "exceeded the time limit of 60 s"))
    failed = scale.repeated_pair([{"n_pings": 100}, {"n_pings": 400}], ["a.h5", "b.h5"], 3, 60.0)
    assert "exponent" not in failed and "100 pings: exceeded" in failed["failed"]


def test_mumps_loads_and_a_missing_solver_says_why():
    ok, note = probe_linear_solver("mumps")
    assert ok, note
    ok, note = probe_linear_solver("no_such_solver")
    assert not ok and note


def test_unknown_suite_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="suite"):
        run("everything", True, tmp_path)


def test_readme_block_is_replaced_between_its_markers_only(tmp_path):
    from adcpdyn.benchmarks.common import replace_marked_block

    begin, end = "<!-- t: begin -->", "<!-- t: end -->"
    path = tmp_path / "README.md"
    path.write_text(f"# title\n\nbefore\n{begin}\nold table\n{end}\nafter\n")
    replace_marked_block(path, begin, end, "new | table")
    assert path.read_text() == f"# title\n\nbefore\n{begin}\nnew | table\n{end}\nafter\n"
    path.write_text(f"no markers\n{end}\n")
    with pytest.raises(ValueError, match=r"^--readme: .* needs the line '<!-- t: begin -->' once"):
        replace_marked_block(path, begin, end, "x")
    assert path.read_text() == f"no markers\n{end}\n"  # left untouched


def test_solver_rows_are_judged_against_the_best_feasible_objective():
    """A penalty solution below the best by violating the constraints does not set the best; a
    failed row never does; starts count as at the best within the relative tolerance."""
    from adcpdyn.benchmarks.solver_comparison import FEASIBLE, OBJECTIVE_RTOL, _summarise

    def row(f, ok, g_viol, starts, solve_s=1.0):
        return {"objective": f, "success": ok, "g_violation": g_viol, "box_violation": 0.0, "solve_s": solve_s,
                "starts": [{"objective": s, "success": ok, "iterations": 10} for s in starts]}

    rows = _summarise({"ipopt": row(100.0, True, 0.0, [100.0, 100.0 * (1 + OBJECTIVE_RTOL / 2), 120.0], 2.0),
                       "penalty": row(99.9, True, 100 * FEASIBLE, [99.9, 99.9]),
                       "broken": row(50.0, False, 0.0, [50.0]),
                       "crashed": {"error": "process exited with status -11"}})
    assert rows["ipopt"]["best_objective"] == 100.0
    assert rows["ipopt"]["fraction_at_best"] == pytest.approx(2 / 3)
    assert rows["penalty"]["objective_rel_to_best"] == pytest.approx(-1e-3)
    assert rows["penalty"]["fraction_at_best"] == 0.0
    assert rows["penalty"]["solve_ratio_to_ipopt"] == pytest.approx(0.5)
    assert "best_objective" not in rows["crashed"]


def test_survey_day_targets_follow_the_rows(capsys):
    """The survey-day targets read the 20-transect one-core row, the one-core exponent and the
    diagnosis row: met and not met as the numbers say, a failed row reported, not a crash."""
    from adcpdyn.benchmarks.survey_day import print_survey_day

    def row(n, placement, s, **kw):
        return {"runs": n, "pings": 500 * n, "placement": placement, "calibration_s": s, "peak_rss_mb": 100.0 * n,
                "misalignment_error_deg": 0.01, "misalignment_se_deg": 0.02, **kw}

    base = {"pings_per_transect": 500, "sizes": [2, 20]}
    fast = {**base, "rows": [row(2, "one_core", 4.0), row(20, "one_core", 40.0), row(20, "here", 39.0),
                             row(20, "dask", 30.0), row(20, "here", 39.0, diagnosis_s=100.0, verdict="none")],
            "exponent_runs": 1.0}
    print_survey_day(fast)
    assert [t["met"] for t in fast["targets"]] == [True, True, True]
    assert "Dask LocalCluster (2 workers) 1.33x" in capsys.readouterr().out
    slow = {**base, "rows": [row(2, "one_core", 4.0), row(20, "one_core", 80.0),
                             {"runs": 20, "placement": "dask", "error": "worker exited with status 1: boom"}],
            "exponent_runs": 1.3}
    print_survey_day(slow)
    assert [t["met"] for t in slow["targets"]] == [False, False, False]
    assert "worker exited with status 1: boom" in capsys.readouterr().out


@pytest.mark.slow  # 2.8-4.6 s in two runs of make test on 2026-12-03's host: `make test-slow`, CI's second step
def test_navigation_window_check_is_the_weighted_spread_about_the_mean(capsys, monkeypatch):
    """bench navigation's window check: chi2/dof of estimates about their inverse-variance mean,
    against a hand computation; its target follows the number; a missing real file is listed."""
    from types import SimpleNamespace

    from adcpdyn.benchmarks import navigation_real as nav

    est = {1: (1.0, 0.5), 2: (2.0, 0.5), 3: (4.0, 1.0)}  # window -> (deg, SE deg)
    calls = iter(est.values())
    # the defaults: the third window keeps a bed, the second is not determined (out of the spread)
    defaults = iter([(1.0, 0.5, None), (9.0, np.inf, None), (2.0, 0.5, [0.01, 0.01])])
    plain = []

    def fake(cases, navigation, starts, **options):
        if options:  # a window: compass deviation and bed left out
            assert options == {"compass_deviation": "off", "moving_bed": "off"}
            m, s, bed = *next(calls), None
        else:  # the file itself first, then the windows with the defaults
            plain.append(1)
            m, s, bed = (0.0, 1.0, None) if len(plain) == 1 else next(defaults)
        r = SimpleNamespace(heading_misalignment_rad=np.radians(m), heading_misalignment_se_rad=np.radians(s),
                            moving_bed_velocity_se_m_s=bed, noise_sigma={"bt": 0.01}, multistart=SimpleNamespace(status="ok"))
        return r, 0.1

    monkeypatch.setattr(nav, "_calibrate", fake)
    monkeypatch.setattr(nav, "NAVIGATIONS", ("knots",))
    monkeypatch.setattr(nav, "WINDOWS", {"RiverPro_test01.PD0": (3, None)})
    res = nav.bench_navigation(quick=True)
    if res["missing"]:
        assert res["files"] == [] and "RiverPro_test01.PD0" in res["missing"][0]
        return
    w = np.array([4.0, 4.0, 1.0])
    m = np.array([1.0, 2.0, 4.0])
    mean = np.sum(w * m) / np.sum(w)
    window, default = res["windows"]
    assert window["chi2_per_dof"] == pytest.approx(np.sum(w * (m - mean) ** 2) / 2, rel=1e-9)
    assert default["options"] == nav.DEFAULTS and default["chi2_per_dof"] == pytest.approx(4.0 * 0.5, rel=1e-9)
    nav.print_navigation(res)
    assert [t["met"] for t in res["targets"]] == [window["chi2_per_dof"] <= nav.COVERED_CHI2,
                                                  default["chi2_per_dof"] <= nav.COVERED_CHI2]
    out = capsys.readouterr().out
    assert "| RiverPro_test01.PD0 | knots | bed and deviation off | +1.00 +- 0.50, +2.00 +- 0.50, +4.00 +- 1.00 |" in out
    assert "| defaults | +1.00 +- 0.50, +9.00 +- inf, +2.00 +- 0.50 (bed kept) | 2.00 |" in out


@pytest.mark.slow  # about 4 s: `make test-slow`, CI's second step
def test_graph_reuse_rows_say_which_set_ups_took_a_kept_graph(monkeypatch):
    from adcpdyn.benchmarks import graph_reuse
    from adcpdyn.estimators import model_cache

    monkeypatch.delenv(model_cache.CACHE_ENV, raising=False)
    off, on = graph_reuse.measure("pool_m0", repeats=2)
    assert (off["cache"], on["cache"]) == (False, True)
    assert off["graph"] == ["built", "built"] and on["graph"] == ["built", "kept"]
    assert len(set(off["objective"] + on["objective"])) == 1  # the same solves to the last digit
