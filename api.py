"""The Python API: read or import a case, simulate, calibrate, correct, compare, diagnose, export.

Every function here is exported at the package top (``import adcpdyn``) and does what the
command of the same name does (``adcpdyn --help``), with the same checks and the same
numbers: the command line calls these functions. A case can be given as a case file path,
a :class:`~adcpdyn.cases.case.Case` or an :class:`ImportedCase`; a calibration as a
CALIB.json path, a :class:`~adcpdyn.estimators.calibration.result.CalibrationResult`, a
:class:`~adcpdyn.estimators.calibration.record.CalibrationRecord` or a parsed dict.

Verbs that use the attitude (``calibrate``, ``correct``, ``compare``, ``diagnose``) first
restrict a case to what its attitude record covers, as the command line does
(:func:`~adcpdyn.cases.coverage.restrict_to_coverage`), and keep what that left out, with
the case's plausibility warnings, in their result.

Heavy modules (CasADi, xarray, the dolfyn reader) are imported when a function needs them.
See ``docs/api.md`` for a worked example.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:  # pragma: no cover - names for annotations only
    import xarray

    from .cases.case import Case
    from .estimators.asc import Correction
    from .estimators.calibration.config import CalibrationConfig
    from .estimators.calibration.record import CalibrationRecord
    from .estimators.calibration.result import CalibrationResult
    from .estimators.diagnosis.diagnose import DiagnosisResult

__all__ = ["ImportedCase", "Comparison", "read_case", "import_file", "simulate", "read_calibration", "calibrate", "field_selftest",
           "correct", "compare", "diagnose", "to_xarray", "export", "CORRECTION_METHODS", "TIMINGS", "REFERENCES",
           "FIGURE_FORMATS"]

CORRECTION_METHODS = ("asc", "adc", "paper_literal", "rootfinder", "oracle")
TIMINGS = ("deep", "shallow", "exact")  # travel-time model of the dynamic corrections
REFERENCES = ("bt", "gnss")  # water velocities referenced to the bottom track or to the GNSS
FIGURE_FORMATS = ("png", "pdf", "svg")


# ----------------------------------------------------------------------------------------------- types
@dataclass(frozen=True, eq=False)
class ImportedCase:
    """A case imported from an instrument file, with the importer's audit trail.

    Attributes
    ----------
    case : Case
        The case (SI units, NED Earth frame, case beam order).
    audit : dict
        HDF5 group -> attributes of every conversion the importer made (``/provenance``:
        instrument file, its SHA-256, reader, coordinate system found, GNSS clock offset ...).
    path : pathlib.Path or None
        The case file it was written to (``import_file(..., out=)`` or :meth:`write`), else None.
    """

    case: "Case"
    audit: dict
    path: Path | None = None

    @property
    def provenance(self) -> dict:
        """The importer's ``/provenance`` attributes."""
        return dict(self.audit.get("/provenance", {}))

    def write(self, out) -> "ImportedCase":
        """Write the case file with its audit attributes (atomically); return the record with ``path`` set.

        Raises
        ------
        ValueError
            ``out`` is the instrument file itself, or its folder does not exist.
        """
        from .cases.atomic import check_output_file
        from .cases.importers import write_imported

        source = self.provenance.get("source_file")
        check_output_file(out, source, option="out")
        write_imported(self.case, self.audit, out, source=source)
        return dataclasses.replace(self, path=Path(out))


@dataclass(eq=False)
class Comparison:
    """Every correction method on one case against its truth or its measured reference.

    Attributes
    ----------
    case : str
        The case's name.
    against : str
        ``truth`` (a simulated case's /truth) or ``reference`` (the measured reference velocity:
        the GNSS, or the vessel known at rest).
    table : dict
        Method (and ``against``) -> the paper's metrics (:func:`~adcpdyn.estimators.statistics.metrics.velocity_metrics`).
    corrections : dict
        Method -> :class:`~adcpdyn.estimators.asc.Correction`.
    not_run : dict
        Method -> why this calibration could not drive it.
    warnings : list of str
        What the coverage step left out and the case's plausibility warnings.
    files : list of pathlib.Path
        The table (JSON) and the figure, when ``out`` was given.
    """

    case: str
    against: str
    table: dict
    corrections: dict
    not_run: dict
    warnings: list = field(default_factory=list)
    files: list = field(default_factory=list)

    @property
    def against_text(self) -> str:
        """What the methods were compared against, in words."""
        return "simulated truth" if self.against == "truth" else "the measured reference (GNSS)"

    def format_table(self) -> str:
        """The metrics table as text (what ``adcpdyn compare`` prints)."""
        from .estimators.statistics.metrics import format_table

        return format_table(self.table)


