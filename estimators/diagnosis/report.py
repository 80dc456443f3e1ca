"""The diagnosis written out: DIAG.json, a readable Markdown table, and figures of the
held-out residuals per channel over time and frequency, before and after the verdict's
effect."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...cases.atomic import atomic_path
from ...cases.summary import error_velocity_levels
from ...models.effects import get_effect
from ...text import noise_level_text
from ..calibration.result import jsonable
from ..statistics.periodogram import lomb_scargle
from .model import noise_key


def write_json(result, path) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(jsonable(result.to_dict()), fh, indent=2)


def table(result, n_where: int = 6) -> str:
    """Markdown: verdict, gap, where (ranked channels) and the effect ranking."""
    r = result
    lines = [f"# Diagnosis of {r.case}", "", f"**Verdict: {r.verdict}** — {r.statement}", "",
             f"Held-out gap (excess chi-square per sample, 0 = fits to the noise): before {r.gap_before:.3f} "
             f"(z = {r.gap_z_before:.1f}), after {r.gap_after:.3f} (z = {r.gap_z_after:.1f}).", ""]
    if r.velocity_error_before_m_s is not None:
        lines += [f"Velocity error after correction (RMS horizontal, vs truth): base model "
                  f"{1000 * r.velocity_error_before_m_s:.1f} mm/s, with the verdict "
                  f"{1000 * r.velocity_error_after_m_s:.1f} mm/s.", ""]
    lines += ["## Where the gap lies (base model, held-out residuals)", "",
              "| rank | channel | score (z) | detail |", "|---:|---|---:|---|"]
    for k, w in enumerate(r.where[:n_where]):
        lines.append(f"| {k + 1} | {w['channel']} | {w['score']:.1f} | {w['detail']} |")
    plan = steps(r)
    lines += ["", "## Which effect, step by step (forward selection)", ""]
    lines += [f"- step {k}: against {against} (held-out gap {ref:.3f} chi2/n)" for k, against, ref, _ in plan]
    lines += ["", "| step | effect | delta LL | delta BIC | p-value | gap after | removes (of the base's gap) | "
              "significant | parameters (± SE) | solver |", "|---:|---|---:|---:|---:|---:|---:|:---:|---|---|"]
    nyquist = result_nyquist_hz(r)
    for k, _, ref, scores in plan:
        for s in scores:
            params = parameters_text(s, nyquist)
            if len(params) > 160:
                params = params[:157] + "..."
            p = "n/a (no unknowns)" if not np.isfinite(s["p_value"]) else f"{s['p_value']:.2g}"
            share = removed_share(s, ref, r.gap_before)
            lines.append(f"| {k} | {s['effect']} | {s['delta_ll']:.1f} | {s['delta_bic']:.1f} | {p} | "
                         f"{s['gap_after']:.3f} | {'n/a' if not np.isfinite(share) else f'{100 * share:.0f}%'} | "
                         f"{'yes' if s['significant'] else ''} | {params} | {s['status']} |")
    if r.base.get("skipped_effects"):
        lines += ["", "Not tried: " + "; ".join(f"{k} ({v})" for k, v in r.base["skipped_effects"].items())]
    lines += ["", noise_text(r)]
    return "\n".join(lines) + "\n"


UNIT_SUFFIXES = (("_rad_s", "rad/s"), ("_m_s", "m/s"), ("_s", "s"), ("_m", "m"))  # from the name; _rad in deg


def noise_text(result) -> str:
    """The noise levels with their units, and beside the bottom track's the beam noise its own error
    velocity implies (``adcpdyn info``): a bt level well above it is misfit the base leaves, not noise."""
    text = "Noise levels (one standard deviation): " + ", ".join(noise_level_text(g, v) for g, v in result.noise.items())
    fits = getattr(result, "fits", None) or {}
    runs = fits["base"][0].base.runs if "base" in fits else []
    floors = []
    for run in runs:
        _, beam, used = error_velocity_levels(run.case.pings.bt_radial_m_s, run.case.instrument.beam_directions())
        if used:
            floors.append(f"{beam:.3g} m/s" + (f" ({run.case.name})" if len(runs) > 1 else ""))
    if floors:
        text += f"; the bottom track's error velocity alone implies {', '.join(floors)} per beam"
    return text


def parameter_text(name: str, value: float, se: float | None, at_bound: bool = False, span: float | None = None) -> str:
    """One fitted unknown in the field's units: ``delay 0.0077 s ± 0.0011 s``, angles in degrees
    (``C -28.6 deg ± 1.2 deg``); one held at its bound says so instead of a standard error, and one
    whose standard error exceeds ``span`` (the width of its plausible range) is not determined:
    the data leave it anywhere in that range (a tilt low-pass under a motion model with no tilt
    rate to filter, ± 5e9 s)."""
    short = name.split(".", 1)[-1]
    unit, scale = "", 1.0
    if short.endswith("_rad"):  # an angle (a rate is _rad_s)
        short, unit, scale = short[:-4], "deg", float(np.degrees(1.0))
    else:
        for suffix, u in UNIT_SUFFIXES:
            if short.endswith(suffix):
                short, unit = short[:-len(suffix)], u
                break
    u = f" {unit}" if unit else ""
    if at_bound:
        return f"{short} {scale * value:+.4g}{u} at its bound: not determined"
    if span is not None and se is not None and np.isfinite(span) and (not np.isfinite(se) or se > span):
        return f"{short} {scale * value:+.4g}{u}, not determined (its standard error exceeds its range of {scale * span:.3g}{u})"
    spread = "± n/a" if se is None or not np.isfinite(se) else f"± {scale * se:.2g}{u}"
    return f"{short} {scale * value:+.4g}{u} {spread}"


PING_SAMPLED_FREQUENCIES = ("heave.omega_rad_s", "surge.omega_rad_s")  # seen only at the pings (and fixes)


def alias_note(omega_rad_s: float, nyquist_hz: float) -> str:
    """Words for a fitted frequency above the pings' Nyquist: the pings see it as its alias, so
    the fit cannot tell the one from the other (nor the amplitude's scale with it); else ''."""
    f = abs(omega_rad_s) / (2 * np.pi)
    if not np.isfinite(f) or not nyquist_hz or f <= nyquist_hz:
        return ""
    rate = 2.0 * nyquist_hz
    alias = abs(f - rate * np.round(f / rate))
    return (f" ({f:.3g} Hz: above the pings' Nyquist {nyquist_hz:.3g} Hz, to the pings an alias of {alias:.3g} Hz, "
            "which fits nearly alike)")


def parameters_text(score: dict, nyquist_hz: float | None = None) -> str:
    """An effect's fitted unknowns (:func:`parameter_text`), comma separated; a frequency the pings
    sample above their Nyquist ``nyquist_hz`` says so (:func:`alias_note`)."""
    bound = score.get("at_bound", [])
    spans = {p.name: p.upper - p.lower for p in get_effect(score["effect"]).parameters} if "effect" in score else {}
    out = []
    for n, v in score["params"].items():
        text = parameter_text(n, v, score["params_se"].get(n), n in bound, spans.get(n.split(".", 1)[-1]))
        if nyquist_hz and n in PING_SAMPLED_FREQUENCIES:
            text += alias_note(v, nyquist_hz)
        out.append(text)
    return ", ".join(out)


def result_nyquist_hz(result) -> float | None:
    """The lowest ping Nyquist frequency of a diagnosis's runs (None when its fits are not kept)."""
    fits = getattr(result, "fits", None) or {}
    runs = fits["base"][0].base.runs if "base" in fits else []
    return min((ping_nyquist_hz(run.case) for run in runs), default=None)


EFFECT_LEGEND = ("dLL, dBIC: change of log-likelihood and BIC against the step's model (dBIC < 0: better); p: "
                 "p-value; gap after: held-out excess chi2/n with the effect; removes: share of the base's held-out "
                 "gap the effect removes at its step; sig: significant (the step's best significant one joins the "
                 "model)")


def steps(result) -> list:
    """The forward selection as it ran: (step, the model the step's candidates are judged against,
    that model's held-out gap, the step's scores), from the ranking's rounds and the effects chosen."""
    ranking = [sc if isinstance(sc, dict) else sc.to_dict() for sc in result.ranking]
    given = list(getattr(result, "given", {}) or {})
    first = "the base" + (" with the run's own " + ", ".join(sorted({n.split(".")[0] for n in given})) if given else "")
    out, ref, against = [], result.gap_before, first
    for k in sorted({sc["round"] for sc in ranking}):
        scores = [sc for sc in ranking if sc["round"] == k]
        out.append((k, against, ref, scores))
        if k > len(result.selected):
            break
        chosen = result.selected[k - 1]
        ref = next((sc["gap_after"] for sc in scores if sc["effect"] == chosen), ref)
        against = f"{first} + {' + '.join(result.selected[:k])}"
    return out


def removed_share(score: dict, step_gap: float, base_gap: float) -> float:
    """The share of the base's held-out gap an effect removes at its step (NaN without a gap):
    comparable across steps, where each step's own gap may be small."""
    return (step_gap - score["gap_after"]) / base_gap if base_gap > 0 else float("nan")


def terminal_text(result, n_where: int = 6, width: int | None = None) -> str:
    """What ``adcpdyn diagnose`` prints: :func:`table`'s content for a terminal, no line (table,
    list or sentence) wider than :data:`~adcpdyn.text.TABLE_WIDTH` characters."""
    import textwrap

    from ...text import TABLE_WIDTH, Column, text_table

    width = width or TABLE_WIDTH
    r = result

    def para(text: str, indent: str = "") -> list:
        return textwrap.wrap(text, width=width, subsequent_indent=indent or "  ")

    lines = [f"Diagnosis of {r.case}"]
    lines += para(f"Verdict: {r.verdict} — {r.statement}")
    lines += para(f"Held-out gap (excess chi-square per sample, 0 = fits to the noise): before {r.gap_before:.3f} "
                  f"(z = {r.gap_z_before:.1f}), after {r.gap_after:.3f} (z = {r.gap_z_after:.1f}).")
    if r.velocity_error_before_m_s is not None:
        lines += para(f"Velocity error after correction (RMS horizontal, vs truth): base model "
                      f"{1000 * r.velocity_error_before_m_s:.1f} mm/s, with the verdict {1000 * r.velocity_error_after_m_s:.1f} mm/s.")
    lines += ["", "Where the gap lies (base model, held-out residuals; score z: chi-square excess in SDs), worst first:"]
    for k, w in enumerate(r.where[:n_where]):
        lines += textwrap.wrap(f"{k + 1:>2}. {w['channel']} (z = {w['score']:.1f}): {w['detail']}", width=width,
                               subsequent_indent="      ")
    lines += ["", "Which effect, step by step (forward selection):"]
    plan = steps(r)
    lines += para("; ".join(f"step {k}: against {against} (held-out gap {ref:.3f} chi2/n)" for k, against, ref, _ in plan))
    rows = {f"{k} {sc['effect']}": {**sc, "removed": removed_share(sc, ref, r.gap_before)}
            for k, _, ref, scores in plan for sc in scores}

    def cell(column, name, value):
        if column.key == "p_value":
            return "n/a" if value is None or not np.isfinite(value) else f"{value:.2g}"  # n/a: no unknowns
        if column.key == "significant":
            return "yes" if value else ""
        return column.text(value)

    columns = [Column("delta_ll", "dLL", "-", 1), Column("delta_bic", "dBIC", "-", 1), Column("p_value", "p", "-"),
               Column("gap_after", "gap after", "chi2/n", 3), Column("removed", "removes", "%", 0, 100.0),
               Column("significant", "sig", "")]
    if rows:
        lines.append(text_table(rows, columns, first="step effect", legend=EFFECT_LEGEND, width=width, cell=cell))
        lines.append("Fitted unknowns (± SE) and the solver's status, by step:")
        nyquist = result_nyquist_hz(r)
        for name, sc in rows.items():
            lines += textwrap.wrap(f"  {name}: {parameters_text(sc, nyquist) or 'no unknowns'}; {sc['status']}",
                                   width=width, subsequent_indent="      ")
    if r.base.get("skipped_effects"):
        lines += para("Not tried: " + "; ".join(f"{k} ({v})" for k, v in r.base["skipped_effects"].items()))
    lines += para(noise_text(r))
    return "\n".join(lines) + "\n"


# The residual figure's rows: bottom track beam by beam, ranges, the reference, the attitude,
# then the pseudo-observations of the navigation (priors on the vessel's motion) last.
CHANNEL_GROUPS = ("bt", "range", "reference", "heading", "pitch", "roll", "motion", "vertical")
CHANNEL_LABELS = {"bt": "BT beam", "range": "range beam", "reference": "reference", "motion": "motion prior",
                  "vertical": "vertical prior"}
AXIS_ORDER = {"north": 0, "east": 1, "down": 2}
FIGURE_FONT_PT = 9  # tick labels and legends; axis labels 10 pt


def channel_sort_key(channel: str) -> tuple:
    """A channel's place in the figure: group (:data:`CHANNEL_GROUPS`), then beam 1-4 or
    north/east/down; unknown groups after the known ones, by name."""
    local = channel.rpartition("/")[2]
    group, _, rest = local.partition("_")
    rank = CHANNEL_GROUPS.index(group) if group in CHANNEL_GROUPS else len(CHANNEL_GROUPS)
    if rest.startswith("beam") and rest[4:].isdigit():
        within = int(rest[4:])
    else:
        within = AXIS_ORDER.get(rest, 9)
    return rank, within, local


def channel_label(channel: str) -> str:
    """Words for a channel's row: ``bt_beam1`` -> ``BT beam 1``, ``reference_north`` -> ``reference north``."""
    group, _, rest = channel.rpartition("/")[2].partition("_")
    if rest.startswith("beam") and rest[4:].isdigit():
        rest = rest[4:]
    return f"{CHANNEL_LABELS.get(group, group)} {rest}".strip()


def ping_nyquist_hz(case) -> float:
    """The highest frequency the pings resolve: 0.5 / median ping interval (Hz)."""
    dt = np.diff(np.asarray(case.pings.time_s, dtype=float))
    dt = dt[np.isfinite(dt) & (dt > 0)]
    if dt.size == 0:
        raise ValueError(f"case {case.name}: fewer than two distinct ping times, no frequency resolved")
    return 0.5 / float(np.median(dt))


def spectrum_hz(t: np.ndarray, z: np.ndarray, f_max_hz: float):
    """(frequencies in Hz, Lomb-Scargle power of ``z``) from the lowest resolvable frequency
    (one cycle over the record) to ``f_max_hz``, or to the samples' own Nyquist when lower.

    The power is scipy's unnormalised periodogram, whose mean is the variance for white noise:
    of residuals divided by their noise level, white noise at that level reads 1.
    Returns None with fewer than 8 samples or no frequency to resolve.
    """
    if t.size <= 8:
        return None
    order = np.argsort(t)
    t, z = t[order], z[order]
    span = float(t[-1] - t[0])
    dt = np.diff(t)
    dt = dt[dt > 0]
    if span <= 0 or dt.size == 0:
        return None
    f_lo, f_hi = 1.0 / span, min(f_max_hz, 0.5 / float(np.median(dt)))
    if f_hi <= f_lo:
        return None
    n = int(np.clip(8 * span * (f_hi - f_lo), 200, 20000))  # 8 points per resolution element 1/span
    f = np.linspace(f_lo, f_hi, n)
    return f, lomb_scargle(t, z - z.mean(), 2 * np.pi * f)


def residual_figure(result):
    """The held-out residual figure as a matplotlib Figure (see :func:`figures`).

    One row per channel with samples, in a fixed order (:func:`channel_sort_key`: BT beams 1-4, ranges, the
    reference north/east/down, heading/pitch/roll, the motion priors last), every run of a
    joint diagnosis in the same row (marker and line style per run). Left: held-out residual
    over its noise level, r/sigma, against time. Right: its Lomb-Scargle periodogram against
    frequency in Hz, from one cycle over the record up to the Nyquist frequency of the pings
    (0.5 / median ping interval), with the attitude model's motion modes marked.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from ...plots import panel_letters

    base_model, _ = result.fits["base"]
    shown = [("base model", result.cv_residuals["base"], base_model)]
    if result.verdict in result.fits:
        shown.append((f"with {result.verdict}", result.cv_residuals[result.verdict], result.fits[result.verdict][0]))
    runs = base_model.base.runs
    run_names = [r.case.name for r in runs]
    nyquist = [ping_nyquist_hz(r.case) for r in runs]
    f_axis_max = max(nyquist)
    modes_hz = sorted({float(f"{w / (2 * np.pi):.3g}") for r in runs if getattr(r, "fit", None) is not None
                       for w, _ in r.fit.params.modes if 0 < w / (2 * np.pi) <= f_axis_max})
    by_local: dict = {}
    slices = base_model.channel_slices()
    for ch, _ in base_model.channels:
        if np.any(base_model.mask[slices[ch]] > 0):  # a channel without a sample (a reference without its down
            by_local.setdefault(ch.rpartition("/")[2], []).append(ch)  # component) gets no empty row
    rows = sorted(by_local, key=channel_sort_key)
    markers, styles = "ox^+sd", ("-", "--", ":", "-.")
    fig, axes = plt.subplots(len(rows), 2, figsize=(12, 1.45 * len(rows) + 1.6), squeeze=False, sharex="col",
                             layout="constrained")
    f_lo = f_axis_max
    for row, local in enumerate(rows):
        ax_t, ax_f = axes[row]
        for ch in by_local[local]:
            k = run_names.index(ch.rpartition("/")[0]) if "/" in ch else 0
            sigma = result.noise[noise_key(ch)]
            for j, (label, raw, model) in enumerate(shown):
                sl = model.channel_slices()[ch]
                m = model.mask[sl] > 0
                t, z = model.times[sl][m], raw[sl][m] / sigma
                ax_t.plot(t, z, markers[k % len(markers)], ms=2.5, color=f"C{j}", alpha=0.8)
                spec = spectrum_hz(t, z, nyquist[k])
                if spec is not None:
                    ax_f.loglog(spec[0], np.maximum(spec[1], 1e-6), styles[k % len(styles)], lw=0.9, color=f"C{j}")
                    f_lo = min(f_lo, float(spec[0][0]))
        ax_t.axhline(0.0, color="0.6", lw=0.6)
        ax_f.axhline(1.0, color="0.35", lw=0.8)
        for f in modes_hz:
            ax_f.axvline(f, color="tab:red", lw=0.9, alpha=0.5)
        ax_t.set_ylabel(f"{channel_label(local)}\nr/σ", fontsize=10)
        ax_f.set_ylabel("power", fontsize=10)
        ax_f.set_ylim(bottom=1e-2)
        for ax in (ax_t, ax_f):
            ax.tick_params(labelsize=FIGURE_FONT_PT, labelbottom=True)
            ax.grid(True, lw=0.4, color="0.88")
    axes[0, 1].set_xlim(f_lo, f_axis_max)
    axes[0, 1].xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axes[0, 1].xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axes[0, 1].xaxis.set_minor_formatter(NullFormatter())
    axes[0, 0].set_title("held-out residual over its noise level σ (dimensionless)", fontsize=10)
    axes[0, 1].set_title(f"Lomb-Scargle periodogram of r/σ up to the pings' Nyquist {f_axis_max:.3g} Hz\n"
                         "(dimensionless; grey line: white noise at σ = 1; red: motion modes)", fontsize=10)
    axes[-1, 0].set_xlabel("time in run (s)" if len(runs) > 1 else "time (s)", fontsize=10)
    axes[-1, 1].set_xlabel("frequency (Hz)", fontsize=10)
    panel_letters(axes)
    handles = [Line2D([], [], color=f"C{j}", marker="o", ls="-", ms=4, label=label) for j, (label, _, _) in enumerate(shown)]
    if len(runs) > 1:
        handles += [Line2D([], [], color="0.3", marker=markers[k % len(markers)], ls=styles[k % len(styles)], ms=4,
                           label=name) for k, name in enumerate(run_names)]
    if modes_hz:
        handles.append(Line2D([], [], color="tab:red", alpha=0.5, label="motion modes " + ", ".join(f"{f:.3g}" for f in modes_hz)
                              + " Hz"))
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 6), fontsize=FIGURE_FONT_PT,
               frameon=False)
    fig.suptitle(f"{result.case}: held-out residuals per channel, verdict {result.verdict}", fontsize=11)
    return fig


def figures(result, path, fmt: str = "png") -> list[Path]:
    """The held-out residual figure (:func:`residual_figure`), written as ``STEM_residuals.FMT``
    beside ``path`` (DIAG.json: ``DIAG_residuals.png``), so that two diagnoses written into one
    folder keep their own figures (``fmt``: png, pdf or svg)."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = residual_figure(result)
    out = path.with_name(f"{path.stem}_residuals.{fmt}")
    try:
        with atomic_path(out, suffix=f".{fmt}") as tmp:
            fig.savefig(tmp, dpi=100, format=fmt)
    finally:
        plt.close(fig)
    return [out]


def write_report(result, json_path, fmt: str = "png") -> list[Path]:
    """DIAG.json plus DIAG.md and the figure (``fmt``: png, pdf or svg) beside it."""
    json_path = Path(json_path)
    write_json(result, json_path)
    md = json_path.with_suffix(".md")
    with atomic_path(md) as tmp:
        Path(tmp).write_text(table(result))
    return [json_path, md] + figures(result, json_path, fmt)
