"""The one-pass Lomb-Scargle periodogram against scipy's (an independent implementation)."""

import numpy as np
from scipy.signal import lombscargle

from adcpdyn.estimators.statistics.periodogram import FREQUENCY_BLOCK, lomb_scargle


def test_lomb_scargle_equals_scipys_per_column_on_irregular_samples():
    rng = np.random.default_rng(7)
    t = 1e4 + np.sort(rng.random(700)) * 1200.0  # irregular, far from the clock's zero
    y = rng.standard_normal((700, 3)) + np.column_stack([np.sin(0.9 * t), 0.2 * np.cos(5.1 * t + 1), np.zeros(700)])
    omega = np.linspace(0.05, 15.0, 3 * FREQUENCY_BLOCK + 17)  # several blocks and a remainder
    ours = lomb_scargle(t, y, omega)
    theirs = np.column_stack([lombscargle(t, y[:, j], omega) for j in range(3)])
    assert ours.shape == (omega.size, 3)
    assert np.max(np.abs(ours - theirs)) < 1e-10 * np.max(theirs)
    assert np.argmax(ours[:, 0]) == np.argmin(np.abs(omega - 0.9)) and np.argmax(ours[:, 1]) == np.argmin(np.abs(omega - 5.1))
    one = lomb_scargle(t, y[:, 1], omega[:40])
    assert one.shape == (40,) and np.allclose(one, theirs[:40, 1], rtol=1e-10, atol=0)


def test_lomb_scargle_at_the_nyquist_of_regular_samples():
    """Where every sample sits on a zero of the sine (the sin^2 sum vanishes), the guard keeps the cosine part."""
    t = np.arange(100) * 0.5
    y = np.cos(2 * np.pi * t) + 0.1
    omega = np.array([2 * np.pi, 1.0, 4 * np.pi])
    assert np.allclose(lomb_scargle(t, y, omega), lombscargle(t, y, omega), rtol=1e-11, atol=0)
    assert abs(lomb_scargle(t, y, omega)[0] - 50.0) < 1e-9  # 0.5 * (sum y cos)^2 / sum cos^2 = 0.5 * 100^2 / 100


def test_info_dominant_period_is_sought_below_the_samples_nyquist():
    """One attitude sample per 0.67-s ping (a few per cent of jitter) and a 9-s roll: the info
    summary finds 9 s, not an above-Nyquist alias of the jitter; a record too coarse for the band
    gives NaN."""
    from adcpdyn.cases.summary import dominant_period_s, sampled_nyquist_hz

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.53, 0.90, 272))
    x = np.deg2rad(1.0) * np.sin(2 * np.pi * t / 9.0) + np.deg2rad(0.3) * rng.standard_normal(t.size)
    assert abs(dominant_period_s(t, x) - 9.0) < 0.3
    assert 1.0 / dominant_period_s(t, rng.standard_normal(t.size)) <= sampled_nyquist_hz(t)  # noise: never above
    assert np.isnan(dominant_period_s(np.arange(20) * 30.0, rng.standard_normal(20)))  # Nyquist 0.017 Hz < 0.02