@dataclass(frozen=True, eq=False)
class _Source:
    """A case with where it came from: its file (None in memory) and the importer's /provenance."""

    case: "Case"
    path: str | None
    provenance: dict


# ----------------------------------------------------------------------------------------------- helpers
def _choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name}: expected one of {list(allowed)}, got {value!r}")


def _source(case, what: str = "case") -> _Source:
    from .cases.case import Case

    if isinstance(case, _Source):
        return case
    if isinstance(case, ImportedCase):
        return _Source(case.case, None if case.path is None else str(case.path), case.provenance)
    if isinstance(case, Case):
        return _Source(case, None, {})
    if isinstance(case, (str, os.PathLike)):
        from .cases.io import read_case as _read
        from .cases.netcdf import read_provenance

        c = _read(case)
        return _Source(c, str(case), read_provenance(case))
    raise ValueError(f"{what}: expected a case file path, a Case or an ImportedCase, got {type(case).__name__}")


def _prepared(src: _Source) -> tuple[_Source, list]:
    """The case restricted to what its attitude record covers, and the notes (warnings, what was left out)."""
    from .cases.coverage import restrict_to_coverage
    from .cases.validation import case_warnings

    notes = case_warnings(src.case)
    case, note = restrict_to_coverage(src.case, source=src.path or src.case.name)
    if note:
        notes.append(note)
    return dataclasses.replace(src, case=case), notes


def _case_record(src: _Source) -> dict:
    """Provenance of one input case: name, file and SHA-256, and the instrument file it was imported from."""
    from .cases.hashing import sha256_of

    out = {"name": src.case.name, "path": src.path,
           "sha256": sha256_of(src.path) if src.path and Path(src.path).is_file() else None}
    if "source_file" in src.provenance:
        out["source_file"] = str(src.provenance["source_file"])
        out["source_file_sha256"] = src.provenance.get("source_file_sha256")
    return out


def _many(cases) -> bool:
    return isinstance(cases, (list, tuple))


def _keyed(sources: list) -> list:
    """Runs of one scenario share a name: key them by file name (as a joint calibration's ``runs`` are)."""
    if len({s.case.name for s in sources}) == len(sources):
        return sources
    return [dataclasses.replace(s, case=s.case.replace(name=Path(s.path).stem)) if s.path else s for s in sources]


def _calibrated_runs(sources: list, calibration: "CalibrationRecord | None", accept_other_instrument: bool) -> tuple:
    """The cases of ``sources`` (already :func:`_keyed`) as the calibration's runs (checked to be its
    instrument's, named as it keys its runs: :func:`~adcpdyn.estimators.calibration.identity.as_calibrated_run`),
    and the notes on applying it."""
    from .estimators.calibration.identity import as_calibrated_run

    runs, notes = [], []
    for s in sources:
        run, applied = as_calibrated_run(s.case, s.path or s.case.name, calibration, accept_other_instrument)
        runs.append(run)
        notes += applied
    return runs, notes


def _calibration_provenance(record, given: str) -> dict:
    """What a correction records of the calibration it was given (a ``given`` object read into
    ``record``): the file it was read from with its SHA-256 then, or that it was in memory."""
    if record is None:
        return {"calibration_file": "none"}
    if record.source_sha256 is not None:
        return {"calibration_file": record.source, "calibration_sha256": record.source_sha256}
    return {"calibration_file": f"none (a {given} in memory, not a file)"}


# ----------------------------------------------------------------------------------------------- read, import, simulate
def read_case(path) -> "Case":
    """Read and validate a case file (the HDF5 of ``adcpdyn simulate`` or ``adcpdyn import``).

    Parameters
    ----------
    path : str or os.PathLike
        The case file.

    Returns
    -------
    Case
        As stored: not restricted to the attitude record's coverage (the verbs do that).

    Raises
    ------
    ValueError
        One line naming the file and the field (``CaseFormatError``), or a missing file.
    """
    from .cases.io import read_case as _read

    return _read(path)


