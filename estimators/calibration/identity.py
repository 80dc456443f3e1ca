"""Whether a calibration belongs to a run: the same instrument (refused otherwise, in one line
naming both), at the same site and season (warned otherwise).

Another head's lever arms, installation angles and compass corrections applied to this one
move every velocity without a trace; a calibration written before schema 3 does not say whose
it is, and is applied with a note saying so. :func:`as_calibrated_run` also names the run as the
calibration keys its runs.
"""

from __future__ import annotations

from pathlib import Path

from ...cases.case import Case
from ...cases.identity import identity_of, instrument_difference, site_differences, site_of
from .record import CalibrationRecord

OVERRIDE_FLAG = "--accept-other-instrument"


def check_calibration_identity(calibration: CalibrationRecord | None, case, accept_other_instrument: bool = False) -> list:
    """Notes on applying ``calibration`` to ``case``.

    Raises
    ------
    ValueError
        One line naming both instruments when the calibration is another instrument's (unless
        ``accept_other_instrument``: then a note says it was applied anyway).
    """
    if calibration is None:
        return []
    source = calibration.source or "the calibration"
    theirs = calibration.instrument
    if theirs is None:
        return [f"{source} does not say which instrument it calibrated (written before schema 3): applied to "
                f"{case.name} unchecked"]
    notes, mine = [], identity_of(case)
    why = instrument_difference(theirs, mine)
    if why:
        text = (f"{source} calibrated {theirs.label()}, but {case.name} was measured with {mine.label()} ({why}): "
                "another instrument's lever arms and angles")
        if not accept_other_instrument:
            raise ValueError(f"calibration: {text}; pass {OVERRIDE_FLAG} to apply it anyway")
        notes.append(f"{text}, applied anyway ({OVERRIDE_FLAG})")
    if calibration.site is not None:
        far = site_differences(calibration.site, site_of([case]))
        if far:
            notes.append(f"{source} was made where and when {case.name} was not ({', '.join(far)}): an installation "
                         "remounted or a compass re-swung since would not show in it")
    return notes


def as_calibrated_run(case: Case, path, calibration: CalibrationRecord | None,
                      accept_other_instrument: bool = False) -> tuple[Case, list]:
    """The run a calibration is applied to, and the notes on applying it: the calibration checked
    to be this instrument's (:func:`check_calibration_identity`, a one-line
    refusal otherwise), and the case named as the calibration keys its runs (by case name, or by
    file name when the cases shared one) so that :meth:`CalibrationRecord.moving_bed_for` finds its own run."""
    runs = [] if calibration is None else [r.case for r in calibration.runs]
    if case.name not in runs and Path(path).stem in runs:
        case = case.replace(name=Path(path).stem)
    return case, check_calibration_identity(calibration, case, accept_other_instrument)
