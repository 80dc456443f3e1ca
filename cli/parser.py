"""The command line: every verb, its options and their checks (one-line errors naming the flag)."""

from __future__ import annotations

import argparse

import numpy as np

from ..solvers.nlp_methods import METHODS
from .verbs.calibration import cmd_calibrate, cmd_compare_formulations
from .verbs.cases import cmd_cache, cmd_export, cmd_import, cmd_info, cmd_scenarios, cmd_simulate
from .verbs.correction import cmd_compare, cmd_correct
from .verbs.demo import cmd_bench, cmd_demo
from .verbs.diagnosis import cmd_diagnose


DEFAULT_CASES = ("pool_m1", "pool_m2")


TIMINGS = ("deep", "shallow", "exact")  # correct --timing


FIGURE_FORMATS = ("png", "pdf", "svg")


EXIT_STATUS = """exit status:
  0    success
  1    a solve failed or did not converge (calibrate, diagnose; a batch with a case not
       converged); the output is still written and says so
  2    bad input: an unreadable or invalid file, an impossible value or option; one line on
       stderr names the field (a batch: some case failed, the others are written)
  130  interrupted (Ctrl-C: 128 + SIGINT); no partial file is left
  141  the output's reader stopped reading (a pipe into `head`: 128 + SIGPIPE); nothing said
  143  terminated (128 + SIGTERM); no partial file is left
"""


def _int_at_least(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}")
        return value
    return parse


def _angle_deg(text: str) -> float:
    value = _finite(text)
    if not -180.0 <= value <= 180.0:
        raise argparse.ArgumentTypeError(f"expected an angle in degrees within +-180, got {text!r}")
    return value


def _deviation_prior_deg(text: str) -> float:
    value = _finite(text)
    if not 0.0 < value <= np.rad2deg(0.5):
        raise argparse.ArgumentTypeError(f"expected a standard deviation in degrees within (0, 28.6], got {text!r}")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


