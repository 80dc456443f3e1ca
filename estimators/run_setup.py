"""The numeric decisions of one run, made before anything symbolic is built (:class:`RunSetup`),
its residual channels, and what several runs tell together before the fit (courses, headings,
positions along the section)."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from ..cases.case import Case
from ..models.motion import SampledAttitude
from ..models.rotations import course_difference_rad
from .asc import asc
from .attitude_fit import AttitudeFit, random_share, sampled_attitude
from .knots import random_walk_intensity, vertical_velocity_level
from .noise_guess import initial_noise


ATTITUDE_SOURCES = ("model", "samples", "frozen")
NAVIGATIONS = ("knots", "random_walk")
NAVIGATION_CHOICES = NAVIGATIONS + ("auto",)  # what a user may ask for: auto decides per run
REFERENCE_MARGIN_KNOTS = 1.0  # reference samples kept up to this many knot intervals beyond the pings
THINNED_ATTITUDE_SEED = 0  # the attitude samples a thinned run keeps (RunSetup.thinned): the same ones every time


def has_moving_reference(case: Case) -> bool:
    """Whether the run carries a moving reference velocity (GNSS, video: not a stationary one)."""
    ref = case.reference
    return ref is not None and not ref.stationary and ref.velocity_m_s is not None


def choose_navigation(case: Case, attitude_source: str, requested: str = "auto", irregular: bool = False) -> str:
    """A run's vessel-velocity model: ``requested``, or for ``auto`` a velocity per ping
    (``random_walk``) where no reference holds the run still and the boat's motion is irregular:
    its beams take the sensor's samples, or the motion model follows the attitude only beyond the
    sensors' noise (``irregular``, :func:`~adcpdyn.estimators.calibration.problem.irregular_attitude`:
    a white residual of several degrees, as a real boat's aliased yaw leaves). A real boat changes
    speed between two fixes: the bottom track sees it, a smooth curve does not; without a
    reference the bottom track alone follows it, and a smooth curve through it leaves the boat's
    own motion as a gap (a 94-s window of RiverPro_test01, whose heading the model follows to 4.3
    deg of white residual, was blind on knots to a 0.2 m/s bed and a 2-s reference delay).
    ``knots`` where a motion model follows the attitude to the sensors' noise (its course as
    smooth as the model) or the reference stays put."""
    if requested not in NAVIGATION_CHOICES:
        raise ValueError(f"navigation: expected one of {list(NAVIGATION_CHOICES)}, got {requested!r}")
    if requested != "auto":
        return requested
    held_still = case.reference is not None and case.reference.stationary
    moving = attitude_source == "samples" or (attitude_source == "model" and irregular)
    return "random_walk" if moving and not held_still else "knots"


@dataclass(frozen=True)
class Channel:
    """One residual channel of one run: ``name`` as in CALIB.json (heading, bt_beam1,
    range_beam2, reference_north, ...), its rows' times and mask."""

    run: int
    name: str
    time_s: np.ndarray
    mask: np.ndarray

    @property
    def size(self) -> int:
        return int(self.time_s.size)

    @property
    def group(self) -> str:
        return self.name.split("_")[0]


DELAY_FIELDS = ("sample_shift_s", "sample_tilt_lead_s", "reference_shift_s")