def import_file(source, out=None, *, name: str | None = None, start_s: float | None = None,
                end_s: float | None = None, every: int = 1, salinity_psu: float | None = None) -> ImportedCase:
    """Import a TRDI PD0 file (or a dolfyn Dataset read from one) into a case.

    Parameters
    ----------
    source : str, os.PathLike or xarray.Dataset
        An instrument file (``.PD0``, ``.000``, ``.ENS``, ``.ENR``, ...; Nortek AD2CP files are
        refused with the reason), or the :class:`xarray.Dataset` that ``mhkit.dolfyn.read``
        returned for a TRDI file. A Dataset carries less than the file: its GNSS comes only from
        dolfyn's own fields (float32 positions unless read as adcpdyn reads them; NMEA text in
        the file is not seen), dolfyn's merged cell sizes are unknown, and no SHA-256 of the
        instrument file is recorded (the provenance says so).
    out : str or os.PathLike, optional
        Also write the case file here (atomically, never over the instrument file).
    name : str, optional
        The case's name (default: the file's stem; ``dataset`` for a Dataset without a file name).
    start_s, end_s : float, optional
        Keep pings in this window, seconds from the file's first ping.
    every : int
        Keep every n-th ping (decimation of long files), >= 1.
    salinity_psu : float, optional
        The water's salinity where the instrument's setting was wrong (0 ppt entered at sea):
        its sound speed recomputed from the recorded temperature, every radial and range rescaled
        (:func:`adcpdyn.cases.sound_speed.with_salinity`; the change in ``/provenance``).

    Returns
    -------
    ImportedCase
        The case and the importer's audit trail (``path`` set when ``out`` was given).

    Raises
    ------
    ValueError
        One line (``ImportFailure``) naming what the file lacks or why it cannot be read.
    """
    from .cases.importers import Window
    from .cases.importers import import_file as _import

    if not isinstance(every, int) or isinstance(every, bool) or every < 1:
        raise ValueError(f"every: expected an integer >= 1, got {every!r}")
    window = Window(start_s=start_s, end_s=end_s, every=every)
    if isinstance(source, (str, os.PathLike)):
        case, audit = _import(Path(source), window)
        if name:
            case = case.replace(name=str(name))
    else:
        from .cases.importers import import_dataset

        case, audit = import_dataset(source, window, name=name)
    if salinity_psu is not None:
        from .cases.importers import resalted

        case, audit = resalted(case, audit, salinity_psu)
    imported = ImportedCase(case, audit)
    return imported if out is None else imported.write(out)


def simulate(scenario, seed: int = 0, *, runs: int | None = None, out=None):
    """Simulate a built-in (or given) scenario into a case with its ``/truth``.

    Parameters
    ----------
    scenario : str or Scenario
        A scenario name (``adcpdyn scenarios``) or a :class:`~adcpdyn.cases.scenario.Scenario`.
    seed : int
        Noise seed (>= 0).
    runs : int, optional
        A survey's number of transects (survey scenarios only, e.g. ``river_survey``).
    out : str or os.PathLike, optional
        Write the case file here; with ``runs``, a folder receiving ``NAME_run01.h5`` ...

    Returns
    -------
    Case, or list of Case with ``runs``
    """
    from .cases.io import write_case
    from .cases.scenario import Scenario, get_scenario
    from .cases.simulation import simulate as _simulate

    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed!r}")
    if runs is not None:
        from .cases.survey import simulate_survey

        if not isinstance(scenario, str):
            raise ValueError("scenario: a survey (runs=) is simulated by name")
        cases = simulate_survey(scenario, runs, seed)
        if out is not None:
            Path(out).mkdir(exist_ok=True)
            for c in cases:
                write_case(c, Path(out) / f"{c.name}.h5")
        return cases
    sc = scenario if isinstance(scenario, Scenario) else get_scenario(scenario)
    case = _simulate(sc, seed=seed)
    if out is not None:
        write_case(case, out)
    return case


def read_calibration(path) -> "CalibrationRecord":
    """Read, validate and type a CALIB.json (same as ``CalibrationResult.from_json``).

    Returns
    -------
    CalibrationRecord
        Typed fields: lever arms, installation angles, heading misalignment, compass
        deviation, declination, moving bed (site and per run), attitude model and source,
        noise levels, runs, provenance.

    Raises
    ------
    ValueError
        One line naming the file and the key.
    """
    from .estimators.calibration.record import CalibrationRecord

    return CalibrationRecord.from_json(path)


