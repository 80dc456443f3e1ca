"""``adcpdyn bench compliance``: the IOOS compliance-checker's scores (cf:1.8, acdd:1.3, ioos:1.2) of
netCDF exports, simulated and real, each a case and its static correction, without and with an
attribution file (docs/examples/attribution.toml: who made and distributes the data).

Scores are the checker's own (``compliance-checker --test=...``, normal criteria: high and
medium checks): points scored over points possible, per suite. The exports:

- ``sim deep_ship``: a simulated run without a site: no UTC dates, no positions (no CF
  discrete-sampling geometry, no time or position extents to give);
- ``sim river_survey``: a simulated transect with a site: UTC dates and GNSS positions;
- ``real RiverPro_test01``: the real RiverPro file (``ADCPDYN_REAL_DATA``, default
  ../shared/data/real); listed as missing when absent.

Needs the ``compliance-checker`` package (the ``test`` extra).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .common import Target, machine, print_targets, real_dir, save_figure

SUITES = ("cf:1.8", "acdd:1.3", "ioos:1.2")
TARGET_PERCENT = 95.0
CRITERIA_LIMIT = 2  # the checker's "normal" criteria: high and medium checks count
REAL_FILE = "RiverPro_test01.PD0"
EXAMPLE_ATTRIBUTION = Path(__file__).resolve().parents[1] / "docs" / "examples" / "attribution.toml"


class Score(NamedTuple):
    """One suite's result: points scored and possible, and the high-priority checks failed."""

    scored: int
    possible: int
    high_failed: int

    @property
    def percent(self) -> float:
        return 100.0 * self.scored / self.possible


def checker_scores(path, suites=SUITES) -> dict:
    """``{suite: Score}`` of one netCDF file by the IOOS compliance-checker (normal criteria).

    Raises
    ------
    RuntimeError
        The checker could not run a suite on the file (its errors listed).
    """
    import contextlib
    import io
    import warnings

    from compliance_checker.runner import CheckSuite

    # the checker's notes on the standard-name table it uses (stdout) and on its own deprecations
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        cs = CheckSuite()
        cs.load_all_available_checkers()
        ds = cs.load_dataset(str(path))
        results = cs.run_all(ds, list(suites), skip_checks=[])
    out = {}
    for suite, (groups, errors) in results.items():
        if errors:
            raise RuntimeError(f"{path}: compliance-checker {suite}: {errors}")
        agg = cs.build_structure(suite, groups, str(path), CRITERIA_LIMIT)
        out[suite] = Score(int(agg["scored_points"]), int(agg["possible_points"]), int(agg["high_count"]))
    return out


def _cases(folder: Path) -> tuple[list, list]:
    """(label, case file) of the exported cases, and the real files missing."""
    from .. import api

    out, missing = [], []
    for label, scenario in (("sim deep_ship", "deep_ship"), ("sim river_survey", "river_survey")):
        path = folder / f"{scenario}.h5"
        api.simulate(scenario, seed=1, out=path)
        out.append((label, path))
    real = real_dir() / REAL_FILE
    if real.is_file():
        path = folder / f"{real.stem}.h5"
        api.import_file(real, out=path)
        out.append((f"real {real.stem}", path))
    else:
        missing.append(str(real))
    return out, missing


def bench_compliance(quick: bool = True) -> dict:
    """Every export (case and static correction, without and with the example attribution) scored
    (``quick`` changes nothing: the whole suite takes about 20 s). A default attribution named by
    ``ADCPDYN_ATTRIBUTION`` is set aside for the run: plain exports have none."""
    import os

    from ..cases.attribution import ENVIRONMENT

    default = os.environ.pop(ENVIRONMENT, None)
    try:
        return _bench(quick)
    finally:
        if default is not None:
            os.environ[ENVIRONMENT] = default


