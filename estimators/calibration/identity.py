"""Whether a calibration belongs to a run: the same instrument (refused otherwise, in one line
naming both), at the same site and season (warned otherwise).

Another head's lever arms, installation angles and compass corrections applied to this one
move every velocity without a trace; a calibration written before schema 3 does not say whose
it is, and is applied with a note saying so.
"""

from __future__ import annotations

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