# ----------------------------------------------------------------------------------------------- calibrate
def calibrate(cases, config: "CalibrationConfig | None" = None, *, progress: Callable[[str], None] | None = None,
              **options) -> "CalibrationResult":
    """Calibrate one run, or several runs of one boat at one site in one NLP.

    Parameters
    ----------
    cases : case or list of cases
        A case file path, Case or ImportedCase; a list of several calibrates them jointly
        (shared lever arms, installation or heading misalignment, compass deviation, moving
        bed; per run its attitude and navigation: ``calibrate_runs``). Runs sharing a case
        name are keyed by their file names.
    config : CalibrationConfig, optional
        The options (default ``CalibrationConfig()``: 24 starts, ``exact`` formulation ...).
    progress : callable, optional
        Called with a one-line text when the attitude pre-fit starts and when the solve starts.
    **options
        ``CalibrationConfig`` fields replacing those of ``config`` (e.g. ``n_starts=2``,
        ``moving_bed="off"``).

    Returns
    -------
    CalibrationResult
        ``success``, estimates with standard errors, ``warnings`` (the cases' own first);
        ``provenance`` names the cases and their SHA-256; ``to_json(path)`` writes CALIB.json.

    Raises
    ------
    ValueError
        An unknown option, a bad case, or a problem the calibration refuses (one line).
    """
    from .estimators.calibration.config import CalibrationConfig
    from .estimators.calibration.problem import CalibrationProblem

    config = config or CalibrationConfig()
    known = {f.name for f in dataclasses.fields(CalibrationConfig)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"options: unknown calibration option {unknown[0]!r}; expected CalibrationConfig fields: "
                         f"{', '.join(sorted(known))}")
    if options:
        config = dataclasses.replace(config, **options)
    many = _many(cases) and len(cases) > 1
    items = list(cases) if _many(cases) else [cases]
    if not items:
        raise ValueError("cases: expected at least one case")
    prepared = [_prepared(_source(c, "cases")) for c in items]
    sources = _keyed([s for s, _ in prepared])
    notes = [n for _, ns in prepared for n in ns]
    say = progress or (lambda text: None)
    say(f"attitude pre-fit and building the NLP of {len(sources)} run(s) ({', '.join(s.case.name for s in sources)})")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # every warning is written into the result
        problem = CalibrationProblem([s.case for s in sources] if many else sources[0].case, config)
        say(f"solving: {config.n_starts} start(s), {len(problem.names)} unknowns")
        result = problem.solve()
    result.warnings = notes + list(result.warnings)  # the cases' own warnings first, in CALIB.json too
    result.provenance = {**result.provenance, "cases": [{**_case_record(s), "warnings": ns}
                                                        for s, (_, ns) in zip(sources, prepared)]}
    wanted = config.own_effects == "on" or (config.own_effects == "auto" and not many)
    if wanted and result.success and result.attitude_source == "samples":
        from .estimators.diagnosis.own_effects import AUTO_MAX_PINGS

        n_pings = sum(s.case.pings.n for s in sources)
        if config.own_effects == "auto" and n_pings > AUTO_MAX_PINGS:
            result.warnings.append(f"own_effects: the run was not diagnosed on top of its calibration ({n_pings} pings, "
                                   f"above the {AUTO_MAX_PINGS} of own_effects 'auto'; 'on' diagnoses it, which takes "
                                   "minutes, or diagnose windows of it with this calibration)")
            return result
        say("diagnosing the runs on top of the calibration: what they show of their own")
        result.own_effects = _own_effects(sources, result)
    return result


def _own_effects(sources: list, result) -> dict | None:
    """What the calibrated runs show on top of their calibration (CALIB.json ``own_effects``), diagnosed
    as ``adcpdyn diagnose`` would them; None, with a warning, where they cannot be diagnosed."""
    from .estimators.calibration.record import as_record
    from .estimators.diagnosis.own_effects import find_own_effects

    record = as_record(result)
    runs, _ = _calibrated_runs(sources, record, False)
    try:
        return find_own_effects(runs if len(runs) > 1 else runs[0], record, _diagnosis_config())
    except ValueError as e:
        result.warnings.append(f"own_effects: the runs were not diagnosed ({e})")
        return None


