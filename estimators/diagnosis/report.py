"""The diagnosis written out: DIAG.json, a readable Markdown table, and figures of the
held-out residuals per channel over time and frequency, before and after the verdict's
effect."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...cases.atomic import atomic_path
from ..calibration.result import jsonable
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
    lines += ["", "## Which effect", "",
              "| effect | delta LL | delta BIC | p-value | gap after | shrink | significant | parameters (± SE) | solver |",
              "|---|---:|---:|---:|---:|---:|:---:|---|---|"]
    for s in r.ranking:
        bound = s.get("at_bound", [])
        params = ", ".join(f"{n.split('.', 1)[1]} {v:+.4g} " + ("at its bound: not determined" if n in bound else
                                                                f"± {s['params_se'][n]:.2g}") for n, v in s["params"].items())
        if len(params) > 160:
            params = params[:157] + "..."
        p = "n/a (no unknowns)" if not np.isfinite(s["p_value"]) else f"{s['p_value']:.2g}"
        lines.append(f"| {s['effect']} | {s['delta_ll']:.1f} | {s['delta_bic']:.1f} | {p} | "
                     f"{s['gap_after']:.3f} | {100 * s['shrink_fraction']:.0f}% | {'yes' if s['significant'] else ''} | "
                     f"{params} | {s['status']} |")
    if r.base.get("skipped_effects"):
        lines += ["", "Not tried: " + "; ".join(f"{k} ({v})" for k, v in r.base["skipped_effects"].items())]
    lines += ["", "Noise levels: " + ", ".join(f"{g} {v:.3g}" for g, v in r.noise.items())]
    return "\n".join(lines) + "\n"


def figures(result, folder, fmt: str = "png") -> list[Path]:
    """Residuals over time and their Lomb-Scargle spectra per channel, base vs verdict (panels
    lettered (a), (b), ...; ``fmt``: png, pdf or svg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import signal

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    base_model, _ = result.fits["base"]
    shown = [("base", result.cv_residuals["base"], base_model)]
    if result.verdict in result.fits:
        shown.append((result.verdict, result.cv_residuals[result.verdict], result.fits[result.verdict][0]))
    channels = [w["channel"] for w in result.where]
    fig, axes = plt.subplots(len(channels), 2, figsize=(12, 1.6 * len(channels) + 1), squeeze=False)
    for row, ch in enumerate(channels):
        sigma = result.noise[noise_key(ch)]
        for label, raw, model in shown:
            sl = model.channel_slices()[ch]
            m = model.mask[sl] > 0
            t, z = model.times[sl][m], raw[sl][m] / sigma
            axes[row, 0].plot(t, z, ".", ms=2, label=label)
            if t.size > 8:
                order = np.argsort(t)
                w = np.linspace(0.05, 12.0, 500)
                p = signal.lombscargle(t[order], z[order] - z.mean(), w)
                axes[row, 1].semilogy(w, np.maximum(p, 1e-12), lw=0.8, label=label)
        axes[row, 0].set_ylabel(f"{ch}\n(r / sigma)", fontsize=7)
    axes[0, 0].legend(fontsize=7)
    axes[0, 0].set_title("held-out residuals over time")
    axes[0, 1].set_title("Lomb-Scargle power (rad/s)")
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("angular frequency (rad/s)")
    from ...plots import panel_letters

    panel_letters(axes)
    fig.tight_layout()
    stem = result.runs[0] + (f"_and_{len(result.runs) - 1}_more" if len(result.runs) > 1 else "") if result.runs else result.case
    out = folder / f"{stem}_residuals.{fmt}"
    with atomic_path(out, suffix=f".{fmt}") as tmp:
        fig.savefig(tmp, dpi=90, format=fmt)
    plt.close(fig)
    return [out]


def write_report(result, json_path, fmt: str = "png") -> list[Path]:
    """DIAG.json plus DIAG.md and the figure (``fmt``: png, pdf or svg) beside it."""
    json_path = Path(json_path)
    write_json(result, json_path)
    md = json_path.with_suffix(".md")
    with atomic_path(md) as tmp:
        Path(tmp).write_text(table(result))
    return [json_path, md] + figures(result, json_path.parent, fmt)