def _bench(quick: bool) -> dict:
    from .. import api

    rows = []
    with tempfile.TemporaryDirectory(prefix="adcpdyn-compliance-") as tmp:
        folder = Path(tmp)
        cases, missing = _cases(folder)
        for label, path in cases:
            for attribution in (None, EXAMPLE_ATTRIBUTION):
                tag = "attributed" if attribution else "plain"
                for kind in ("case", "corrected"):
                    out = folder / f"{path.stem}_{kind}_{tag}.nc"
                    tic = time.perf_counter()
                    if kind == "case":
                        api.export(path, out, attribution=attribution, history="adcpdyn bench compliance")
                    else:
                        api.correct(path, "asc", out=out, attribution=attribution, history="adcpdyn bench compliance")
                    export_s = time.perf_counter() - tic
                    scores = checker_scores(out)
                    rows.append({"export": label, "kind": kind, "attribution": tag, "export_s": export_s,
                                 **{s: {**v._asdict(), "percent": v.percent} for s, v in scores.items()}})
                    print(f"{label:>22s} {kind:>9s} {tag:>10s}  " + "  ".join(
                        f"{s} {v.scored}/{v.possible} {v.percent:5.1f} %" for s, v in scores.items()), flush=True)
    from compliance_checker import __version__ as cc_version

    return {"suite": "compliance", "machine": machine(), "compliance_checker": cc_version, "rows": rows,
            "missing": missing}


def print_compliance(res: dict) -> None:
    print(f"\nIOOS compliance-checker {res['compliance_checker']} (normal criteria), percent of points; "
          "'attributed': with docs/examples/attribution.toml")
    print(f"{'export':>22s} {'kind':>9s} {'attribution':>11s} " + " ".join(f"{s:>9s}" for s in SUITES))
    for r in res["rows"]:
        print(f"{r['export']:>22s} {r['kind']:>9s} {r['attribution']:>11s} "
              + " ".join(f"{r[s]['percent']:9.1f}" for s in SUITES))
    for m in res["missing"]:
        print(f"  missing: {m}")
    dated = [r for r in res["rows"] if r["attribution"] == "attributed" and r["export"] != "sim deep_ship"]
    worst = min((r[s]["percent"] for r in dated for s in SUITES), default=float("nan"))
    cf = min((r["cf:1.8"]["percent"] for r in res["rows"]), default=float("nan"))
    print_targets(res, [
        Target(f"cf:1.8 on every export >= {TARGET_PERCENT:g} % (lowest, %)", cf, cf >= TARGET_PERCENT),
        Target(f"all three suites >= {TARGET_PERCENT:g} % on the attributed exports with dates and positions "
               "(lowest, %)", worst, worst >= TARGET_PERCENT),
    ])


EXPORT_LABELS = {"real RiverPro_test01": "real RiverPro_test01",
                 "sim river_survey": "simulated river_survey (dates, positions)",
                 "sim deep_ship": "simulated deep_ship (no dates, no positions)"}


def markdown_table(res: dict) -> str:
    """docs/netcdf.md's table: percent of points, cf:1.8 / acdd:1.3 / ioos:1.2, without and with the example
    attribution, one row per export and kind (real first, corrected before case)."""
    def cell(r):
        return " / ".join(f"{r[s]['percent']:.1f}".replace("100.0", "100") for s in SUITES)

    rows = {(r["export"], r["kind"], r["attribution"]): r for r in res["rows"]}
    lines = ["| export | no attribution | `--attribution docs/examples/attribution.toml` |", "| --- | --- | --- |"]
    for export, label in EXPORT_LABELS.items():
        for kind in ("corrected", "case"):
            if (export, kind, "plain") in rows:
                lines.append(f"| {label}, {'corrected (asc)' if kind == 'corrected' else 'case'} | "
                             f"{cell(rows[export, kind, 'plain'])} | {cell(rows[export, kind, 'attributed'])} |")
    return "\n".join(lines)


def figure_compliance(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["rows"]
    labels = [f"{r['export']}, {r['kind']}, {r['attribution']}" for r in rows]
    fig, ax = plt.subplots(figsize=(9, 0.55 * len(rows) + 1.5))
    y = np.arange(len(rows))[::-1]
    for k, suite in enumerate(SUITES):
        ax.barh(y + 0.27 * (1 - k), [r[suite]["percent"] for r in rows], height=0.27, label=suite)
    ax.axvline(TARGET_PERCENT, color="k", lw=0.8, ls="--", label=f"target {TARGET_PERCENT:g} %")
    ax.set_yticks(y, labels, fontsize=9)
    ax.set_xlabel("compliance-checker score (% of points, normal criteria)")
    ax.set_xlim(50, 100)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.07 * 14 / (len(rows) + 2)), ncol=4)
    ax.set_title("netCDF exports scored by the IOOS compliance-checker\n"
                 "(attributed: with docs/examples/attribution.toml)", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
