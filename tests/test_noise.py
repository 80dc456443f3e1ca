"""Coloured (AR(1)) measurement noise: stated lag-1 autocorrelation and the white case's variance."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from adcpdyn.cases.scenario import Noise, get_scenario
from adcpdyn.models.sensors import ar1_noise
from adcpdyn.cases.simulation import simulate


def lag1(x) -> float:
    x = np.asarray(x, dtype=float) - np.mean(x)
    return float(np.sum(x[1:] * x[:-1]) / np.sum(x * x))


@pytest.mark.parametrize("rho", [0.5, 0.9, -0.4])
def test_ar1_has_the_stated_autocorrelation_and_unit_variance(rho):
    w = np.random.default_rng(3).normal(size=(200_000, 2))
    e = ar1_noise(w, rho)
    for j in range(2):
        # standard errors: lag-1 ~ (1 - rho^2) / sqrt(n); variance ~ sqrt(2 (1 + rho^2) / (1 - rho^2) / n)
        assert abs(lag1(e[:, j]) - rho) < 5 * (1 - rho**2) / np.sqrt(w.shape[0])
        assert abs(np.var(e[:, j]) - 1.0) < 5 * np.sqrt(2 * (1 + rho**2) / (1 - rho**2) / w.shape[0])
    # the recursion itself, written out
    assert e[0, 0] == w[0, 0]
    assert np.allclose(e[1:, 0], rho * e[:-1, 0] + np.sqrt(1 - rho**2) * w[1:, 0], atol=1e-12)


def test_white_is_returned_unchanged():
    w = np.random.default_rng(1).normal(size=(10, 4))
    assert ar1_noise(w, 0.0) is w


@pytest.mark.parametrize("rho", [1.0, -1.0, 1.5])
def test_bad_autocorrelation_rejected(rho):
    with pytest.raises(ValueError, match="rho"):
        ar1_noise(np.zeros(5), rho)
    with pytest.raises(ValueError, match="noise.bt_ar1"):
        Noise(bt_ar1=rho)


def _long(noise: Noise):
    sc = get_scenario("diag_boat")
    return dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=400.0, noise=noise))


def test_simulated_noise_is_coloured_with_the_white_variance():
    """The same seed with and without noise: the difference is the noise itself."""
    quiet = Noise(bt_m_s=0.0, bt_fraction=0.0, reference_m_s=0.0)
    rho_bt, rho_ref, sigma = 0.7, 0.8, 0.01
    noisy = dataclasses.replace(quiet, bt_m_s=sigma, reference_m_s=sigma, bt_ar1=rho_bt, reference_ar1=rho_ref)
    a, b = simulate(_long(quiet), seed=5), simulate(_long(noisy), seed=5)
    d_bt = b.pings.bt_radial_m_s - a.pings.bt_radial_m_s
    d_ref = b.reference.velocity_m_s - a.reference.velocity_m_s
    n_bt, n_ref = d_bt.shape[0], d_ref.shape[0]
    for j in range(4):
        assert abs(lag1(d_bt[:, j]) - rho_bt) < 4 * (1 - rho_bt**2) / np.sqrt(n_bt) + 4.0 / n_bt
        assert abs(np.std(d_bt[:, j]) / sigma - 1) < 0.25
    for j in range(3):
        assert abs(lag1(d_ref[:, j]) - rho_ref) < 4 * (1 - rho_ref**2) / np.sqrt(n_ref) + 4.0 / n_ref
        assert abs(np.std(d_ref[:, j]) / sigma - 1) < 0.35
