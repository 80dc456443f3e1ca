"""Starting noise levels measured without the model (the fit re-estimates them from there)."""

import numpy as np

from adcpdyn.estimators.noise_guess import range_noise_from_differences


def test_slant_range_noise_is_read_from_first_differences_not_the_beds_shape():
    """Four beams over a bed 75 m down that slopes and differs between the beams by metres, with 0.4 m of
    white noise and a few dropouts: the level comes back within its sampling error (about 3 %), the
    bed's shape and the beams' offsets left out."""
    rng = np.random.default_rng(3)
    t = np.arange(2000) * 1.3
    bed = 75.0 + 5.0 * np.sin(2 * np.pi * t / 900.0)[:, None] + np.array([2.4, -1.9, -2.1, 1.6])[None, :]
    ranges = bed + rng.normal(0.0, 0.4, bed.shape)
    ranges[rng.random(bed.shape) < 0.05] = np.nan
    level = range_noise_from_differences(ranges)
    assert abs(level / 0.4 - 1.0) < 0.08
    assert np.nanstd(ranges - np.nanmean(ranges, axis=1, keepdims=True)) > 4 * level  # what a spread about the mean would give


def test_too_few_ranges_start_from_two_centimetres():
    assert range_noise_from_differences(np.full((30, 4), np.nan)) == 0.02
    assert range_noise_from_differences(np.ones((5, 4))) == 0.02