count, seed = _int_at_least(1), _int_at_least(0)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block): ``adcpdyn VERB: error: ...``."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see `{self.prog} --help`)\n")


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Each option's default in its help (when it has one), epilogs kept as written."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("%(default)" not in text and action.option_strings and action.default not in (None, False, argparse.SUPPRESS)
                and not action.required):
            text += " (default: %(default)s)"
        return text


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__
    from ..api import CORRECTION_METHODS, REFERENCES

    p = _Parser(prog="adcpdyn", description=__doc__, epilog=EXIT_STATUS, formatter_class=_HelpFormatter)
    p.add_argument("--version", action="version", version=f"adcpdyn {__version__}")
    sub = p.add_subparsers(dest="command", required=True, title="commands", metavar="command")

    def command(name, help, func):
        s = sub.add_parser(name, help=help, description=help[0].upper() + help[1:] + ".", epilog=EXIT_STATUS,
                           formatter_class=_HelpFormatter)
        s.set_defaults(func=func)
        return s

    def figure_format(s):
        s.add_argument("--format", default="png", choices=FIGURE_FORMATS, help="file format of the figures")

    def accept_other_instrument_option(s):
        s.add_argument("--accept-other-instrument", action="store_true",
                       help="apply a calibration whose CALIB.json names another instrument (refused by default)")

    def attribution_option(s):
        s.add_argument("--attribution", metavar="ORG.toml",
                       help="netCDF: who made and distributes the data (creator_*, publisher_*, institution, license, "
                            "naming_authority, infoUrl, ...: ACDD-1.3/IOOS-1.2 attribute names; "
                            "docs/examples/attribution.toml); default: the file named by the environment variable "
                            "ADCPDYN_ATTRIBUTION, when set, else 'not stated'. The file is named in the export with "
                            "its SHA-256")

    command("scenarios", "list the built-in scenarios", cmd_scenarios)

    s = command("cache", "where the compiled per-ping models are kept, how many, and how to empty it", cmd_cache)
    s.add_argument("--clear", action="store_true", help="delete them (they are built again when needed)")
    s.add_argument("--list", type=seed, default=10, metavar="N", help="name the N newest")

    s = command("simulate", "simulate a scenario into a case file (a survey's transects with --runs)", cmd_simulate)
    s.add_argument("scenario", help="a built-in scenario (`adcpdyn scenarios`)")
    s.add_argument("--seed", type=seed, default=0, help="noise seed")
    s.add_argument("--out", required=True, help="CASE.h5; with --runs a folder (NAME_run01.h5, ...)")
    s.add_argument("--runs", type=count,
                   help="a survey's number of transects (alternating banks; seeds SEED, SEED+1, ...)")
    s.add_argument("--compass-deg", type=_finite, nargs=3, metavar=("A", "B", "C"),
                   help="survey: fix the compass deviation (heading reads psi + A + B sin psi + C cos psi); default drawn")
    s.add_argument("--bed-speed", type=_finite, help="survey: fix the moving bed's speed downstream, m/s; default drawn")
    s.add_argument("--bed-profile", choices=["uniform", "parabolic"], help="survey: bed speed across the section")

    s = command("import", "import a TRDI PD0 or Nortek AD2CP file into a case file", cmd_import)
    s.add_argument("file", help="instrument file (.PD0, .000, .ENS, .ENR, .ad2cp, ...)")
    s.add_argument("--out", required=True, help="CASE.h5 (never the input file)")
    s.add_argument("--start", type=_finite, help="first ping to keep, seconds from the file's first ping")
    s.add_argument("--end", type=_finite, help="last ping to keep, seconds from the file's first ping")
    s.add_argument("--salinity-psu", type=_finite, help="the water's salinity (ppt) where the instrument's setting was "
                   "wrong: its sound speed recomputed from the recorded temperature, every radial and range rescaled")
    s.add_argument("--every", type=count, default=1, help="keep every n-th ping (decimation for long files)")

    s = command("info", "summarise a case file", cmd_info)
    s.add_argument("case", help="CASE.h5")

    def batch_options(s):
        s.add_argument("--scheduler", default="auto",
                       help="many cases: auto (in this process for 1-2 cases, else a Dask LocalCluster), local (a "
                            "LocalCluster), none (one after another here) or a scheduler address tcp://HOST:PORT; "
                            "calibrate of one case or --joint: where its starts are solved (auto: here)")
        s.add_argument("--workers", type=count, default=None, help="many cases: LocalCluster worker processes "
                       "(default: one per CPU, at most one per case); one calibration: threads here, or "
                       "LocalCluster processes with --scheduler local")

    s = command("correct", "correct every ping of a case (or of many: files, a folder or a glob)", cmd_correct)
    s.add_argument("case", nargs="+", help="case file(s), folder(s) or glob pattern(s)")
    batch_options(s)
    s.add_argument("--method", default="asc", choices=CORRECTION_METHODS,
                   help="asc: static (installation angles or heading misalignment); adc, paper_literal, rootfinder: "
                        "dynamic, with the calibration's lever arms; oracle: a simulated case's truth")
    s.add_argument("--timing", default="deep", choices=TIMINGS,
                   help="travel-time model of the dynamic methods: deep (Eqs. 66-70), shallow, or exact (rootfinder, "
                        "oracle: travel time with the moving transducer)")
    s.add_argument("--calibration", help="CALIB.json from `adcpdyn calibrate`")
    accept_other_instrument_option(s)
    s.add_argument("--reference", default="bt", choices=REFERENCES,
                   help="water velocities referenced to the bottom track (bt) or to the GNSS velocity (gnss)")
    s.add_argument("--out", required=True, help="output file (OUT.h5, or OUT.nc for CF netCDF); with many cases, a folder")
    attribution_option(s)

    s = command("export", "a case or a corrected file as CF-1.8 / ACDD-1.3 / IOOS-1.2 netCDF (ENU, UTC time, "
                          "xarray-ready)", cmd_export)
    s.add_argument("input", help="CASE.h5 or the output of `adcpdyn correct` (OUT.h5)")
    s.add_argument("--case", help="a corrected file's case (default: the case it names)")
    s.add_argument("--out", required=True, help="OUT.nc")
    attribution_option(s)

    s = command("compare", "every correction method on one case: metrics table and figures", cmd_compare)
    s.add_argument("case", help="CASE.h5 (with /truth, or a GNSS reference)")
    s.add_argument("--calibration", help="CALIB.json from `adcpdyn calibrate` (without one: asc and oracle only)")
    accept_other_instrument_option(s)
    s.add_argument("--out", help="folder for the table (JSON) and figure")
    figure_format(s)

    def calibration_options(s):
        s.add_argument("--formulation", default="exact", choices=["paper", "exact", "minimal", "free"],
                       help="lever-arm constraints: paper (Janus conditions relaxed), exact (equalities), minimal "
                            "(r_i = Lambda T_i + P), free (twelve coordinates)")
        s.add_argument("--starts", type=count, default=24, help="multistart size")
        s.add_argument("--screen-pings", type=int, default=2000, metavar="N",
                       help="runs of twice N pings or more (without a velocity per ping): every start solved on every "
                            "k-th ping, about N in all, the best of them then on all pings; 0: every start on all pings")
        s.add_argument("--seed", type=seed, default=0, help="seed of the start design")
        s.add_argument("--method", default="joint", choices=["joint", "two-stage"],
                       help="joint (one NLP) or two-stage (the paper's)")
        s.add_argument("--timing", default="auto", choices=["auto", "shallow", "deep", "exact"],
                       help="bottom-track model (auto: by the round-trip time)")
        s.add_argument("--tangential", default="consistent", choices=["consistent", "paper_literal"],
                       help="tangential velocity dLambda/dt r (consistent) or the printed Omega r")
        s.add_argument("--attitude", default="auto", choices=["auto", "model", "samples"],
                       help="the beams' attitude: model (damped-mode model fitted jointly), samples (the sensor's "
                            "samples, for runs no motion model follows) or auto")
        s.add_argument("--jacobian", default="auto", choices=["auto", "symbolic", "assembled"],
                       help="symbolic (whole problem differentiated by CasADi) or assembled (per row, long runs)")
        s.add_argument("--compile", default="auto", choices=["auto", "always", "never"],
                       help="the assembled problem's per-ping model as machine code from the per-machine cache "
                            "(`adcpdyn cache`; built by the C compiler the first time, same numbers): auto when the runs "
                            "hold 500 pings or more together (the Jacobian then assembled) or their Jacobian is assembled anyway "
                            "(a large expanded graph), always "
                            "(with --jacobian assembled) or never")
        s.add_argument("--navigation", default="knots", choices=["knots", "random_walk", "auto"],
                       help="the vessel's velocity: knots (piecewise-linear), random_walk (a velocity at every ping, "
                            "its random-walk intensity and the noise levels from the data) or auto (random_walk for "
                            "a run under way whose beams take the sensor's samples, as a real file's do, or whose motion "
                            "model follows the attitude only beyond the sensors' noise)")
        s.add_argument("--moving-bed", default="auto", choices=["auto", "off", "constant", "section"],
                       help="bed moving under the bottom track: auto (with a moving reference a constant bed, kept only "
                            "when a test says it moves), off (a bed verified fixed), constant, or section (a function "
                            "of the position along the section)")
        s.add_argument("--bed-knots", type=_int_at_least(2), default=None,
                       help="--moving-bed section: values across the section (default 3)")
        s.add_argument("--compass-deviation", default="auto", choices=["auto", "on", "off"],
                       help="head sensor: add B sin(heading) + C cos(heading) to the misalignment (auto: with a prior, "
                            "when the headings span enough)")
        s.add_argument("--compass-deviation-prior-deg", type=_deviation_prior_deg, default=None,
                       help="--compass-deviation auto: the one-cycle deviation left after the compass's own calibration, "
                            "one standard deviation of B and of C in degrees (default 1: the prior N(0, 1 deg^2) each)")
        s.add_argument("--own-effects", default="auto", choices=["auto", "on", "off"],
                       help="auto: one run whose beams take the sensor's samples (a real file) is diagnosed on top of "
                            "the calibration and what it shows of its own is kept in CALIB.json, held when it is "
                            "diagnosed again (which then answers what changed since); on: a --joint survey's runs too "
                            "(one joint diagnosis); off: not diagnosed")
        s.add_argument("--standard-errors", default="hac", choices=["hac", "white"],
                       help="hac (Newey-West sandwich, coloured residuals) or white")
        s.add_argument("--declination-deg", type=_angle_deg,
                       help="magnetic declination at the site (east positive), when the cases carry no position and date")
        s.add_argument("--solver", default="ipopt", choices=list(METHODS),
                       help="NLP solver of the multistart (ipopt; CasADi's SQP, interior-point and augmented-Lagrangian "
                            "plugins; scipy least_squares on the residuals): `adcpdyn bench solvers` compares them")

    s = command("calibrate", "estimate attitude model, lever arms and installation angles (one or many cases)",
                cmd_calibrate)
    s.add_argument("case", nargs="+", help="case file(s), folder(s) or glob pattern(s)")
    calibration_options(s)
    batch_options(s)
    s.add_argument("--joint", action="store_true",
                   help="several runs of one boat at one site in ONE NLP (shared lever arms, installation or heading "
                        "misalignment, moving bed); --out is then one CALIB.json")
    s.add_argument("--out", required=True, help="CALIB.json; with many cases (not --joint), a folder (CASE.json each, summary.json)")

    s = command("compare-formulations", "calibrate with every constraint formulation and tabulate",
                cmd_compare_formulations)
    s.add_argument("case", help="CASE.h5")
    calibration_options(s)
    s.add_argument("--out", help="optional JSON of the table")

    s = command("diagnose", "where the sim-to-real gap lies, which unmodelled effect causes it, how far it shrinks",
                cmd_diagnose)
    s.add_argument("case", nargs="*", help="CASE.h5 (omit with --selftest); with --joint several runs, folders or globs")
    s.add_argument("--joint", action="store_true",
                   help="several runs of one boat together: shared effects (compass, beams, sound speed, latency, lever "
                        "arms) and per-run ones (moving bed, heave, forced roll); whole runs held out too")
    s.add_argument("--calibration", help="CALIB.json from `adcpdyn calibrate` (its platform quantities pinned in the base)")
    accept_other_instrument_option(s)
    s.add_argument("--out", help="DIAG.json (DIAG.md and a figure are written beside it)")
    s.add_argument("--effects", nargs="+", metavar="EFFECT", help="catalog effects to try (default: all)")
    s.add_argument("--attitude", default="auto", choices=["auto", "model", "samples"],
                   help="the beams' attitude: model (damped-mode motion model), samples (the sensor's samples, runs no "
                        "model follows) or auto")
    s.add_argument("--given", nargs="+", default=(), metavar="EFFECT",
                   help="effects the run is known to carry (e.g. what its clean run named): fitted first and kept, "
                        "the candidates judged on top of them")
    s.add_argument("--ignore-own-effects", action="store_true",
                   help="the calibration's own runs: do not hold what they showed when calibrated (CALIB.json "
                        "own_effects), diagnose them afresh")
    s.add_argument("--navigation", default="auto", choices=["auto", "random_walk", "knots"],
                   help="the base's vessel velocity: random_walk (a velocity at every ping, its random-walk intensity "
                        "from the data: a real boat's speed changes between fixes are motion), knots (a smooth curve) "
                        "or auto: random_walk where the beams take the attitude sensor's samples (every real file) or a motion "
                        "model follows the attitude only beyond the sensors' noise, knots where it follows to their noise or "
                        "the reference is stationary")
    s.add_argument("--field-selftest", action="store_true",
                   help="what this file can detect: the field's errors (compass offset, attitude and reference latency, "
                        "moving bed, sound speed, tilt low-pass, heave) injected at typical sizes into its recorded "
                        "channels, each diagnosed blind with its calibration (--calibration, else calibrated on itself); "
                        "with --effects only the errors those can name; with --joint a survey's runs, each error in "
                        "every run, diagnosed jointly")
    s.add_argument("--selftest", type=count, metavar="N", help="blind self-test on N simulated cases")
    s.add_argument("--seed", type=seed, default=0, help="seed of the self-test draws")
    s.add_argument("--selftest-calibrated", action="store_true",
                   help="self-test in the paper's workflow: each platform calibrated on an effect-free run of its own, "
                        "each case diagnosed with that calibration")
    s.add_argument("--platforms", nargs="+", choices=["launch_vessel", "launch_head", "pool", "survey_ship", "river"],
                   help="self-test platforms to draw from (default: all)")
    figure_format(s)

    s = command("bench", "benchmarks with their targets", cmd_bench)
    s.add_argument("suite", choices=["calibration", "correction", "formulations", "solvers", "scale", "survey", "surveyday", "diagnosis",
                                     "diagnosis-survey", "compliance", "navigation"],
                   help="which benchmark")
    s.add_argument("--quick", action="store_true", help="fewer seeds")
    s.add_argument("--out", default="benchmarks/results", help="folder of the results")
    s.add_argument("--readme", metavar="FILE", help="solvers suite: put its tables between FILE's solver-table markers "
                                                    "(docs/benchmarks.md)")

    s = command("demo", "the main job on the built-in default case", cmd_demo)
    s.add_argument("--scenario", nargs="+", default=list(DEFAULT_CASES), help="measurement runs to correct")
    s.add_argument("--calibration-scenario", default="pool_m0", help="calibration run")
    s.add_argument("--starts", type=count, default=24, help="multistart size")
    s.add_argument("--seed", type=seed, default=1, help="noise seed")
    s.add_argument("--out", default="demo_out", help="output folder")
    figure_format(s)
    return p
