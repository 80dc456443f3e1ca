"""Output fit to hand to a hydrographer (issue 26 items 4-5): terminal tables within 100
characters with a unit under every number column and the abbreviations explained, warnings on
stderr, ADCPDYN_PROGRESS=0 silencing every bar; figures with frequency in Hz up to the pings'
Nyquist, channels in a fixed order, one length unit, legends clear of the data and the ticks,
whole-number ticks on count axes."""

from __future__ import annotations

import dataclasses
import io
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import adcpdyn
from adcpdyn.cli import main
from adcpdyn.text import TABLE_WIDTH, Column, text_table

MIN_FONT_PT = 8.0
PERCENT = re.compile(r"^(-?\d+\.\d|n/a)$")  # one decimal, never four


def _table(text: str, first: str, n_rows: int) -> list[str]:
    """The first table in ``text``: its header (starting with ``first``), unit line and rows."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(first + " "))
    return lines[start:start + 2 + n_rows]


def _metric_rows(speed_m_s: float, distance_m: float) -> dict:
    base = {"mean_m_s": speed_m_s, "sd_m_s": 0.21, "rsd_pct": 12.3456, "mae_m_s": 0.0314, "mre_pct": 13.0123,
            "error_sd_m_s": 0.0504, "error_rsd_pct": 12.4444, "displacement_m": distance_m,
            "distance_error_m": 3.1911, "distance_re_pct": 3.5231, "vector_error_rms_m_s": 0.1581,
            "direction_error_rms_deg": 26.31}
    rows = {m: dict(base) for m in ("asc", "adc", "paper_literal", "rootfinder", "oracle")}
    rows["paper_literal"]["mre_pct"] = float("nan")
    rows["reference"] = {k: (0.0 if "error" in k or k.startswith(("mae", "mre")) else v) for k, v in base.items()}
    return rows


@pytest.mark.parametrize("speed_m_s, distance_m", [(0.0085, 0.381), (5.2, 12345.678)])  # a pool boat, a ship
def test_metric_table_fits_100_characters_with_units_one_decimal_percentages_and_a_legend(speed_m_s, distance_m):
    from adcpdyn.estimators.statistics.metrics import METRIC_COLUMNS, format_table

    text = format_table(_metric_rows(speed_m_s, distance_m))
    lines = text.splitlines()
    assert max(len(ln) for ln in lines) <= TABLE_WIDTH, text
    table = _table(text, "method", 6)
    assert table[1].split() == [unit for _, unit, _, _ in METRIC_COLUMNS.values()]  # a unit under every column
    percent = [k for k, (_, unit, _, _) in enumerate(METRIC_COLUMNS.values()) if unit == "%"]
    for row in table[2:]:
        cells = row.split()[1:]
        assert len(cells) == len(METRIC_COLUMNS), row
        assert all(PERCENT.match(cells[k]) for k in percent), row
        assert all(len(c.partition(".")[2]) <= 3 for c in cells), row
    legend = " ".join(lines[len(table):])
    for abbreviation in ("R:", "MAE", "MRE", "Err:", "Disp:", "Dist:", "VecErr", "DirErr"):
        assert abbreviation in legend, abbreviation
    assert ("12346 " if distance_m > 1000 else "0.381 ") in text and "12345.6" not in text  # metres: no spurious digits


def test_a_table_too_wide_is_split_into_blocks_each_repeating_the_first_column():
    columns = [Column(f"k{i}", f"head{i}", "m", 3) for i in range(20)]
    rows = {"first_case": {f"k{i}": 1234.5678 * i for i in range(20)}, "second": {f"k{i}": -1.0 for i in range(20)}}
    text = text_table(rows, columns, first="case", legend="head0..head19: twenty lengths " * 8)
    lines = text.splitlines()
    assert max(len(ln) for ln in lines) <= TABLE_WIDTH
    headers = [ln for ln in lines if ln.startswith("case ")]
    assert len(headers) >= 2
    assert sorted(h for ln in headers for h in ln.split()[1:]) == sorted(c.head for c in columns)
    assert sum(ln.startswith("first_case ") for ln in lines) == len(headers)


def test_diagnosis_effect_table_and_formulation_table_fit_100_characters():
    from adcpdyn.estimators.diagnosis.report import parameter_text
    from adcpdyn.estimators.calibration.formulation_compare import format_rows

    row = {"objective": 1234.5678, "max_constraint_violation": 1.2e-9, "time_s": 1.234, "iterations_best": 23,
           "iterations_mean": 31.25, "fraction_at_best": 0.875, "n_unobservable": 0, "n_weak": 1,
           "tangential_radial_rms_m_s": 0.00041, "lever_arm_rms_error_m": 0.0123}
    text = format_rows({f: row for f in ("paper", "exact", "minimal", "free")})
    assert max(len(ln) for ln in text.splitlines()) <= TABLE_WIDTH, text
    assert text.splitlines()[1].split() == ["-", "-", "count", "count", "s", "fraction", "count", "count", "mm/s", "mm"]
    assert parameter_text("effect0.C_rad", np.radians(-28.6), np.radians(1.2)) == "C -28.6 deg ± 1.2 deg"
    assert parameter_text("effect0.omega_rad_s", 7.2, 0.03) == "omega +7.2 rad/s ± 0.03 rad/s"
    assert parameter_text("effect0.C_rad", -0.5, 0.0, at_bound=True).endswith("at its bound: not determined")
    assert parameter_text("tilt_lowpass.tau_s", 2.5, 5e9, span=5.0) == \
        "tau +2.5 s, not determined (its standard error exceeds its range of 5 s)"
    assert parameter_text("effect0.C_rad", -0.1, 6.0, span=1.0).endswith("range of 57.3 deg)")
    assert parameter_text("tilt_lowpass.tau_s", 0.5, 0.1, span=5.0) == "tau +0.5 s ± 0.1 s"


def test_selftest_confusion_matrix_fits_100_characters():
    from adcpdyn.api import _diagnosis_config
    from adcpdyn.estimators.diagnosis.selftest import format_summary, summarise

    labels = list(_diagnosis_config(None).effects)
    rows = [dict(expected=e, verdict=v, correct=e == v, remaining_gap_significant=False, where_top="bt",
                 shrink_reported=0.5, shrink_oracle=0.5, platform="pool")
            for e, v in [("installation_misalignment", "installation_misalignment"), ("heave", "surge+heave"),
                         ("none", "none")] * 40]
    text = format_summary(summarise(rows, labels))
    matrix = text.split("\ncases:")[0].splitlines()
    assert len(matrix) == len(labels) + 3 and max(len(ln) for ln in matrix) <= TABLE_WIDTH, text
    row = next(ln for ln in matrix if ln.split()[1:2] == ["heave"])
    surge = labels.index("surge") + 1
    assert int(row.split()[1 + surge]) == 40  # heave's cases counted in surge's numbered column


def test_demo_and_compare_tables_fit_and_warnings_go_to_stderr(tmp_path, capfd, monkeypatch):
    monkeypatch.setenv("ADCPDYN_PROGRESS", "0")
    out_dir = tmp_path / "demo"
    assert main(["demo", "--starts", "2", "--scenario", "pool_m1", "--out", str(out_dir)]) == 0
    out, err = capfd.readouterr()
    table = _table(out, "method", 6)
    assert max(len(ln) for ln in table) <= TABLE_WIDTH and table[-1].startswith("truth "), table
    long = [ln for ln in (out + err).splitlines() if len(ln) > TABLE_WIDTH]
    assert not long, long  # prose (the case summary, the solver's line, warnings) wraps as the tables do
    assert "warning:" not in out and "warning: " in err  # the head-frame attitude's warning
    assert "multistart" not in err and "\r" not in err
    assert main(["compare", str(out_dir / "pool_m1.h5"), "--calibration", str(out_dir / "calibration.json")]) == 0
    out, err = capfd.readouterr()
    table = _table(out, "method", 6)
    assert max(len(ln) for ln in out.splitlines()) <= TABLE_WIDTH, out
    assert table[1].split()[:3] == ["mm/s", "mm/s", "%"]


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_zero_silences_every_bar_even_on_a_terminal(monkeypatch):
    from adcpdyn import batch
    from adcpdyn.progress import progress_bar_enabled
    from adcpdyn.solvers.multistart import multistart

    class Broken:  # a solver that fails at once: the bar is all that would print
        def __call__(self, **kw):
            raise RuntimeError("no solve")

        def stats(self):
            return {}

    for setting, shown in (("0", False), ("", True)):
        terminal = _Terminal()
        monkeypatch.setattr(sys, "stderr", terminal)
        monkeypatch.setenv("ADCPDYN_PROGRESS", setting)
        assert progress_bar_enabled() is shown
        multistart(Broken(), np.zeros((3, 2)), -np.ones(2), np.ones(2), np.zeros(0), np.zeros(0), np.zeros(0))
        with batch._bar(2, None) as bar:
            assert bar.disable is not shown
        assert ("multistart" in terminal.getvalue()) is shown


# ------------------------------------------------------------------------------------------ figures
def _draw(fig):
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _fonts_at_least(fig, minimum: float) -> list:
    """Every visible text of the figure (ticks, labels, titles, letters, legends) smaller than ``minimum``."""
    small = [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_fontsize") and hasattr(a, "get_text"))
             if t.get_visible() and t.get_text().strip() and t.get_fontsize() < minimum]
    return small


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


@pytest.fixture(scope="module")
def diagnosis():
    from adcpdyn.cases.scenario import get_scenario

    sc = get_scenario("diag_boat")  # as tests/test_cli_surface.py: 30 s, a few seconds to diagnose
    sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=30.0))
    case = adcpdyn.simulate(sc, seed=3)
    return case, adcpdyn.diagnose(case, effects=["attitude_latency"])


@pytest.mark.slow  # 9 s: `make test-slow`, CI's second step
def test_diagnosis_figure_hz_up_to_the_pings_nyquist_channels_in_order_readable(diagnosis, tmp_path):
    import matplotlib.pyplot as plt

    from adcpdyn.estimators.diagnosis import report

    case, result = diagnosis
    result = dataclasses.replace(result, verdict="attitude_latency")  # base and an effect, both drawn
    nyquist = 0.5 / np.median(np.diff(case.pings.time_s))
    assert report.ping_nyquist_hz(case) == pytest.approx(nyquist)
    fig = report.residual_figure(result)
    try:
        renderer = _draw(fig)
        time_axes, spectrum_axes = fig.axes[0::2], fig.axes[1::2]
        assert [ax.get_ylabel().split("\n")[0] for ax in time_axes] == (
            [f"BT beam {i}" for i in range(1, 5)] + [f"range beam {i}" for i in range(1, 5)]
            + ["reference north", "reference east", "reference down", "heading", "pitch", "roll"])
        assert all(ax.get_ylabel().endswith("r/σ") for ax in time_axes)
        assert time_axes[-1].get_xlabel() == "time (s)" and spectrum_axes[-1].get_xlabel() == "frequency (Hz)"
        for ax in spectrum_axes:
            low, high = ax.get_xlim()
            assert high == pytest.approx(nyquist) and low == pytest.approx(1 / 30.0, rel=0.1)
            curves = [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]
            assert len(curves) == 2  # base and the effect
            assert all(np.max(ln.get_xdata()) <= nyquist * (1 + 1e-12) for ln in curves)
            assert ax.get_xscale() == "log"
        letters = [t.get_text() for ax in fig.axes for t in ax.texts]
        assert letters[:2] == ["(a)", "(b)"] and letters[-2:] == ["(aa)", "(ab)"]
        assert all(re.fullmatch(r"\([a-z]+\)", s) for s in letters) and len(set(letters)) == len(letters)
        assert not _fonts_at_least(fig, MIN_FONT_PT)
        assert not any(ax.get_legend() for ax in fig.axes) and len(fig.legends) == 1
        legend = fig.legends[0].get_window_extent(renderer)
        assert not any(_overlaps(legend, ax.get_tightbbox(renderer)) for ax in fig.axes)
        texts = [t.get_text() for t in fig.legends[0].get_texts()]
        assert texts[:2] == ["base model", "with attitude_latency"] and texts[-1].endswith("Hz")
    finally:
        plt.close(fig)
    written = report.figures(result, tmp_path / "first.json", "png") + report.figures(result, tmp_path / "second.json", "png")
    assert written == [tmp_path / "first_residuals.png", tmp_path / "second_residuals.png"]  # one run, two reports: two figures
    assert all(w.stat().st_size > 10_000 for w in written)


def test_channel_order_and_labels_of_a_joint_diagnosis():
    from adcpdyn.estimators.diagnosis.report import channel_label, channel_sort_key

    shuffled = ["r2/motion_east", "r1/roll", "r1/reference_down", "r1/bt_beam3", "r1/range_beam1", "r1/bt_beam1",
                "r1/heading", "r1/reference_north", "r1/pitch", "r1/motion_north", "r1/bt_beam2"]
    assert [channel_label(c) for c in sorted(shuffled, key=channel_sort_key)] == [
        "BT beam 1", "BT beam 2", "BT beam 3", "range beam 1", "reference north", "reference down", "heading", "pitch",
        "roll", "motion prior north", "motion prior east"]


def test_diagnose_prints_within_100_characters_with_hz_and_units(diagnosis):
    from adcpdyn.estimators.diagnosis.report import table, terminal_text

    _, result = diagnosis
    text = terminal_text(result)
    assert max(len(ln) for ln in text.splitlines()) <= TABLE_WIDTH, text
    assert "rad/s" not in text.split("Which effect")[0] and " Hz" in text
    assert "bt 0.00" in text and re.search(r"bt \d\.\d+ m/s", text) and re.search(r"heading \d\.\d+ deg", table(result))
    assert "delay +0.00" in text and " s ± " in text  # the latency in seconds, said so
    # the bottom track's own floor beside its fitted level, as its error velocity gives it
    from adcpdyn.cases.summary import error_velocity_levels

    case = result.fits["base"][0].base.runs[0].case
    floor = error_velocity_levels(case.pings.bt_radial_m_s, case.instrument.beam_directions())[1]
    assert f"the bottom track's error velocity alone implies {floor:.3g} m/s per beam" in " ".join(text.split())
    assert f"error velocity alone implies {floor:.3g} m/s per beam" in table(result)


def test_panel_labels_go_past_z_in_letters():
    from adcpdyn.plots import panel_label

    assert [panel_label(k) for k in (0, 25, 26, 27, 51, 52)] == ["a", "z", "aa", "ab", "az", "ba"]
    with pytest.raises(ValueError, match="^k: "):
        panel_label(-1)


@pytest.mark.parametrize("scale, unit", [(1.0, "cm"), (20.0, "m")])
def test_radius_vectors_one_length_unit_and_the_legend_clear_of_panels_and_ticks(monkeypatch, scale, unit):
    from adcpdyn import plots

    figs = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figs.append(fig))
    r = scale * np.array([[-0.015, 0.0, 0.15], [0.015, 0.0, 0.15], [0.0, 0.015, 0.15], [0.0, -0.015, 0.15]])
    se = np.full((4, 3), 0.004 * scale)
    se[0, 0] = np.inf  # undetermined: no bar, no infinite axis
    plots.radius_vectors_figure(r + 0.002 * scale, se, r, "body", "r.png")
    fig = figs[-1]
    renderer = _draw(fig)
    labels = [label for ax in fig.axes for label in (ax.get_xlabel(), ax.get_ylabel(), getattr(ax, "get_zlabel", str)())
              if label]
    assert len(labels) == 5 and all(label.endswith(f"({unit})") for label in labels), labels
    assert not any(ax.get_legend() for ax in fig.axes) and len(fig.legends) == 1
    legend = fig.legends[0].get_window_extent(renderer)
    assert not any(_overlaps(legend, ax.get_tightbbox(renderer)) for ax in fig.axes)
    assert not _fonts_at_least(fig, MIN_FONT_PT)
    top = fig.axes[1]
    assert top.yaxis_inverted() and np.all(np.isfinite(top.get_xlim()))  # seen from above, z down
    import matplotlib.pyplot as plt

    plt.close(fig)


# -------------------------------------------------------------------------------- benchmark figures
def _captured(monkeypatch, module):
    figs = []
    monkeypatch.setattr(module, "save_figure", lambda fig, path: figs.append(fig))
    return figs


def _whole(ticks, low, high) -> bool:
    inside = [t for t in ticks if low - 1e-9 <= t <= high + 1e-9]
    return bool(inside) and all(float(t).is_integer() for t in inside)


def test_survey_bench_figure_counts_in_whole_numbers(monkeypatch):
    from adcpdyn.benchmarks import survey

    figs = _captured(monkeypatch, survey)
    rng = np.random.default_rng(0)
    single = {"misalignment_error_deg": 0.5, "misalignment_se_deg": 2.0}
    res = {"starts": 24, "scale": [{"runs": k, "setup_s": 1.0, "solve_s": 2.0 * k, "total_s": 1.0 + 2.0 * k} for k in (1, 2, 4)],
           "accuracy": [{"survey_seed": s, "joint": {"misalignment_error_deg": 0.1, "misalignment_se_deg": 0.1},
                         "singles": [single, single]} for s in (101, 102)],
           "coverage": {"rows": [{"misalignment_error_deg": e, "misalignment_se_deg": 1.0, "misalignment_white_se_deg": 0.5}
                                 for e in rng.normal(size=7)]}}
    survey.figure_survey(res, Path("s.png"))
    fig = figs[-1]
    _draw(fig)
    a, b, c = fig.axes
    assert _whole(a.get_xticks(), 1, 4) and list(b.get_xticks()) == [101, 102]
    assert _whole(c.get_yticks(), *c.get_ylim())
    assert all(ax.get_xlabel() and ax.get_ylabel() for ax in (a, b, c))
    assert "(count)" in a.get_xlabel() and "(count)" in c.get_ylabel() and "(s)" in a.get_ylabel()
    assert not _fonts_at_least(fig, MIN_FONT_PT)


def test_other_bench_figures_label_their_axes_with_units(monkeypatch):
    from adcpdyn.benchmarks import common, formulations, scale

    results = Path(common.__file__).parent / "results"
    for module, figure, name in ((formulations, formulations.figure_formulations, "formulations_quick"),
                                 (scale, scale.figure_scale, "scale_quick")):
        figs = _captured(monkeypatch, module)
        figure(json.loads((results / f"{name}.json").read_text()), Path("x.png"))
        fig = figs[-1]
        _draw(fig)
        for ax in fig.axes:
            assert re.search(r"\((s|MB|mm/s|fraction|pings)\)$", ax.get_ylabel()), ax.get_ylabel()
            assert ax.get_xlabel(), name
        assert not _fonts_at_least(fig, MIN_FONT_PT), name


def test_weak_directions_are_said_in_words():
    """A weakly determined direction is named by its largest unknowns (trading off, together, one
    alone, a mix), the coefficients kept in brackets."""
    import numpy as np

    from adcpdyn.estimators.statistics.uncertainty import _describe

    names = ["compass_deviation_cos", "compass_deviation_sin", "heading_misalignment", "moving_bed_north"]
    assert _describe(np.array([0.82, -0.55, 0.1, 0.06]), names, {}).startswith(
        "compass deviation cos against compass deviation sin (one up and the other down fits as well) (+0.82")
    assert _describe(np.array([0.1, 0.0, 0.72, 0.69]), names, {}).startswith(
        "heading misalignment and moving bed north together")
    assert _describe(np.array([0.99, 0.1, 0.0, 0.0]), names, {}).startswith("compass deviation cos alone")
    assert _describe(np.array([0.5, 0.5, 0.5, 0.5]), names, {}).startswith("a mix of ")


def test_prose_wraps_to_the_table_width_without_splitting_numbers_or_names():
    from adcpdyn.text import prose

    line = "heading misalignment against the reference (deg): +19.8767 +- 0.7858 (true heading = " + "x " * 40
    lines = prose(line).splitlines()
    assert lines[0].startswith("heading misalignment against the reference (deg): +19.8767 +- 0.7858")
    assert all(len(ln) <= TABLE_WIDTH for ln in lines) and all(ln.startswith("    ") for ln in lines[1:])
    assert prose("short  line  ") == "short  line  "  # a line that fits is left as it is
    path = "/a/" + "b" * 120
    assert path in prose(f"wrote {path}")  # a word longer than the width stays whole


def test_weak_directions_in_the_boats_own_velocity_are_summarised_in_one_phrase():
    """Thirty weak directions among the per-knot velocities are one phrase (runs, components), not
    thirty coefficient vectors; the platform's own weak direction is still named in words."""
    import numpy as np

    from adcpdyn.estimators.statistics.uncertainty import uncertainty

    names = [f"run2/V{k}_{a}" for k in range(10) for a in "xyz"] + ["heading_misalignment", "moving_bed_north"]
    n = len(names)
    J = 1e3 * np.eye(n)  # in scaled unknowns: SE 1e-3 of a scale, well determined
    J[np.arange(2, 30, 3), np.arange(2, 30, 3)] = 1.0  # the vertical velocities barely seen (SE a whole scale)
    J[-2:, -2:] = [[1e3, 1e3], [1e3, 1e3 + 5.0]]  # misalignment and bed barely told apart
    scale = np.ones(n)
    nav = np.array([nm.startswith("run2/V") for nm in names])
    unc = uncertainty(J, None, names, scale, {"navigation": nav})
    warn = next(w for w in unc.warnings if "weakly determined" in w)
    assert "10 in the boat's own velocity between its samples (run2; vertical component)" in warn, warn
    assert "heading misalignment" in warn and "run2/V" not in warn and "+0." not in warn, warn
    assert all("vector" in u and "words" in u for u in unc.unobservable)

