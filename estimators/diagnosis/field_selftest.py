"""Self-test on the user's own file: each field error injected at typical sizes into the file's
recorded channels (:mod:`.field_errors`), on the file's own motion and noise, and diagnosed blind
with the file's own calibration. What it reports is what this file can detect: per error the
share named (top-1), the shrink found for the right effect, and the smallest size detected.
A survey (several runs of one boat) is tested the same way, jointly: the same error written into
every run (one compass, one clock, one bed), diagnosed with the survey's calibration.
"""

from __future__ import annotations

import time

import numpy as np

from ...cases.case import Case
from ..calibration.record import CalibrationRecord
from .config import DiagnosisConfig, holding
from .diagnose import calibration_own_effects, diagnose
from ..run_setup import has_moving_reference
from .field_errors import FIELD_ERRORS, detection_limit, estimate_z, inject_survey, injected_values, needs_reference
from .. import model_cache
from .own_effects import find_own_effects
from .signal_limit import own_delay_profile, signal_limit


def field_selftest(case, calibration: CalibrationRecord | None, config: DiagnosisConfig = DiagnosisConfig(),
                   sizes: dict | None = None, progress=None) -> dict:
    """Diagnose ``case`` (a run, or a survey's runs jointly) clean and with every field error of
    ``sizes`` ({error: sizes}, default the field's typical ones of the errors ``config.effects``
    can name, :func:`default_sizes`) injected, blind, as ``adcpdyn diagnose`` would with the
    calibration: the file's own effects (the calibration's ``own_effects``, else found here,
    :func:`.own_effects.find_own_effects`) held at their values, each a candidate for having moved.

    Returns ``{"rows": [...], "summary": {...}}``: one row per run (error, size, verdict, whether the
    error's effect was named first, the shrink and estimate reported for that effect, the gap
    and its z, seconds); the summary per error (top-1, smallest size detected) and the clean
    run's verdict (anything named there beyond the file's own effects is a false alarm).
    """
    sizes = sizes or default_sizes(config)
    runs = [case] if isinstance(case, Case) else list(case)
    case = runs[0] if len(runs) == 1 else runs  # what diagnose, the limits and the signatures take
    moving = all(has_moving_reference(c) for c in runs)
    trials = [("clean", 0.0)] + [(e, float(s)) for e, ss in sizes.items() for s in ss
                                 if moving or not needs_reference(e)]
    graphs = model_cache.stats()
    tic = time.perf_counter()
    first = diagnose(case, config, calibration=calibration)  # the calibration's own effects held, where they apply
    first_s = time.perf_counter() - tic
    recorded = calibration_own_effects(calibration, runs, config, first.fits["base"][0].base)
    own = recorded or find_own_effects(case, calibration, config, first=first)
    held = holding(config, own) if own["effects"] else config
    rows, limits, beyond, reasons = [], {}, {}, {}
    for error, size in trials:
        run = case if error == "clean" else inject_survey(runs, error, size, calibration)
        if error == "clean" and (recorded or not own["effects"]):  # the first diagnosis is the clean run's, as held
            r, seconds = first, first_s
        else:
            tic = time.perf_counter()
            r = diagnose(run, held, calibration=calibration)
            seconds = time.perf_counter() - tic  # one diagnosis, what a user waits for (not the own effects' rounds)
        expected = "none" if error == "clean" else FIELD_ERRORS[error][0]
        mine = next((s for s in r.ranking if s["effect"] == expected and s["round"] == 1), None)
        row = {"error": error, "size": size, "unit": FIELD_ERRORS[error][1] if error != "clean" else "",
               "expected": expected, "verdict": r.verdict, "hit": r.verdict.split("+")[0] == expected,
               "shrink": mine["shrink_fraction"] if mine else None, "estimate": mine["params"] if mine else None,
               "se": mine["params_se"] if mine else None, "gap": r.gap_before, "gap_z": r.gap_z_before,
               "seconds": seconds, "statement": r.statement}
        if error != "clean":  # the estimate against what was written in (on top of the file's own values)
            row["injected"] = injected_values(runs, error, size, calibration)
            row["estimate_z"] = estimate_z(row["estimate"], row["se"], row["injected"],
                                           {n: v.get("value") or 0.0 for n, v in own["unknowns"].items()})
        if error == "clean":
            # the file's detection limits, before anything is injected: what each error's effect would need on
            # top of the file's own (a given effect's: its moving from its values)
            first_round = {sc["effect"]: sc for sc in r.ranking if sc["round"] == 1}
            limits = {e: detection_limit(e, first_round[spec[0]]["detection_limit"]) if spec[0] in first_round else None
                      for e, spec in FIELD_ERRORS.items()}
            # what the file could show of each error at best (its forward signature): where it asks for more than
            # the effect's own linearised limit, or the effect has none (tilt low-pass, heave), it is the limit
            signal = {e: signal_limit(*r.fits["base"], case, e, config, calibration)
                      for e in dict.fromkeys(e for e, _ in trials[1:])}
            for e, sl in signal.items():
                if sl is not None and (limits.get(e) is None or sl["size"] > limits[e]):
                    limits[e] = sl["size"]
                    beyond[e] = sl["beyond"]
            row["signal_limits"] = signal
            if any(e == "attitude_latency_s" for e, _ in trials) and "attitude_latency" not in own["effects"]:
                profile = own_delay_profile(*r.fits["base"], config)
                if profile is not None:
                    row["attitude_delay_profile"] = profile
                    if profile["rise"] > profile["bar"]:  # read against the file's own peak: no size is told
                        limits["attitude_latency_s"], beyond["attitude_latency_s"] = max(map(abs, profile["delays"])), True
                        reasons["attitude_latency_s"] = (
                            f"the clean file's own attitude-delay profile peaks at {profile['peak_s']:+.2f} s, "
                            f"{profile['rise']:.0f} in log-likelihood over no delay (bar {profile['bar']:.0f}): a latency "
                            "is read against that peak, not zero")
            row["detection_limits"] = limits
            row["detection_limit_reasons"] = reasons
            row["own_effects"] = list(own["effects"])
        row["detection_limit"] = limits.get(error)
        row["detection_limit_beyond"] = beyond.get(error, False)  # not even the largest size searched shows
        row["detection_limit_reason"] = reasons.get(error)
        row["outcome"] = outcome(row, mine, r, config.min_gap)
        rows.append(row)
        if progress:
            progress(f"{error} {size:g}: {r.verdict}")
    return {"case": "+".join(c.name for c in runs), "rows": rows, "summary": summarise(rows),
            "navigation": first.base["navigation"], "own_effects": list(own["effects"]),
            "own_effects_from": "calibration" if own is recorded else "found here",
            "model_graphs": {k: v - graphs[k] for k, v in model_cache.stats().items() if k in ("hits", "misses")},
            "skipped": sorted(e for e in sizes if needs_reference(e)) if not moving else []}


