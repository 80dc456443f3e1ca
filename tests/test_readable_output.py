"""Output fit to hand to a hydrographer (issue 26 items 4-5): terminal tables within 100
characters with a unit under every number column and the abbreviations explained, warnings on
stderr, ADCPDYN_PROGRESS=0 silencing every bar; figures with frequency in Hz up to the pings'
Nyquist, channels in a fixed order, one length unit, legends clear of the data and the ticks,
whole-number ticks on count axes."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

import adcpdyn

MIN_FONT_PT = 8.0


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
    written = report.figures(result, tmp_path, "png")
    assert written == [tmp_path / f"{case.name}_residuals.png"] and written[0].stat().st_size > 10_000


def test_channel_order_and_labels_of_a_joint_diagnosis():
    from adcpdyn.estimators.diagnosis.report import channel_label, channel_sort_key

    shuffled = ["r2/motion_east", "r1/roll", "r1/reference_down", "r1/bt_beam3", "r1/range_beam1", "r1/bt_beam1",
                "r1/heading", "r1/reference_north", "r1/pitch", "r1/motion_north", "r1/bt_beam2"]
    assert [channel_label(c) for c in sorted(shuffled, key=channel_sort_key)] == [
        "BT beam 1", "BT beam 2", "BT beam 3", "range beam 1", "reference north", "reference down", "heading", "pitch",
        "roll", "motion prior north", "motion prior east"]


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