def test_a_frequency_above_the_pings_nyquist_is_said_to_be_an_alias():
    """Heave fitted at 1.65 Hz from pings every 0.67 s (Nyquist 0.746 Hz) is the same samples as
    0.159 Hz: the report says so; below the Nyquist, or without one, nothing is added."""
    import numpy as np

    from adcpdyn.estimators.diagnosis.report import alias_note, parameters_text

    note = alias_note(2 * np.pi * 1.652, 0.746)
    assert "1.65 Hz: above the pings' Nyquist 0.746 Hz" in note and "alias of 0.16 Hz" in note, note
    t = np.arange(40) * (0.5 / 0.746)  # the pings really do see the two frequencies alike
    assert np.allclose(np.cos(2 * np.pi * 1.652 * t), np.cos(2 * np.pi * 0.16 * t), atol=0.02)
    assert alias_note(2 * np.pi * 0.5, 0.746) == "" and alias_note(2 * np.pi * 1.652, None) == ""
    score = {"effect": "heave", "params": {"heave.omega_rad_s": 2 * np.pi * 1.652, "heave.cos_m": 0.001},
             "params_se": {"heave.omega_rad_s": 0.005, "heave.cos_m": 0.0004}}
    assert "Nyquist" in parameters_text(score, 0.746) and "Nyquist" not in parameters_text(score)

