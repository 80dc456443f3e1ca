"""The real-file table of docs/real-data.md, from what ``benchmarks/real_data.sh OUT`` wrote:
``python -m adcpdyn.benchmarks.real_table OUT`` prints it (markdown), so the page is pasted from a
run, never typed. Per file: calibrate's status and time, the heading misalignment with the IGRF
declination and the compass error, the moving-bed test and bed, the compass deviation, the
head-frame lever arms, the corrections against GNSS (compare), and diagnose's verdict, held-out
gap and worst channel with its time."""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import numpy as np

from ..estimators.calibration.record import CalibrationRecord

STEPS = ("import", "calibrate", "compare", "correct", "diagnose")


def _times(out: Path) -> dict:
    """{(file, step): (exit status, seconds)} from the script's summary.txt."""
    found = {}
    for line in (out / "summary.txt").read_text().splitlines():
        m = re.fullmatch(r"(\S+) (\w+) exit (\d+), ([\d.]+) s", line.strip())
        if m:
            found[(m[1], m[2])] = (int(m[3]), float(m[4]))
    return found


def _pm(value, se, digits=2) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    se_text = "n.d." if se is None or not math.isfinite(se) else f"{se:.{digits}f}"
    return f"{value:+.{digits}f} +- {se_text}"


def _calibration(c: CalibrationRecord) -> list:
    """Misalignment, bed, deviation and lever-arm cells of one calibration (the typed record; the
    moving-bed test, which the record does not type, from its validated file)."""
    deg = math.degrees
    m = c.heading_misalignment_rad
    mis = "no reference" if m is None else _pm(deg(m), deg(c.heading_misalignment_se_rad))
    if m is not None and c.magnetic_declination_rad is not None:
        mis += f" [{deg(c.magnetic_declination_rad):+.2f}; {deg(c.compass_error_rad):+.2f}]"
    test = c.data.get("moving_bed_test") or {}
    bed_text = f"{test['decision']} ({test.get('percent_of_flow', math.nan):.1f} % of the flow)" if test else c.moving_bed
    if c.moving_bed_velocity_m_s is not None:
        bed_text += "; " + ", ".join(_pm(v, s, 3) for v, s in zip(c.moving_bed_velocity_m_s, c.moving_bed_velocity_se_m_s))
    dev, dev_se = c.compass_deviation_rad, c.compass_deviation_se_rad or (None, None)
    dev_text = "-" if not dev else ", ".join(_pm(deg(v), None if s is None else deg(s), 1) for v, s in zip(dev, dev_se))
    head, head_se = c.radius_vectors_head_m, c.radius_vectors_head_se_m
    if head is None or head_se is None or not np.isfinite(head_se[0]).any():
        lever = "not determined"
    else:
        lever = ", ".join(f"{a} {_pm(v, s, 3)}" for a, v, s in zip("xyz", head[0], head_se[0]))
    return [mis, bed_text, dev_text, lever]


def _comparison(cmp: dict) -> str:
    parts = []
    for method in ("asc", "adc", "rootfinder"):
        m = cmp.get(method)
        if m:
            parts.append(f"{method.upper() if method != 'rootfinder' else 'rootfinder'} {m['vector_error_rms_m_s']:.3f} m/s / "
                         f"{m['direction_error_rms_deg']:.1f} deg")
    refused = cmp.get("not_run") or {}
    if refused:
        parts.append("refused: " + ", ".join(sorted(refused)))
    return "; ".join(parts) or "-"


def table(out) -> str:
    out = Path(out)
    times = _times(out)
    lines = ["| case | calibrate (status, s) | heading misalignment (deg) [IGRF declination; compass error] | moving-bed "
             "test; bed north, east (m/s) | compass deviation B, C (deg) | lever arm, head frame (m) | against GNSS "
             "(vector / direction error) | diagnose: verdict, held-out gap (z), worst channel; s |",
             "|---|---|---|---|---|---|---|---|"]
    for folder in sorted(p for p in out.iterdir() if p.is_dir()):
        name = folder.name
        row = [name]
        calib = folder / "calib.json"
        status = {s: times.get((name, s), (None, math.nan)) for s in STEPS}
        if calib.exists():
            c = CalibrationRecord.from_json(calib)
            row.append(f"{(c.data.get('solver') or {}).get('status', '?')}, {status['calibrate'][1]:.1f}")
            row += _calibration(c)
        else:
            row += [f"exit {status['calibrate'][0]}"] + ["-"] * 4
        cmp = next(iter((folder / "cmp").glob("*_compare.json")), None) if (folder / "cmp").is_dir() else None
        row.append(_comparison(json.loads(cmp.read_text())) if cmp else f"compare exit {status['compare'][0]}")
        diag = folder / "diag.json"
        if diag.exists():
            d = json.loads(diag.read_text())
            worst = d["where"][0]["channel"] if d.get("where") else "-"
            row.append(f"{d['verdict']}, {d['gap_before']:.3f} (z = {d['gap_z_before']:.1f}), {worst}; "
                       f"{status['diagnose'][1]:.1f}")
        else:
            row.append(f"exit {status['diagnose'][0]} (one line: {_first_line(folder / 'diagnose.log')})")
        lines.append("| " + " | ".join(row) + " |")
    offsets = []
    for folder in sorted(p for p in out.iterdir() if p.is_dir() and (p / "calib.json").exists()):
        run = CalibrationRecord.from_json(folder / "calib.json").runs[0]
        if run.transducer_depth_offset_m is not None:
            offsets.append(f"{folder.name} {_pm(run.transducer_depth_offset_m, run.transducer_depth_offset_se_m, 3)} m")
    if offsets:
        lines += ["", "The transducer-depth offset the slant ranges give (`runs[].transducer_depth_offset_m`): "
                  + "; ".join(offsets) + "."]
    return "\n".join(lines)


def _first_line(log: Path) -> str:
    text = log.read_text().strip().splitlines() if log.exists() else []
    errors = [t for t in text if "error:" in t]
    return (errors[-1] if errors else (text[-1] if text else "")).replace("|", "/")[:120]


if __name__ == "__main__":
    print(table(sys.argv[1] if len(sys.argv) > 1 else "/tmp/adcpdyn-real"))
