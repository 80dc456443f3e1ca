"""The runs' own effects: what the diagnosis names on a calibration's own runs, clean, on top of
that calibration. Kept with the calibration (CALIB.json ``own_effects``), they are held at their
values whenever those runs are diagnosed again, so a diagnosis of them answers what changed since
(an error a given effect carries shows as that effect moving from its values), not what they always
had (winriver01: a compass deviation on one course, a salinity setting of 0 ppt in the Bay of Fundy).
"""

from __future__ import annotations

import dataclasses

from .config import DiagnosisConfig
from .diagnose import diagnose

# pings (all runs) up to which own_effects 'auto' diagnoses a calibrated run: a 2995-ping transect's diagnosis takes
# about 36 s (`adcpdyn bench diagnosis`), rounds of it more; at 10^5 pings it took longer than the calibration by far
AUTO_MAX_PINGS = 5000


def find_own_effects(cases, calibration, config: DiagnosisConfig = DiagnosisConfig(), first=None) -> dict:
    """The runs' own effects on top of ``calibration`` (a record of these runs): what their diagnosis
    names (``first``, when already run), then what it names with those given, until nothing more (at
    most ``config.max_effects``; the forward selection's later rounds judge against a held-out gap
    the chosen effects have already emptied, so a second effect under a first is only seen this
    way), and their joint estimates.

    Returns ``{"effects": [...], "unknowns": {unknown: {"value", "se"}}, "navigation", "statement"}``
    (``effects`` empty where the runs show none).
    """
    if getattr(calibration, "own_effects", None):  # found anew, not held at what the record says
        calibration = dataclasses.replace(calibration, own_effects=None)
    first = first or diagnose(cases, dataclasses.replace(config, given=()), calibration=calibration)
    own, r, given = tuple(first.selected), first, ()
    while r.selected and len(own) < config.max_effects:
        r, given = diagnose(cases, dataclasses.replace(config, given=own), calibration=calibration), own
        own = own + tuple(n for n in r.selected if n not in own)
    if own and given != own:
        r = diagnose(cases, dataclasses.replace(config, given=own), calibration=calibration)
    return {"effects": list(own), "unknowns": {n: dict(v) for n, v in r.given.items()} if own else {},
            "navigation": first.base["navigation"], "statement": first.statement}