def test_the_effect_table_shows_each_step_of_the_forward_selection_with_shares_of_the_base_gap():
    """Rounds are not merged by effect name (a later round's numbers under an earlier round's row):
    each step's rows say what they were judged against, and the share removed is of the base's gap,
    so a step whose own gap is small reads 26 %, not 1480 %."""
    from types import SimpleNamespace

    from adcpdyn.estimators.diagnosis.report import steps, table, terminal_text

    def score(k, effect, gap_after, sig):
        return {"round": k, "effect": effect, "gap_after": gap_after, "significant": sig, "delta_ll": 1.0,
                "delta_bic": -5.0, "p_value": 0.01, "params": {}, "params_se": {}, "status": "ok"}

    ranking = [score(1, "compass_deviation", 0.012, True), score(1, "moving_bed", 0.445, False),
               score(2, "moving_bed", -0.167, True), score(3, "heave", -0.224, False)]
    r = SimpleNamespace(case="x", verdict="compass_deviation+moving_bed", statement="", gap_before=0.687,
                        gap_after=-0.167, gap_z_before=11.1, gap_z_after=-2.7, velocity_error_before_m_s=None,
                        where=[], ranking=ranking, selected=["compass_deviation", "moving_bed"], given={},
                        base={}, noise={"bt": 0.01})
    plan = steps(r)
    assert [(k, against, round(ref, 3)) for k, against, ref, _ in plan] == [
        (1, "the base", 0.687), (2, "the base + compass_deviation", 0.012),
        (3, "the base + compass_deviation + moving_bed", -0.167)]
    text = terminal_text(r)
    rows = {ln.split()[0] + " " + ln.split()[1]: ln.split() for ln in text.splitlines()
            if ln[:1].isdigit() and len(ln.split()) > 6}
    assert rows["1 moving_bed"][5] == "0.445" and rows["2 moving_bed"][5] == "-0.167"
    assert rows["2 moving_bed"][6] == "26" and rows["1 compass_deviation"][6] == "98"  # (0.012 + 0.167) / 0.687
    assert "| 2 | moving_bed |" in table(r) and "| 26% |" in table(r)