# ----------------------------------------------------------------------------------------------- correct
def correct(case, method: str = "asc", calibration=None, *, timing: str = "deep", reference: str = "bt",
            out=None, history: str | None = None, accept_other_instrument: bool = False,
            attribution=None) -> "Correction":
    """Correct every ping of a case: vessel velocity (bottom track) and water profile.

    Parameters
    ----------
    case : str, os.PathLike, Case or ImportedCase
    method : {'asc', 'adc', 'paper_literal', 'rootfinder', 'oracle'}
        ``asc`` static correction (installation angles or heading misalignment); the dynamic
        methods use the calibration's lever arms; ``oracle`` a simulated case's truth.
    calibration : str, os.PathLike, CalibrationResult, CalibrationRecord or dict, optional
        A CALIB.json path or a calibration in memory (same numbers either way).
    timing : {'deep', 'shallow', 'exact'}
        Travel-time model of the dynamic methods.
    reference : {'bt', 'gnss'}
        Water velocities referenced to the bottom track or to the GNSS velocity.
    out : str or os.PathLike, optional
        Write the result: HDF5 (``OUT.h5``, as ``adcpdyn correct``) or CF netCDF (``OUT.nc``).
    history : str, optional
        What produced it (the netCDF ``history`` attribute).
    accept_other_instrument : bool
        Apply a calibration whose CALIB.json names another instrument (refused by default).
    attribution : str, os.PathLike or Attribution, optional
        With ``out=OUT.nc``: who made and distributes the data (:func:`to_xarray`).

    Returns
    -------
    Correction
        ``vessel_velocity_m_s`` (N, 3) NED, ``water_velocity_m_s`` (N, K, 3) or None,
        ``provenance`` (:class:`~adcpdyn.cases.corrected.CorrectionProvenance`): what was applied
        (heading misalignment, declination, moving bed, calibrated and entered transducer depth,
        calibration file and SHA-256, source case and SHA-256, warnings).

    Raises
    ------
    ValueError
        One line naming the argument or field.
    """
    from .cases.hashing import sha256_of
    from .estimators.calibration.record import as_record
    from .estimators.calibration.identity import as_calibrated_run
    from .estimators.correction.correct_case import correct_case

    _choice("method", method, CORRECTION_METHODS)
    _choice("timing", timing, TIMINGS)
    _choice("reference", reference, REFERENCES)
    netcdf = out is not None and Path(out).suffix.lower() == ".nc"
    if attribution is not None and not netcdf:
        raise ValueError(f"attribution: only with out=OUT.nc (netCDF), got out={None if out is None else str(out)!r}")
    from .cases.attribution import as_attribution

    attribution = as_attribution(attribution) if netcdf else None  # a bad file (or ADCPDYN_ATTRIBUTION) fails first
    if out is not None:
        from .cases.atomic import check_output_file

        check_output_file(out, *[p for p in (case, calibration) if isinstance(p, (str, os.PathLike))], option="out")
    cal = as_record(calibration)
    src, notes = _prepared(_source(case))
    c, applied = as_calibrated_run(src.case, src.path or src.case.name, cal, accept_other_instrument)
    notes = notes + applied
    result = correct_case(c, method, cal, timing, reference).with_provenance(
        warnings=tuple(notes), **_calibration_provenance(cal, type(calibration).__name__),
        calibration_provenance=(cal.provenance or None) if cal is not None else None,
        source_case_name=c.name, source_case_file=src.path,
        source_case_sha256=sha256_of(src.path) if src.path and Path(src.path).is_file() else None)
    if out is not None:
        _write_correction(dataclasses.replace(src, case=c), result, out, cal, history, attribution)
    return result


def _write_correction(src: _Source, result, out, calibration: "CalibrationRecord | None", history,
                      attribution=None) -> None:
    if Path(out).suffix.lower() != ".nc":
        from .cases.corrected import write_correction

        write_correction(result, out, source_case=src.path or "")
        return
    from .cases.netcdf import to_xarray as _to_xarray
    from .cases.netcdf import write_netcdf

    ds = _to_xarray(src.case, result, provenance=src.provenance, source_case_path=src.path, history=history,
                    attribution=attribution)
    inputs = [p for p in (src.path, None if calibration is None else calibration.source) if p]
    write_netcdf(ds, out, *inputs)