def default_sizes(config: DiagnosisConfig) -> dict:
    """The field's typical sizes ({error: sizes}, :data:`.field_errors.FIELD_ERRORS`) of the errors
    whose catalog effect the diagnosis tries (``config.effects``): an error no candidate could name
    is not injected to be counted a miss."""
    return {e: spec[2] for e, spec in FIELD_ERRORS.items() if spec[0] in config.effects}


def outcome(row: dict, mine: dict | None, result, min_gap: float = 0.1) -> str:
    """Why an injected error was or was not named, in words: named; not tried (why); no gap to
    explain (the held-out excess of the model the candidates are judged against is under
    ``min_gap``: nothing can be significant, whatever was injected); under the file's detection
    limit (the clean run's, :func:`.field_errors.detection_limit`); below detection (its own effect
    fitted alone is not significant, though the size is above the limit); or outscored
    (it is significant, another effect was preferred: the two are hard to tell apart here)."""
    if row["expected"] == "none":
        return "clean" if row["verdict"] == "none" else f"names {row['verdict']}"
    if row["hit"]:
        return "named"
    if mine is None:
        why = result.base.get("skipped_effects", {}).get(row["expected"], "not among the candidates")
        return f"not tried: {why}"
    # the BIC change of adding the effect (negative: better; the coloured one, which decides)
    detail = f"BIC change {mine['delta_bic_hac']:+.0f}, " \
             f"shrink {100 * mine['shrink_fraction']:.0f} %" \
             + (f", held-out z {mine['heldout_z']:.1f}" if np.isfinite(mine.get("heldout_z", np.nan)) else "")
    limit = row.get("detection_limit")
    if not mine["significant"] and limit is not None and row["size"] < limit:
        unit = f" {row['unit']}" if row["unit"] else ""
        if row.get("detection_limit_reason"):
            return f"under the file's detection limit ({row['size']:g}{unit}: {row['detection_limit_reason']}; {detail})"
        if row.get("detection_limit_beyond"):
            return f"under the file's detection limit ({row['size']:g}{unit}: not even {limit:.3g}{unit} shows on this file; {detail})"
        return f"under the file's detection limit ({row['size']:g} < {limit:.3g}{unit}; {detail})"
    if not mine["significant"] and result.gap_before <= min_gap:
        return f"no gap to explain (held-out excess {result.gap_before:.2f}; {detail})"
    if not mine["significant"]:
        return f"below detection ({detail})"
    return f"outscored by {row['verdict'].split('+')[0]} ({detail})"