@dataclass
class RunSetup:
    """The numeric decisions of one run, made before anything symbolic is built.

    ``attitude_source``: ``model`` (motion-model unknowns of this run), ``samples`` (the
    sensor's samples, data: :func:`~adcpdyn.estimators.attitude_fit.sampled_attitude`) or
    ``frozen`` (a model fixed beforehand, the two-stage method). ``knots``: navigation-velocity knot times (None: stationary).
    ``reference_rows`` (derived from the knots): which reference samples enter (inside the pings' span).
    ``section_position``: position of each ping along the section in [0, 1] (section bed).
    ``navigation``: ``knots`` (the velocity piecewise-linear between the knots, nothing else) or
    ``random_walk`` (a velocity at every ping, :func:`.knots.ping_knots`, tied to its neighbours by a
    random-walk prior: the ``motion`` rows (V_j+1 - V_j) / sqrt(dt_j) of the horizontal velocity, whose
    level sqrt(q) in m/s/sqrt(s) is the process intensity, a real boat's ping-to-ping speed changes
    being motion; the vertical velocity, a floating boat's heave, zero-mean: the ``vertical`` rows
    V_j,down, whose level is its spread).
    """

    case: Case
    fit: AttitudeFit
    attitude_source: str
    timing: str
    knots: np.ndarray | None
    use_ranges: bool
    attitude_reason: str = ""
    section_position: np.ndarray | None = None
    sample_shift_s: float = 0.0  # rows take the samples' segment about t + shift (a latency's current estimate)
    sample_tilt_lead_s: float = 0.0  # and their tilts low-pass-inverted with this tau (a tilt low-pass' current estimate)
    reference_shift_s: float = 0.0  # reference rows take the navigation at t - shift (a reference latency's current estimate)
    navigation: str = "knots"
    sample_interpolation: str | None = None  # a calibration's way of joining the samples; None: from the data
    samples: SampledAttitude | None = field(default=None, init=False)
    reference_rows: np.ndarray | None = field(default=None, init=False)
    depth_from_ranges: bool = field(default=False, init=False)  # the case's depth is its ranges' (:meth:`Case.depth_from_ranges`)

    @property
    def random_walk(self) -> bool:
        """A velocity at every ping under the random-walk prior (a moving run with random_walk)."""
        return self.navigation == "random_walk" and self.knots is not None

    def noise_guess(self) -> dict:
        """{group: starting noise level} of this run: :func:`.noise_guess.initial_noise`, and when it walks the
        walk's intensity and the vertical velocity's level from the static (ASC) velocities, one
        correction for both (:mod:`.knots`)."""
        guess = initial_noise(self.case, self.fit, self.attitude_source == "model")
        if self.random_walk:
            v = asc(self.case).vessel_velocity_m_s
            guess["motion"] = random_walk_intensity(self.case, v)
            guess["vertical"] = vertical_velocity_level(self.case, v)
        return guess

    def __post_init__(self):
        if self.attitude_source not in ATTITUDE_SOURCES:
            raise ValueError(f"attitude_source: expected one of {list(ATTITUDE_SOURCES)}, got {self.attitude_source!r}")
        if self.navigation not in NAVIGATIONS:
            raise ValueError(f"navigation: expected one of {list(NAVIGATIONS)}, got {self.navigation!r}")
        if self.random_walk and self.knots.size < 2:
            raise ValueError("navigation: 'random_walk' needs at least two knots")
        self.reference_rows = reference_rows(self.case, self.knots)
        self.depth_from_ranges = self.case.depth_from_ranges()
        if self.attitude_source == "samples":
            self.samples = sampled_attitude(self.case, self.fit, self.sample_interpolation)

    def at_delays(self, **delays: float) -> "RunSetup":
        """This run with other current estimates of its delays (``sample_shift_s``, ``sample_tilt_lead_s``,
        ``reference_shift_s``): what comes from the data alone (the smoothed samples, the reference rows)
        kept, not derived again (the samples' smoothing splines cost 0.2 s on a 3000-ping run)."""
        unknown = set(delays) - set(DELAY_FIELDS)
        if unknown:
            raise ValueError(f"at_delays: expected some of {list(DELAY_FIELDS)}, got {sorted(unknown)}")
        other = copy.copy(self)
        for name, value in delays.items():
            setattr(other, name, float(value))
        return other

    def thinned(self, every: int) -> "RunSetup":
        """This run on every ``every``-th ping (the last kept, so the span and the knots stay) and every
        ``every``-th of its reference samples, and a motion model's run a random one in ``every`` of its attitude
        samples (every k-th would alias the modes: pool_m0's 5 samples a period): the same unknowns on fewer rows (a
        long calibration's multistart screens its starts so). The smoothed samples are kept, not derived again."""
        n = self.case.pings.n
        rows = np.unique(np.append(np.arange(0, n, every), n - 1))
        other = copy.copy(self)
        other.case = self.case.ping_subset(rows)
        if self.attitude_source == "model":  # its sensor rows too: a random share, whose times alias no mode
            m = self.case.attitude.time_s.size
            other.case = other.case.replace(attitude=self.case.attitude.subset(
                random_share(m, -(-m // every) + 2, THINNED_ATTITUDE_SEED)))
        other.depth_from_ranges = other.case.depth_from_ranges()
        if self.section_position is not None:
            other.section_position = self.section_position[rows]
        if self.reference_rows is not None:
            other.reference_rows = self.reference_rows[::every]
        return other

    def covered(self, times) -> np.ndarray:
        """Rows the beams' attitude covers: all with a motion model; with the sensor's samples only
        those inside the samples' span (samples are interpolated, never extrapolated: a ping 0.14 s
        before the first sample, just after a release from a heel, carried 0.1 m/s of error)."""
        times = np.asarray(times, dtype=float)
        if self.samples is None:
            return np.ones(times.shape, dtype=bool)
        return (times >= self.samples.time_s[0]) & (times <= self.samples.time_s[-1])

    @property
    def moving_reference(self) -> bool:
        return self.reference_rows is not None and self.reference_rows.size > 0

    @property
    def reference_time_s(self) -> np.ndarray:
        return self.case.reference.time_s[self.reference_rows]

    @property
    def reference_velocity_m_s(self) -> np.ndarray:
        return self.case.reference.velocity_m_s[self.reference_rows]

    @property
    def reference_window_s(self) -> np.ndarray | None:
        """(L, 2) the interval each reference velocity averages over (None: instantaneous samples)."""
        w = self.case.reference.window_s
        return None if w is None else w[self.reference_rows]


def reference_rows(case: Case, knots: np.ndarray | None) -> np.ndarray | None:
    """Indices of the reference samples inside the pings' span (plus one knot interval);
    a one-line error when a moving reference has none there."""
    ref = case.reference
    if ref is None or ref.stationary or ref.time_s is None or ref.velocity_m_s is None:
        return None
    t = case.pings.time_s
    margin = REFERENCE_MARGIN_KNOTS * (float(np.median(np.diff(knots))) if knots is not None and knots.size > 1 else 0.0)
    inside = (ref.time_s >= t[0] - margin) & (ref.time_s <= t[-1] + margin)
    usable = inside & np.any(np.isfinite(ref.velocity_m_s[:, :2]), axis=1)
    if usable.sum() < 2:
        raise ValueError(f"{case.name}: reference.time_s: expected reference samples within the pings' span "
                         f"[{t[0]:.6g}, {t[-1]:.6g}] s, got {int(usable.sum())} usable of {ref.time_s.size} "
                         f"(reference spans [{ref.time_s[0]:.6g}, {ref.time_s[-1]:.6g}] s)")
    return np.flatnonzero(inside)


def section_positions(runs: list[RunSetup]) -> None:
    """Position of every ping along the section, 0 at the bank where the first run starts and
    1 at the other, from the reference velocity integrated over each run and projected on the
    survey's mean crossing direction; sets ``run.section_position``. Each run is taken to span
    the section (a discharge transect runs bank to bank)."""
    tracks, directions = [], []
    for run in runs:
        if not run.moving_reference:
            raise ValueError(f"{run.case.name}: moving_bed 'section' needs a moving reference velocity")
        t, v = run.reference_time_s, np.nan_to_num(run.reference_velocity_m_s[:, :2])
        x = np.vstack([np.zeros(2), np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None], axis=0)])
        tracks.append((t, x))
        directions.append(x[-1] - x[0])
    axis = directions[0] / max(np.linalg.norm(directions[0]), 1e-9)
    along = [np.sign(np.dot(d, axis)) or 1.0 for d in directions]
    axis = np.sum([a * d for a, d in zip(along, directions)], axis=0)
    axis = axis / max(np.linalg.norm(axis), 1e-9)
    for run, (t, x) in zip(runs, tracks):
        u = x @ axis  # every run on the same axis: a run in either direction reads 0 at the same bank
        s = (u - u.min()) / max(u.max() - u.min(), 1e-9)
        run.section_position = np.clip(np.interp(run.case.pings.time_s, t, s), 0.0, 1.0)


def speed_guess(run: RunSetup) -> float:
    if run.moving_reference:
        v = run.reference_velocity_m_s[:, :2]
        speed = np.linalg.norm(v, axis=1)
        speed = speed[np.isfinite(speed)]
        if speed.size:
            return float(np.median(speed))
    return 0.1


def course_offset_rad(runs: list[RunSetup]) -> float:
    """Course of the reference minus course of the static (ASC) bottom-track velocity over all
    runs' pings, radians (circular mean); 0 without a moving reference."""
    diffs = []
    for run in runs:
        if not run.moving_reference:
            continue
        v = asc(run.case).vessel_velocity_m_s
        t = run.case.pings.time_s
        tr, vr = run.reference_time_s, run.reference_velocity_m_s
        ok_r = np.all(np.isfinite(vr[:, :2]), axis=1)
        if ok_r.sum() < 2:
            continue
        g = np.column_stack([np.interp(t, tr[ok_r], vr[ok_r, j]) for j in range(2)])
        ok = np.all(np.isfinite(v[:, :2]), axis=1) & (np.hypot(*g.T) > 0.1)
        if ok.any():
            diffs.append(course_difference_rad(g[ok], v[ok, :2]))
    if not diffs or np.concatenate(diffs).size < 3:
        return 0.0
    return float(np.angle(np.mean(np.exp(1j * np.concatenate(diffs)))))


def heading_centre(runs: list[RunSetup]) -> tuple[float, float]:
    """Mean sine and cosine of the sensor heading over every run's attitude samples."""
    psi = np.concatenate([r.case.attitude.heading_rad[np.isfinite(r.case.attitude.heading_rad)] for r in runs])
    return (float(np.mean(np.sin(psi))), float(np.mean(np.cos(psi)))) if psi.size else (0.0, 0.0)


def heading_span(runs: list[RunSetup]) -> float:
    """Smallest eigenvalue of the covariance of (sin psi, cos psi) over every run's attitude
    samples: 0.5 for headings all round the compass, 0 for one course or two opposite ones
    (where a one-cycle compass deviation cannot be told from a moving bed)."""
    psi = np.concatenate([r.case.attitude.heading_rad[np.isfinite(r.case.attitude.heading_rad)] for r in runs])
    if psi.size < 3:
        return 0.0
    return float(np.linalg.eigvalsh(np.cov(np.vstack([np.sin(psi), np.cos(psi)])))[0])