# ----------------------------------------------------------------------------------------------- compare
def compare(case, calibration=None, *, out=None, fmt: str = "png", accept_other_instrument: bool = False) -> Comparison:
    """Every correction method on one case against its truth (simulated) or its GNSS reference.

    Parameters
    ----------
    case : str, os.PathLike, Case or ImportedCase
    calibration : path, CalibrationResult, CalibrationRecord or dict, optional
        Without one only ``asc`` (and ``oracle`` on a simulated case) run.
    out : str or os.PathLike, optional
        A folder (created when its parent exists) for ``CASE_compare.json`` and the figure.
    fmt : {'png', 'pdf', 'svg'}
        The figure's format.
    accept_other_instrument : bool
        Apply a calibration whose CALIB.json names another instrument (refused by default).

    Returns
    -------
    Comparison

    Raises
    ------
    ValueError
        The case has neither /truth nor a reference velocity, or a bad argument (one line).
    """
    import json

    from .cases.coverage import reference_at
    from .estimators.calibration.record import as_record
    from .estimators.calibration.identity import as_calibrated_run
    from .estimators.correction.correct_case import correct_case
    from .estimators.statistics.metrics import velocity_metrics

    _choice("fmt", fmt, FIGURE_FORMATS)
    if out is not None:
        from .cases.atomic import check_output_folder

        check_output_folder(out, option="out")
    cal = as_record(calibration)
    src, notes = _prepared(_source(case))
    c, applied = as_calibrated_run(src.case, src.path or src.case.name, cal, accept_other_instrument)
    notes = notes + applied
    methods = [m for m in CORRECTION_METHODS if m != "oracle" or c.truth is not None]
    if cal is None:
        methods = [m for m in methods if m in ("asc", "oracle")]
    results, not_run = {}, {}
    for m in methods:  # a method this calibration cannot drive is reported, not fatal to the others
        try:
            results[m] = correct_case(c, m, cal)
        except ValueError as err:
            not_run[m] = str(err)
    if c.truth is not None:
        ref, label = c.truth.vessel_velocity_m_s, "truth"
    elif c.reference is not None and c.reference.velocity_m_s is not None:
        ref, label = reference_at(c, c.pings.time_s), "reference"
    else:
        raise ValueError(f"{src.path or c.name}: /truth or /reference: needed to compare methods against something")
    table = {m: velocity_metrics(r.time_s, r.vessel_velocity_m_s, ref) for m, r in results.items()}
    table[label] = velocity_metrics(c.pings.time_s, ref, ref)
    comparison = Comparison(c.name, label, table, results, not_run, notes)
    if out is not None:
        from .cases.atomic import atomic_path
        from .estimators.calibration.result import jsonable
        from .plots import velocity_figure

        folder = Path(out)
        table_path, figure_path = folder / f"{c.name}_compare.json", folder / f"{c.name}_compare.{fmt}"
        with atomic_path(table_path) as tmp, open(tmp, "w") as fh:
            json.dump(jsonable({**table, "against": label, "not_run": not_run, "warnings": notes}), fh, indent=2)
        legend = "truth" if label == "truth" else "reference (at rest)" if c.reference.stationary else "GNSS"
        velocity_figure(c.pings.time_s, {m: r.vessel_velocity_m_s for m, r in results.items()}, ref,
                        f"{c.name}: corrections against {comparison.against_text}", figure_path, reference_label=legend)
        comparison.files = [table_path, figure_path]
    return comparison


