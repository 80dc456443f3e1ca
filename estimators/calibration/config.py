"""The settings of a calibration (:class:`CalibrationConfig`): one frozen record, every choice
checked at construction against the values it may take, named by its field."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...solvers.cluster import SERIAL, check_address
from ...solvers.multistart import SolverOptions
from ..formulations import FORMULATIONS
from ..run_setup import NAVIGATION_CHOICES

TIMINGS = ("auto", "shallow", "deep", "exact")
ATTITUDES = ("auto", "model", "samples")
METHODS = ("joint", "two-stage")
TANGENTIALS = ("consistent", "paper_literal")
JACOBIANS = ("auto", "symbolic", "assembled")
COMPILES = ("auto", "always", "never")
MOVING_BED_CHOICES = ("auto", "off", "constant", "section")
DEVIATION_CHOICES = ("auto", "on", "off")
OWN_EFFECTS_CHOICES = ("auto", "on", "off")
SE_METHODS = ("hac", "white")


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of a joint calibration.

    Parameters
    ----------
    formulation : str
        Lever-arm formulation, one of ``paper``, ``exact``, ``minimal``, ``free``.
    n_starts : int
        Multistart size (the attitude pre-fit, the empirical guess and a Latin
        hypercube design over the start region fill it).
    seed : int
        Seed of the start design.
    timing : str
        ``auto`` (deep when the round trip exceeds 1% of the motion period), ``shallow``,
        ``deep`` or ``exact`` (deep with the travel time solved for the moving transducer).
    max_modes : int
        Most damped modes per axis tried by the pre-fit's information criterion.
    modes : int, optional
        Exactly this many modes per axis (the paper uses 1).
    estimate_noise : bool
        Re-estimate each channel's noise from the residuals and solve again.
    velocity_knot_interval_s : float, optional
        Spacing of the navigation-velocity knots (default: from the data rates).
    navigation : str
        The vessel's velocity: ``knots`` (piecewise-linear between knots), ``random_walk`` (a
        velocity at every ping under a random-walk prior, its intensity and every noise level
        from the data by variance components: a real boat's speed changes between two fixes are
        motion, which the bottom track sees and a smooth curve does not) or ``auto`` (the random
        walk for a run that no stationary reference holds still and whose beams take the sensor's
        samples, as a real file's do, or whose motion model follows the attitude only beyond the
        sensors' noise; knots otherwise:
        :func:`~adcpdyn.estimators.run_setup.choose_navigation`).
    lever_box_m : float, optional
        Bound on every lever-arm coordinate (default: half the vessel length, else 10 m).
    installation_bound_rad : float
        Bound on each installation angle (vessel-frame sensors).
    nominal_installation_ypr_rad : tuple
        Installation angles used where the data cannot give them (head sensor).
    epsilon_rel : float
        ``paper`` formulation: relaxation of the Janus conditions.
    use_ranges : bool
        Include slant ranges when the case has them.
    method : str
        ``joint`` (everything in one NLP) or ``two-stage`` (the paper: a one-mode fit of
        each attitude axis, then the lever arms with that attitude frozen and the
        installation angles at their nominal values).
    tangential : str
        ``consistent`` (dLambda/dt r) or ``paper_literal`` (Omega r as printed).
    workers : int
        Threads solving starts at once.
    attitude : str
        Attitude of the beams: ``model`` (the damped-mode model fitted jointly, the paper's
        method), ``samples`` (the sensor's samples, fixed: a smoothing spline within the motion
        band, or straight segments where the samples are too sparse for it; for runs no motion
        model follows: attitude sampled below the motion, long records with turns) or
        ``auto`` (samples when the pre-fit leaves residuals above ``MAX_MODEL_RESIDUAL_RAD``
        that are coloured, |lag-1 autocorrelation| > ``MIN_RESIDUAL_LAG1``: motion the model
        does not follow, not a noisy sensor).
        With samples, lever arms are reported only when the samples resolve the motion
        (at least ``MIN_SAMPLES_PER_PERIOD`` per period of the pre-fit's dominant mode).
    moving_bed : str
        The bed moving under the bottom track (bed load; the reference does not see it):
        ``auto`` (with a moving reference a constant bed, kept only when the data say it moves, and
        with the flow, not against it: :func:`~adcpdyn.estimators.calibration.moving_bed_decision.moving_bed_test`,
        reported in ``moving_bed_test``; else ``off``), ``off`` (a bed verified
        fixed, e.g. by a loop or stationary test), ``constant`` (one velocity, north and east,
        shared by the runs) or ``section`` (a piecewise-linear function of the position along
        the section, ``moving_bed_section_knots`` values shared by the runs).
    compass_deviation : str
        Head sensor against a moving reference: the one-cycle deviation B sin psi + C cos psi on
        top of the misalignment. ``auto``: estimated with the prior N(0,
        ``compass_deviation_prior_rad``^2) on B and C, so where the runs' headings do not fix it
        (one course, or two opposite ones, where it looks like a moving bed) the prior's width
        enters the bed's and the misalignment's standard errors instead of being assumed zero;
        where they span the compass the data dominate. ``on``: estimated without a prior (needs
        headings all round); ``off``: left out (assumed zero).
    compass_deviation_prior_rad : float
        Standard deviation of the prior on B and C (a swung or calibrated compass: about 1 deg).
    standard_errors : str
        ``hac`` (Newey-West sandwich over each run's time bins, never below the white-noise
        SE: :mod:`.hac`) or ``white`` (the Gauss-Newton covariance alone).
    magnetic_declination_rad : float, optional
        Declination at the site (east positive), when known; CALIB.json then reports the
        compass error (misalignment minus declination).
    scheduler : str
        Where the starts are solved: ``none`` (this process, ``workers`` threads), ``local`` (a
        Dask LocalCluster of ``workers`` single-threaded processes) or a Dask scheduler's address
        (``tcp://host:port``); each worker builds the problem itself (:mod:`.distributed`). A
        script that starts a LocalCluster needs Python's ``if __name__ == "__main__":`` guard
        (its workers are spawned processes that import the script).
    jacobian : str
        Residual Jacobian (Gauss-Newton Hessian, standard errors): ``symbolic`` (the whole
        problem expanded to SX and differentiated by CasADi), ``assembled`` (per-row
        Jacobians chained numerically, :mod:`.row_jacobian`; MX problem) or ``auto``
        (assembled above ``ASSEMBLED_MIN_NODES`` expanded nodes, long runs and deep water, or where the
        nodes times the Jacobian's forward directions exceed ``ASSEMBLED_MIN_COST``: a motion model's
        parameters reach every row).
    compile : str
        The assembled problem's per-ping model (bottom track with its gradient, per-row
        Jacobians) as machine code from the per-machine cache (:mod:`~adcpdyn.solvers.compiled`,
        built by the system C compiler the first time; the same numbers as interpreted):
        ``auto`` for problems of at least ``COMPILE_MIN_PINGS`` pings (all runs; the Jacobian then
        assembled unless ``jacobian='symbolic'``, which compiles nothing) and for shorter ones whose
        Jacobian ``auto`` assembles, ``always`` (needs ``jacobian='assembled'``) or ``never``.
    screen_pings : int, optional
        A long calibration's multistart: where the runs hold at least twice this many pings (and
        no velocity per ping), every start is solved on every k-th ping of each run and every k-th
        reference sample (about this many pings in all; the same unknowns), and the best of them
        is then solved on all the data, once. None: every start on all the data.
    own_effects : str
        ``auto``: one run (of at most ``own_effects.AUTO_MAX_PINGS`` pings, a warning above) whose beams take
        the sensor's samples (a real file) is then diagnosed on
        top of the calibration and what it shows is kept with it (CALIB.json ``own_effects``), so a
        later diagnosis of it holds that and answers what changed since
        (:mod:`~adcpdyn.estimators.diagnosis.own_effects`); ``on``: a survey's runs too (one joint
        diagnosis, minutes for many runs); ``off``: not diagnosed.
    solver : SolverOptions
    """

    formulation: str = "exact"
    method: str = "joint"
    tangential: str = "consistent"
    n_starts: int = 24
    seed: int = 0
    timing: str = "auto"
    max_modes: int = 3
    modes: int | None = None
    estimate_noise: bool = True
    velocity_knot_interval_s: float | None = None
    navigation: str = "knots"
    lever_box_m: float | None = None
    installation_bound_rad: float = float(np.deg2rad(15.0))
    nominal_installation_ypr_rad: tuple = (0.0, 0.0, 0.0)
    epsilon_rel: float = 0.05
    use_ranges: bool = True
    workers: int = 2
    scheduler: str = SERIAL
    attitude: str = "auto"
    jacobian: str = "auto"
    compile: str = "auto"
    moving_bed: str = "auto"
    moving_bed_section_knots: int = 3
    compass_deviation: str = "auto"
    compass_deviation_prior_rad: float = float(np.deg2rad(1.0))
    standard_errors: str = "hac"
    magnetic_declination_rad: float | None = None
    own_effects: str = "auto"
    screen_pings: int | None = 2000
    solver: SolverOptions = field(default_factory=SolverOptions)

    def __post_init__(self):
        for name, allowed in (("formulation", FORMULATIONS), ("timing", TIMINGS), ("method", METHODS),
                              ("tangential", TANGENTIALS), ("attitude", ATTITUDES), ("jacobian", JACOBIANS),
                              ("moving_bed", MOVING_BED_CHOICES), ("compass_deviation", DEVIATION_CHOICES),
                              ("standard_errors", SE_METHODS), ("navigation", NAVIGATION_CHOICES),
                              ("compile", COMPILES), ("own_effects", OWN_EFFECTS_CHOICES)):
            if getattr(self, name) not in allowed:
                raise ValueError(f"CalibrationConfig.{name}: expected one of {list(allowed)}, got {getattr(self, name)!r}")
        if not 0 < float(self.compass_deviation_prior_rad) <= 0.5:
            raise ValueError(f"CalibrationConfig.compass_deviation_prior_rad: expected a width in (0, 0.5] rad, "
                             f"got {self.compass_deviation_prior_rad!r}")
        if self.compile == "always" and self.jacobian != "assembled":
            raise ValueError(f"CalibrationConfig.compile (--compile): 'always' compiles the assembled problem's per-ping "
                             f"model; expected jacobian (--jacobian) 'assembled', got {self.jacobian!r}")
        if int(self.moving_bed_section_knots) < 2:
            raise ValueError(f"CalibrationConfig.moving_bed_section_knots: expected >= 2, got {self.moving_bed_section_knots}")
        if self.magnetic_declination_rad is not None and not abs(float(self.magnetic_declination_rad)) <= np.pi:
            raise ValueError(f"CalibrationConfig.magnetic_declination_rad: expected a finite angle within +-pi, "
                             f"got {self.magnetic_declination_rad!r}")
        if self.screen_pings is not None and not (isinstance(self.screen_pings, (int, np.integer)) and self.screen_pings >= 100):
            raise ValueError(f"CalibrationConfig.screen_pings: expected None or an integer >= 100, got {self.screen_pings!r}")
        if int(self.n_starts) < 1:
            raise ValueError(f"CalibrationConfig.n_starts: expected >= 1, got {self.n_starts}")
        check_address(self.scheduler, "CalibrationConfig.scheduler")