def test_calibrate_says_what_the_run_shows_of_its_own_in_its_units():
    """The calibration's own-effects line: none said as such; each effect's unknowns in the field's units
    (angles in degrees); the diagnosis's note when it read them on another base than the calibration's."""
    from adcpdyn.cli.verbs.calibration import own_effects_line

    none = own_effects_line({"effects": [], "unknowns": {}, "navigation": "random_walk", "statement": "none"})
    assert none.startswith("own effects (") and none.endswith("): none")
    note = ("these are the calibration's own runs, calibrated on knots navigation while this base takes random_walk: "
            "compass_offset.A +5.7 +- 1.1 deg may be the two bases reading the same data apart")
    line = own_effects_line({"effects": ["compass_offset", "sound_speed_error"], "navigation": "random_walk",
                             "unknowns": {"compass_offset.A_rad": {"value": 0.1, "se": 0.02},
                                          "sound_speed_error.relative_error": {"value": 0.022, "se": None}},
                             "statement": "compass_offset explains the gap; " + note + " [base: pinned]"})
    assert "compass_offset (A +5.73 deg ± 1.1 deg); sound_speed_error (relative_error +0.022 ± n/a)" in line
    assert line.endswith(f"({note})")


def test_the_field_selftest_prints_a_table_within_the_width_and_why_each_error_was_missed():
    """``diagnose --field-selftest`` on a terminal: no line wider than TABLE_WIDTH however long the
    verdicts and reasons, the reasons beneath the table for the errors not named, sizes without a
    unit printed without a trailing space; the .md keeps the reasons in a column."""
    from adcpdyn.estimators.diagnosis.field_selftest import format_field_selftest, summarise, terminal_field_selftest
    from adcpdyn.text import TABLE_WIDTH

    def row(error, size, unit, verdict, hit, outcome, z=None):
        return {"error": error, "size": size, "unit": unit, "verdict": verdict, "hit": hit, "shrink": 0.5 if hit else None,
                "estimate_z": z, "gap": 0.1234, "gap_z": 12.5, "seconds": 5.2, "outcome": outcome}

    long = "under the file's detection limit (0.3 < 0.496 s; BIC change +49, shrink -96 %, held-out z -0.3) " * 2
    rows = [row("clean", 0.0, "", "none", True, "clean"),
            row("compass_offset_deg", 4.0, "deg", "compass_offset+attitude_latency+heave+moving_bed", True, "named", 1.2),
            row("attitude_latency_s", 0.3, "s", "none", False, long.strip()),
            row("sound_speed_relative", 0.04, "", "moving_bed", False, "outscored by moving_bed")]
    res = {"rows": rows, "summary": summarise(rows), "navigation": "random_walk"}
    out = terminal_field_selftest(res)
    assert max(len(line) for line in out.splitlines()) <= TABLE_WIDTH
    assert "- attitude_latency_s 0.3 s: under the file's detection limit" in out
    assert "- sound_speed_relative 0.04: outscored by moving_bed" in out
    assert "compass_offset_deg 4 deg: " not in out  # named: no reason listed
    md = format_field_selftest(res)
    assert "| attitude_latency_s | 0.3 s | none | no | under the file's" in md and "| 0.04 | moving_bed |" in md