# ----------------------------------------------------------------------------------------------- diagnose
def diagnose(cases, calibration=None, *, effects=None, attitude: str = "auto", navigation: str = "auto",
             given=(), out=None, fmt: str = "png", progress: Callable[[str], None] | None = None,
             accept_other_instrument: bool = False, hold_own_effects: bool = True) -> "DiagnosisResult":
    """Where the sim-to-real gap of a run lies, which unmodelled effect causes it, how far it shrinks.

    Parameters
    ----------
    cases : case or list of cases
        One run, or several runs of one boat (a list: shared and per-run effects, whole runs
        held out too). Paths, Case or ImportedCase objects.
    calibration : path, CalibrationResult, CalibrationRecord or dict, optional
        Its platform quantities are pinned in the base model.
    effects : sequence of str, optional
        Catalog effects to try (default: all).
    attitude : {'auto', 'model', 'samples'}
        The beams' attitude.
    navigation : {'auto', 'random_walk', 'knots'}
        The base's vessel velocity: a velocity at every ping tied by a random-walk prior whose
        intensity the data set (a real boat's ping-to-ping speed changes are motion), or a
        piecewise-linear curve through knots (smooth simulated courses); ``auto`` (default): the
        random walk where the beams take the sensor's samples (every real file, with GNSS or without)
        or a motion model follows the attitude only beyond the sensors' noise, knots where it follows
        to their noise or the reference is stationary.
    given : sequence of str, optional
        Effects the run is known to carry (e.g. what its clean run named): fitted first and kept
        in every model, so the candidates are judged on top of them (``result.given`` holds
        their estimates).
    out : str or os.PathLike, optional
        DIAG.json; DIAG.md and a residual figure are written beside it.
    fmt : {'png', 'pdf', 'svg'}
        The figure's format.
    progress : callable, optional
        Called with each fitted model's label (``effect`` in round 1, ``chosen+effect`` later).
    accept_other_instrument : bool
        Apply a calibration whose CALIB.json names another instrument (refused by default).
    hold_own_effects : bool
        The calibration's own runs: hold what they showed when calibrated (CALIB.json
        ``own_effects``) at its values, so the diagnosis answers what changed since (default); False
        diagnoses them afresh. Without ``given`` only.

    Returns
    -------
    DiagnosisResult
        ``verdict``, ``statement``, gaps before and after, ``where``, ``ranking``;
        ``base["case_warnings"]`` holds what the coverage step left out.

    Raises
    ------
    ValueError
        Too few pings, no attitude, an unknown effect or option (one line).
    """
    from .estimators.calibration.record import as_record
    from .estimators.diagnosis.diagnose import diagnose as _diagnose

    _choice("fmt", fmt, FIGURE_FORMATS)
    many = _many(cases) and len(cases) > 1
    items = list(cases) if _many(cases) else [cases]
    if not items:
        raise ValueError("cases: expected at least one case")
    if out is not None:
        from .cases.atomic import check_output_file

        check_output_file(out, *[p for p in [*items, calibration] if isinstance(p, (str, os.PathLike))], option="out")
    cal = as_record(calibration)
    prepared = [_prepared(_source(c, "cases")) for c in items]
    notes = [n for _, ns in prepared for n in ns]
    run_cases, applied = _calibrated_runs(_keyed([s for s, _ in prepared]), cal, accept_other_instrument)
    notes += applied
    config = _diagnosis_config(effects, attitude, navigation, given, hold_own_effects)
    result = _diagnose(run_cases if many else run_cases[0], config, calibration=cal, progress=progress)
    if notes:
        result.base["case_warnings"] = notes
    if out is not None:
        from .estimators.diagnosis.report import write_report

        write_report(result, out, fmt=fmt)
    return result


def _diagnosis_config(effects=None, attitude: str = "auto", navigation: str = "auto", given=(),
                      hold_own_effects: bool = True) -> "DiagnosisConfig":
    """The diagnosis options the API and the command line expose (the catalog's effects unless named)."""
    from .estimators.diagnosis.diagnose import DiagnosisConfig

    return DiagnosisConfig(effects=tuple(effects) if effects else DiagnosisConfig().effects, attitude=attitude,
                           navigation=navigation, given=tuple(given or ()), hold_own_effects=bool(hold_own_effects))


def field_selftest(case, calibration=None, *, navigation: str = "auto", effects=None, attitude: str = "auto",
                   sizes: dict | None = None, out=None, fmt: str = "png",
                   progress: Callable[[str], None] | None = None, accept_other_instrument: bool = False) -> dict:
    """What this file (or survey) can detect: each field error (compass offset, attitude and
    reference latency, moving bed, sound speed, tilt low-pass, heave) injected at typical sizes into
    the recorded channels, and each run diagnosed blind with the file's calibration.

    Parameters
    ----------
    case : path, Case or ImportedCase, or a list of them
        One run, or a survey's runs (one boat, one river: each error written into every run, the
        bed one velocity downstream, and diagnosed jointly).
    calibration : path, CalibrationResult, CalibrationRecord or dict, optional
        The file's (survey's) calibration; without one it is calibrated on itself first (8 starts,
        jointly for a survey).
    navigation, effects, attitude, accept_other_instrument : as :func:`diagnose`.
    sizes : dict, optional
        {error: sizes} (``adcpdyn.estimators.diagnosis.field_errors.FIELD_ERRORS`` names and
        units); default the field's typical sizes.
    out : str or os.PathLike, optional
        SELFTEST.json; SELFTEST.md and a figure are written beside it.

    Returns
    -------
    dict
        ``rows`` (per run: error, size, verdict, named or not, shrink, estimate, gap) and
        ``summary`` (top-1, per error the smallest size detected, the clean file's verdict).
    """
    from .estimators.calibration.record import as_record
    from .estimators.diagnosis.field_selftest import field_selftest as _field_selftest, write_field_selftest

    _choice("fmt", fmt, FIGURE_FORMATS)
    items = list(case) if _many(case) else [case]
    if not items:
        raise ValueError("case: expected at least one case")
    if out is not None:
        from .cases.atomic import check_output_file

        check_output_file(out, *[p for p in [*items, calibration] if isinstance(p, (str, os.PathLike))], option="out")
    prepared = [_prepared(_source(c, "case")) for c in items]
    notes = [n for _, ns in prepared for n in ns]
    sources = _keyed([s for s, _ in prepared])
    note = None
    if calibration is None:
        calibration = calibrate([s.case for s in sources] if len(sources) > 1 else sources[0].case, n_starts=8)
        note = "calibrated on itself (8 starts" + (", jointly" if len(sources) > 1 else "") + "): no --calibration given"
    cal = as_record(calibration)
    runs, applied = _calibrated_runs(sources, cal, accept_other_instrument)
    notes += applied
    config = _diagnosis_config(effects, attitude, navigation)
    res = _field_selftest(runs if len(runs) > 1 else runs[0], cal, config, sizes=sizes, progress=progress)
    res["notes"] = notes + ([note] if note else [])
    if out is not None:
        write_field_selftest(res, out, fmt=fmt)
    return res


