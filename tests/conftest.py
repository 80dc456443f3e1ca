"""Shared problem builders."""

from __future__ import annotations

import dataclasses

import pytest

from adcpdyn.cases.scenario import Noise, get_scenario


def noise_free(scenario):
    """The same scenario with every noise and the sensor resolution set to zero."""
    zero = Noise(bt_m_s=0.0, bt_fraction=0.0, bt_dropout_probability=0.0, range_m=0.0, range_fraction=0.0,
                 water_m_s=0.0, tilt_rad=0.0, heading_rad=0.0, attitude_resolution_rad=0.0, reference_m_s=0.0)
    return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, noise=zero))


def with_doppler(scenario, **changes):
    """The same scenario with some DopplerModel fields changed."""
    dm = dataclasses.replace(scenario.run.doppler, **changes)
    return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, doppler=dm))


@pytest.fixture(scope="session")
def pool_m0():
    return get_scenario("pool_m0")


@pytest.fixture(scope="session")
def pool_still():
    return get_scenario("pool_still")
