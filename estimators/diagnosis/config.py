"""The settings of a gap diagnosis (:class:`DiagnosisConfig`): which effects to try and when a
difference counts. A module of their own because the base fit (:mod:`.base`), the profiles
(:mod:`.profiles`) and the selection (:mod:`.selection`) all read them, below the orchestrator
(:mod:`.diagnose`) that takes them.
"""

from __future__ import annotations

import dataclasses

import os
from dataclasses import dataclass

import numpy as np

from ...models.effects import CATALOG, effect_of, get_effect
from ...solvers.multistart import SolverOptions
from ..calibration.config import ATTITUDES
from ..run_setup import NAVIGATION_CHOICES


@dataclass(frozen=True)
class DiagnosisConfig:
    """Which effects to try and when a difference counts.

    An effect is significant when its coloured-residual BIC (``delta_bic_hac``: the likelihood
    ratio over the long-run/white variance ratio of its per-bin gains, never below the white one)
    improves on the current model's by more than ``bic_margin`` AND it removes at least
    ``min_shrink`` of the held-out gap. A gap is
    significant when its z-score (excess chi-square over its null standard deviation)
    exceeds ``gap_z`` and it exceeds ``min_gap`` (a practical floor: noise levels are
    estimated, so a few percent of excess is not evidence). Up to ``max_effects`` effects
    are chosen one after another; an effect sharing more than ``confounded_share`` of its
    parameters' variance with a base unknown or a chosen effect is named, not chosen.

    On a random-walk base (real files) the held-out gap need only shrink by ``min_shrink_walk``: a real file keeps structure no catalog
    effect explains, so a real effect removes a smaller share of the whole gap. Its gap's z is
    not a gate there: the noise levels are the data's own (variance components), so the white
    z of what they leave says little; the coloured BIC is the test. For the same reason the held-out
    evidence may instead be the paired one, ``heldout_z`` above ``heldout_z_walk``: once a file's own
    effects are in the model its held-out excess sits at the floor of levels estimated on it, so no
    share of it can shrink (winriver01 with its compass deviation and bed: excess -0.02, while a
    0.15 m/s heave improved the held-out prediction at z 17); the improvement must then also be a
    practical one, ``min_gain_walk`` of the held-out excess (a few percent of the noise variance per
    row), since on a long run a z grows with the pings whatever the size: on a 3000-ping simulated
    river transect a reference lever arm of -0.23 m took up 0.006 of it at z 5.5 (what the base's
    sampled attitude leaves, not a lever arm), while the smallest injected errors named on the
    real files remove 0.03 (2 % sound speed) and more.

    Held-out blocks are ``cv_block_s`` long on knots. On a random walk they are ``cv_block_walk_s``
    long: the walk bridges a short hole from its edges (its motion noise over a few pings is less than
    the beams' noise at one), so a 2-s block of the reference was predicted from the neighbouring
    reference, not from the beams, and a constant disagreement of the two never showed (a 10-deg
    compass offset moved RiverPro's held-out gap from 0.060 to 0.041). Where the long blocks show
    no held-out evidence for an effect the coloured BIC accepts, the ping-scale blocks are asked too
    (``EffectScore.ping``): an effect at the ping scale (a latency, heave) may show there only.

    ``given`` effects (a file's own, found on its clean run) are fitted first and stay in every
    model: the candidates are judged on top of them, and they are reported with their estimates.
    With ``given_values`` ((unknown, value, standard error) of every given effect's unknowns) they
    are held there instead, and each given effect is also a candidate: that effect moved from those
    values (an error since then that a given effect carries, a compass offset in a deviation's
    constant, a sound speed beyond the one found, a heave at another frequency).
    """

    effects: tuple = tuple(CATALOG)
    given: tuple = ()  # effects the run is known to carry (a clean file's own): fitted in every model, not candidates
    given_values: tuple = ()  # ((unknown, value, se), ...): the given effects held at these values
    hold_own_effects: bool = True  # a calibration's own runs: its own effects (CALIB.json own_effects) held, if no given
    cv_folds: int = 5
    cv_block_s: float = 2.0
    cv_block_walk_s: float = 20.0
    bic_margin: float = 10.0
    min_shrink: float = 0.25
    min_shrink_walk: float = 0.05
    heldout_z_walk: float = 2.0
    min_gain_walk: float = 0.02
    gap_z: float = 6.0
    min_gap: float = 0.1
    max_modes: int = 3
    max_effects: int = 3
    confounded_share: float = 0.9
    attitude: str = "auto"  # beams' attitude: model | samples | auto (as the calibration chooses)
    navigation: str = "auto"  # the base's vessel velocity: random_walk (a velocity per ping) | knots | auto
    workers: int = min(2, os.cpu_count() or 1)  # threads refitting a round's candidates at once
    solver: SolverOptions = SolverOptions(tol=1e-6, max_iter=200, hessian="gauss-newton", expand=False, mu_init=1e-5)

    def block_s(self, walk: bool) -> float:
        """The held-out blocks' length on a random-walk base (``walk``) or on knots."""
        return self.cv_block_walk_s if walk else self.cv_block_s

    def __post_init__(self):
        for name in self.effects + self.given:
            get_effect(name)
        held = {effect_of(str(n)) for n, *_ in self.given_values}
        if held and held != set(self.given):
            raise ValueError(f"given_values: expected the unknowns of every given effect {sorted(self.given)}, "
                             f"got those of {sorted(held)}")
        if self.attitude not in ATTITUDES:
            raise ValueError(f"attitude: expected one of {list(ATTITUDES)}, got {self.attitude!r}")
        if self.cv_folds < 2:
            raise ValueError(f"cv_folds: expected an integer >= 2, got {self.cv_folds}")
        for name in ("cv_block_s", "cv_block_walk_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected a positive duration in s, got {getattr(self, name)}")
        if self.navigation not in NAVIGATION_CHOICES:
            raise ValueError(f"navigation: expected one of {list(NAVIGATION_CHOICES)}, got {self.navigation!r}")
        if self.max_effects < 1:
            raise ValueError(f"max_effects: expected an integer >= 1, got {self.max_effects}")
        if not np.isfinite(self.heldout_z_walk):
            raise ValueError(f"heldout_z_walk: expected a finite z threshold, got {self.heldout_z_walk}")
        if not self.min_gain_walk >= 0:
            raise ValueError(f"min_gain_walk: expected a held-out excess >= 0, got {self.min_gain_walk}")


def holding(config: DiagnosisConfig, own: dict) -> DiagnosisConfig:
    """``config`` with the runs' ``own`` effects ({"effects", "unknowns": {unknown: {"value", "se"}}},
    :func:`.own_effects.find_own_effects`) given and held at their values."""
    return dataclasses.replace(config, given=tuple(own["effects"]),
                               given_values=tuple((n, v["value"], v["se"]) for n, v in own["unknowns"].items()))