# ----------------------------------------------------------------------------------------------- export
def to_xarray(case, correction: "Correction | None" = None, *, history: str | None = None,
              attribution=None) -> "xarray.Dataset":
    """A case, and optionally a correction of it, as a CF-1.8 :class:`xarray.Dataset`.

    Parameters
    ----------
    case : str, os.PathLike, Case or ImportedCase
    correction : Correction, optional
        The result of :func:`correct` on this case.
    history : str, optional
        What produced it, for the ``history`` attribute.
    attribution : str, os.PathLike or Attribution, optional
        Who made and distributes the data: creator, publisher, institution, licence, naming
        authority (ACDD-1.3, IOOS-1.2), as a TOML file of those attributes or an
        :class:`~adcpdyn.cases.attribution.Attribution`; without it the TOML file named by the
        environment variable ``ADCPDYN_ATTRIBUTION`` when set, else ``not stated``. A file is named in
        the attributes by absolute path and SHA-256.

    Returns
    -------
    xarray.Dataset
        ENU velocities, UTC ``time`` (when the case has a UTC origin; else the pings'
        coordinate is ``case_time``), dims ``beam``, ``time``, ``depth``; CF trajectoryProfile
        with positions and dates, ACDD-1.3 and IOOS-1.2 attributes; provenance attributes
        (adcpdyn version, source case and instrument file by absolute path with SHA-256,
        method, calibration file, heading misalignment, declination, moving bed).

    Raises
    ------
    ValueError
        The correction does not belong to the case.
    """
    from .cases.netcdf import to_xarray as _to_xarray

    src = _source(case)
    if correction is not None:
        from .cases.coverage import restrict_to_coverage

        src = dataclasses.replace(src, case=restrict_to_coverage(src.case, source=src.path or src.case.name)[0])
    return _to_xarray(src.case, correction, provenance=src.provenance, source_case_path=src.path, history=history,
                      attribution=attribution)


def export(case, out, correction: "Correction | None" = None, *, history: str | None = None,
           attribution=None) -> Path:
    """Write a case (and optionally a correction of it) as CF-1.8 netCDF (h5netcdf engine).

    Parameters
    ----------
    case : str, os.PathLike, Case or ImportedCase
    out : str or os.PathLike
        ``OUT.nc``, written atomically with the permissions of the process umask; never an input.
    correction : Correction, optional
    history : str, optional
    attribution : str, os.PathLike or Attribution, optional
        Who made and distributes the data (:func:`to_xarray`).

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    ValueError
        ``out`` does not end in ``.nc``, its folder is missing, or it names an input.
    """
    from .cases.atomic import check_output_file
    from .cases.netcdf import write_netcdf

    if Path(out).suffix.lower() != ".nc":
        raise ValueError(f"out: expected a netCDF file name ending in .nc, got {str(out)!r}")
    inputs = [case] if isinstance(case, (str, os.PathLike)) else []
    check_output_file(out, *inputs, option="out")
    ds = to_xarray(case, correction, history=history or "adcpdyn.export", attribution=attribution)
    write_netcdf(ds, out, *inputs)
    return Path(out)
