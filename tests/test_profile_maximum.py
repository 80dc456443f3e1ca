"""The one-dimensional profile search a velocity scale's marginal likelihood is read by
(``profiles.profile_maximum``), against closed forms: the maximum and curvature of a quadratic, and
of a Student-t log-likelihood (near-quadratic at its peak, flatter beyond, as the marginal profiles
of a sound speed on real files are), started where the diagnosis starts it (0 and +- the scale)."""

from __future__ import annotations

import numpy as np
import pytest

from adcpdyn.estimators.diagnosis.profiles import PROFILE_SE_SHARE, profile_maximum

SCALE = 0.01  # the sound speed's scale: the first points 0 and +- 0.01


def _student_t(mode: float, width: float, dof: float):
    return lambda v: -(dof + 1) / 2 * np.log1p(((v - mode) / width) ** 2 / dof)


def test_a_quadratic_profile_gives_its_vertex_and_curvature():
    mode, se = 0.023, 0.004
    best, curvature, values = profile_maximum(lambda v: -0.5 * ((v - mode) / se) ** 2, 0.0, SCALE, -0.2, 0.2)
    assert best == pytest.approx(mode, abs=1e-9)
    assert curvature == pytest.approx(-0.5 / se**2, rel=1e-6)
    assert len(values) <= 6


@pytest.mark.parametrize("mode", [-0.037, -0.045, -0.025, 0.03, 0.05])
def test_a_peaked_profile_far_from_the_start_is_located_within_a_share_of_its_se(mode):
    # winriver01 with a 4 % sound speed written in: its profile's maximum at -0.037 beyond the first
    # points' reach; the three points nearest the best once all lay on one side of it (stopped at -0.03)
    width, dof = 0.0036, 30.0
    best, curvature, _ = profile_maximum(_student_t(mode, width, dof), 0.0, SCALE, -0.2, 0.2)
    se = width * np.sqrt(dof / (dof + 1))  # 1/sqrt(-2 x the log-density's curvature at its mode)
    assert abs(best - mode) < PROFILE_SE_SHARE * se
    assert 1.0 / np.sqrt(-2.0 * curvature) == pytest.approx(se, rel=0.1)


def test_a_profile_rising_to_a_bound_ends_there_without_a_curvature():
    best, curvature, _ = profile_maximum(lambda v: 100.0 * v, 0.0, SCALE, -0.2, 0.05)
    assert best == 0.05
    assert curvature > -1e-6  # no peak: a standard error beyond any scale


def test_a_profile_started_at_a_bound_takes_three_points_inside_it():
    # a later round's profile starts at an earlier one's maximum, which may sit at the bound: the point
    # beyond it merges with it, and a parabola through two points is no parabola
    import warnings

    mode, se = 0.005, 0.004
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        best, curvature, values = profile_maximum(lambda v: -0.5 * ((v - mode) / se) ** 2, 0.2, 0.0175, -0.2, 0.2)
    assert best == pytest.approx(mode, abs=PROFILE_SE_SHARE * se)
    assert curvature == pytest.approx(-0.5 / se**2, rel=1e-6)


def test_a_flat_profile_stops_where_it_started():
    seen = []
    best, curvature, values = profile_maximum(lambda v: seen.append(v) or -3.0, 0.0, SCALE, -0.2, 0.2)
    assert best in (0.0, -SCALE, SCALE) and curvature == pytest.approx(0.0, abs=1e-6)
    assert len(seen) == 3 and all(np.isfinite(seen))