COVER_Z = 2.0  # an estimate within this many standard errors of the injected value covers it


def coverage(rows: list) -> dict:
    """Of the injected rows whose error was named with a standard error: how many estimates lie within
    :data:`COVER_Z` standard errors of what was injected, and the largest |z|."""
    z = [r["estimate_z"] for r in rows if r["error"] != "clean" and r["hit"] and r.get("estimate_z") is not None]
    return {"named_with_se": len(z), "within": int(sum(v <= COVER_Z for v in z)), "max_z": max(z, default=None)}


def summarise(rows: list) -> dict:
    per = {}
    for r in rows:
        if r["error"] != "clean":
            per.setdefault(r["error"], []).append(r)
    clean = [r for r in rows if r["error"] == "clean"]
    injected = [r for r in rows if r["error"] != "clean"]
    # detectable: at or above the file's detection limit, computed on the clean run before any injection; an
    # error without a limit (none could be computed) counts as detectable, so a miss there still counts
    detectable = [r for r in injected if r.get("detection_limit") is None or r["size"] >= r["detection_limit"]]
    return {
        "top1": float(np.mean([r["hit"] for r in injected])) if injected else None,
        # top-1 among the injections at or above the file's detection limit (from the clean run's information
        # and residual colour): what is left is the choice among effects, the rest is the file's limit
        "top1_detectable": float(np.mean([r["hit"] for r in detectable])) if detectable else None,
        "n_detectable": len(detectable), "n_injected": len(injected),
        "clean_verdict": clean[0]["verdict"] if clean else None,
        # the named errors' estimates against the sizes written in: how many lie within 2 standard errors
        "covered": coverage(injected),
        "per_error": {e: {"top1": float(np.mean([r["hit"] for r in rs])),
                          "smallest_detected": min([r["size"] for r in rs if r["hit"]], default=None),
                          # one file's limit (rows of several files, a bench, have several: None here)
                          "detection_limit": rs[0].get("detection_limit")
                          if len({r.get("detection_limit") for r in rs}) == 1 else None,
                          "detection_limit_beyond": bool(rs[0].get("detection_limit_beyond", False)),
                          "unit": rs[0]["unit"]} for e, rs in per.items()},
    }


def _z(row: dict) -> str:
    return "" if row.get("estimate_z") is None else f"{row['estimate_z']:.1f}"


def _size(row: dict) -> str:
    return f"{row['size']:g} {row['unit']}".strip()


def _summary_lines(res: dict) -> list:
    """The own effects held, the summary, the estimates' check and each error's line, as sentences."""
    s = res["summary"]
    lines = []
    own = res.get("own_effects") or []
    if own:
        lines += [f"The file's own effects ({', '.join(own)}; {res.get('own_effects_from', 'found here')}) are held at "
                  "their values in every run's model, as a diagnosis of the calibration's own runs holds them: the "
                  "verdicts are what changed on top of them (a given effect named: it moved from its values).", ""]
    lines.append(f"navigation {res['navigation']}; clean file: {s['clean_verdict']}; top-1 over the injected errors: "
                 f"{100 * (s['top1'] or 0):.0f} %; over the {s['n_detectable']} of {s['n_injected']} not under the "
                 f"file's detection limit: {100 * (s['top1_detectable'] or 0):.0f} %")
    c = s.get("covered") or {}
    if c.get("named_with_se"):
        lines.append(f"named errors whose estimate lies within {COVER_Z:g} standard errors of the size written in (on "
                     f"top of the file's own values): {c['within']} of {c['named_with_se']} (the farthest "
                     f"{c['max_z']:.1f} SE off)")
    for e, v in s["per_error"].items():
        smallest = "none" if v["smallest_detected"] is None else f"{v['smallest_detected']:g} {v['unit']}".strip()
        limit = "unknown" if v.get("detection_limit") is None else \
            f"{'over ' if v.get('detection_limit_beyond') else ''}{v['detection_limit']:.3g} {v['unit']}".strip()
        lines.append(f"- {e}: top-1 {100 * v['top1']:.0f} %, smallest detected {smallest}, detection limit {limit}")
    for e in res.get("skipped", []):
        lines.append(f"- {e}: not tried (needs a moving reference velocity)")
    g = res.get("model_graphs")
    if g:
        lines.append(f"model graphs: {g['misses']} built, {g['hits']} taken from a run of the same shape (the recorded "
                     f"numbers are the NLP's parameters; ${model_cache.CACHE_ENV} keeps {model_cache.capacity()})")
    return lines


