"""`adcpdyn info`'s error-velocity line: what no rigid velocity explains, and the beam noise it implies."""

import numpy as np

from adcpdyn.cases.summary import error_velocity_levels
from adcpdyn.models.janus import janus_beam_directions


def test_rigid_velocities_leave_no_error_velocity():
    B = np.asarray(janus_beam_directions(np.deg2rad(20.0)))
    v = np.random.default_rng(1).normal(0.0, 1.0, (500, 3))
    rms, beam, used = error_velocity_levels(v @ B.T, B)
    assert used == 500 and rms < 1e-12 and beam < 1e-12


def test_beam_noise_is_read_back_from_the_error_velocity():
    """Independent beam noise of 0.03 m/s on rigid velocities: the per-beam level comes back within
    its sampling error (4000 pings: about 1 %), three-beam pings left out."""
    rng = np.random.default_rng(2)
    B = np.asarray(janus_beam_directions(np.deg2rad(30.0)))
    radial = rng.normal(0.0, 1.0, (4000, 3)) @ B.T + rng.normal(0.0, 0.03, (4000, 4))
    radial[:100, 2] = np.nan
    rms, beam, used = error_velocity_levels(radial, B)
    assert used == 3900
    assert abs(beam / 0.03 - 1.0) < 0.04
    assert abs(rms / beam - 1.0 / (np.sqrt(2.0) * np.sin(np.deg2rad(30.0)))) < 1e-9  # RDI's error row, |e|
