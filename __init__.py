"""adcpdyn: attitude dynamic correction for vessel-mounted four-beam Janus ADCPs.

The Python API (``docs/api.md`` has a worked example)::

    import adcpdyn

    imported = adcpdyn.import_file("transect.PD0", out="transect.h5")   # or read_case / simulate
    calibration = adcpdyn.calibrate(imported, n_starts=8)               # one run, or a list: one NLP
    calibration.to_json("CALIB.json")
    corrected = adcpdyn.correct(imported, "asc", "CALIB.json")          # or the CalibrationResult itself
    ds = adcpdyn.to_xarray(imported, corrected)                         # CF-1.8, ENU, UTC time
    adcpdyn.export(imported, "transect.nc", corrected)

Functions: :func:`read_case`, :func:`import_file`, :func:`simulate`, :func:`calibrate`,
:func:`read_calibration`, :func:`correct`, :func:`compare`, :func:`diagnose`,
:func:`to_xarray`, :func:`export` (all in :mod:`adcpdyn.api`). Types: ``Case``,
``ImportedCase``, ``CalibrationConfig``, ``CalibrationResult``, ``CalibrationRecord``,
``Correction``, ``Comparison``, ``DiagnosisResult`` (imported on first use: CasADi loads
only when a calibration type or verb needs it).

Sub-packages: ``models`` (symbolic physics), ``estimators`` (calibration, correction,
diagnosis, baselines, statistics), ``solvers`` (numerical drivers), ``cases`` (case files
and scenarios).
"""

from importlib.metadata import PackageNotFoundError as _NotInstalled
from importlib.metadata import version as _version

# absolute, not relative: pytest (importlib mode) also imports this file on its own, as the rootdir's package
from adcpdyn.memory import configure_huge_pages as _configure_huge_pages

_configure_huge_pages()  # numpy's huge-page advice off unless NUMPY_MADVISE_HUGEPAGE says (adcpdyn.memory)

from adcpdyn.api import (CORRECTION_METHODS, FIGURE_FORMATS, REFERENCES, TIMINGS, Comparison, ImportedCase, calibrate,
                         compare, correct, diagnose, export, import_file, read_calibration, read_case, simulate,
                         to_xarray)

try:
    __version__ = _version("adcpdyn")
except _NotInstalled:  # run from a source tree that was never installed
    __version__ = "0.1.0+unknown"

# types, imported when first used (PEP 562)
_LAZY = {
    "Case": ".cases.case",
    "CalibrationConfig": ".estimators.calibration.problem",
    "CalibrationResult": ".estimators.calibration.result",
    "CalibrationRecord": ".estimators.calibration.record",
    "Correction": ".estimators.asc",
    "DiagnosisResult": ".estimators.diagnosis.diagnose",
}

__all__ = ["__version__", "read_case", "import_file", "simulate", "calibrate", "read_calibration", "correct", "compare",
           "diagnose", "to_xarray", "export", "ImportedCase", "Comparison", "CORRECTION_METHODS", "TIMINGS",
           "REFERENCES", "FIGURE_FORMATS", *_LAZY]


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name], "adcpdyn"), name)
    raise AttributeError(f"module 'adcpdyn' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