def format_field_selftest(res: dict) -> str:
    """The self-test as a Markdown table and its summary (SELFTEST.md)."""
    lines = ["| error | size | verdict | named | why | shrink | estimate off by (SE) | gap (z) | s |",
             "|---|---:|---|---|---|---:|---:|---:|---:|"]
    for r in res["rows"]:
        shrink = "" if r["shrink"] is None else f"{100 * r['shrink']:.0f} %"
        lines.append(f"| {r['error']} | {_size(r)} | {r['verdict']} | {'yes' if r['hit'] else 'no'} | "
                     f"{r.get('outcome', '')} | {shrink} | {_z(r)} | "
                     f"{r['gap']:.3f} ({r['gap_z']:.1f}) | {r['seconds']:.0f} |")
    return "\n".join(lines + [""] + _summary_lines(res))


def terminal_field_selftest(res: dict, width: int | None = None) -> str:
    """What ``diagnose --field-selftest`` prints: the rows as a table no wider than
    :data:`~adcpdyn.text.TABLE_WIDTH`, why each error was not named beneath it, then the summary,
    every line wrapped to the width (the Markdown table, with the reasons in a column, is the .md)."""
    import textwrap

    from ...text import TABLE_WIDTH, Column, text_table

    width = width or TABLE_WIDTH
    rows = {f"{r['error']} {_size(r)}" if r["error"] != "clean" else "clean": r for r in res["rows"]}
    text = {"verdict": lambda r: r["verdict"], "hit": lambda r: "yes" if r["hit"] else "no",
            "shrink": lambda r: "" if r["shrink"] is None else f"{100 * r['shrink']:.0f}", "estimate_z": _z,
            "gap": lambda r: f"{r['gap']:.3f}", "gap_z": lambda r: f"{r['gap_z']:.1f}",
            "seconds": lambda r: f"{r['seconds']:.0f}"}
    columns = [Column("verdict", "verdict", ""), Column("hit", "named", ""), Column("shrink", "shrink", "%"),
               Column("estimate_z", "off by", "SE"), Column("gap", "gap", "chi2/n"), Column("gap_z", "gap z", ""),
               Column("seconds", "time", "s")]
    lines = [text_table(rows, columns, first="error, size", width=width,
                        cell=lambda column, name, value: text[column.key](rows[name]))]
    why = [(name, r.get("outcome", "")) for name, r in rows.items() if not r["hit"] and r.get("outcome")]
    if why:
        lines += ["", "not named, and why:"]
        for name, reason in why:
            lines += textwrap.wrap(f"- {name}: {reason}", width=width, subsequent_indent="  ")
    lines.append("")
    for line in _summary_lines(res):
        lines += textwrap.wrap(line, width=width, subsequent_indent="  ") or [""]
    return "\n".join(lines)


def write_field_selftest(res: dict, json_path, fmt: str = "png") -> list:
    """SELFTEST.json, SELFTEST.md and a figure (sizes tried per error, named or not) beside it."""
    import json
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...cases.atomic import atomic_path
    from ..calibration.result import jsonable

    json_path = Path(json_path)
    with atomic_path(json_path) as tmp, open(tmp, "w") as fh:
        json.dump(jsonable(res), fh, indent=2)
    md = json_path.with_suffix(".md")
    with atomic_path(md) as tmp:
        Path(tmp).write_text(f"# Field errors injected into {res.get('case', 'the file')}\n\n" + format_field_selftest(res) + "\n")
    errors = list(res["summary"]["per_error"])
    fig, axes = plt.subplots(1, max(len(errors), 1), figsize=(2.6 * max(len(errors), 1), 2.8), squeeze=False)
    for ax, e in zip(axes[0], errors):
        rs = [r for r in res["rows"] if r["error"] == e]
        for r in rs:
            ax.plot(r["size"], 1 if r["hit"] else 0, "o", color="C2" if r["hit"] else "C3", ms=9,
                    mfc="C2" if r["hit"] else "none")
        ax.set_ylim(-0.5, 1.5)
        ax.set_yticks([0, 1], ["missed", "named"])
        ax.set_xlabel(f"{e} ({rs[0]['unit'] or 'fraction'})", fontsize=8)
    fig.suptitle(f"{res.get('case', '')}: field errors injected, diagnosed blind ({res['navigation']})", fontsize=9)
    fig.tight_layout()
    figure = json_path.with_name(json_path.stem + f"_field_errors.{fmt}")
    with atomic_path(figure) as tmp:
        fig.savefig(tmp, format=fmt, dpi=110)
    plt.close(fig)
    return [json_path, md, figure]
