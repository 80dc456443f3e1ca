"""Shared problem builders."""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path

import numpy as np
import pytest

from adcpdyn.cases.scenario import Noise, get_scenario


def noise_free(scenario):
    """The same scenario with every noise and the sensor resolution set to zero."""
    zero = Noise(bt_m_s=0.0, bt_fraction=0.0, bt_dropout_probability=0.0, range_m=0.0, range_fraction=0.0,
                 water_m_s=0.0, tilt_rad=0.0, heading_rad=0.0, attitude_resolution_rad=0.0, reference_m_s=0.0)
    return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, noise=zero))


def refit_without(A, y, train):
    """The closed form a leave-fold-out prediction must equal: the linear least-squares refit on the
    ``train`` rows, its residuals on the others over sqrt(1 + h), h = a (A_t^T A_t)^-1 a^T."""
    out = ~train
    x = np.linalg.lstsq(A[train], y[train], rcond=None)[0]
    h = np.einsum("ij,jk,ik->i", A[out], np.linalg.inv(A[train].T @ A[train]), A[out])
    return (A[out] @ x - y[out]) / np.sqrt(1 + h)


def with_doppler(scenario, **changes):
    """The same scenario with some DopplerModel fields changed."""
    dm = dataclasses.replace(scenario.run.doppler, **changes)
    return dataclasses.replace(scenario, run=dataclasses.replace(scenario.run, doppler=dm))


@pytest.fixture(autouse=True)
def _no_default_attribution(monkeypatch):
    """A survey office's ADCPDYN_ATTRIBUTION would change every netCDF export the tests check: unset unless a
    test sets it."""
    monkeypatch.delenv("ADCPDYN_ATTRIBUTION", raising=False)


@pytest.fixture(scope="session")
def pool_m0():
    return get_scenario("pool_m0")


@pytest.fixture(scope="session")
def pool_still():
    return get_scenario("pool_still")


def shortened(case, seconds):
    """The first ``seconds`` of a case: pings, attitude, reference and truth rows cut alike."""
    import numpy as np

    p, a = case.pings, case.attitude
    k = p.time_s <= p.time_s[0] + seconds
    m = a.time_s <= p.time_s[0] + seconds
    changes = {
        "pings": dataclasses.replace(p, time_s=p.time_s[k], bt_radial_m_s=p.bt_radial_m_s[k],
                                     bt_range_m=None if p.bt_range_m is None else p.bt_range_m[k]),
        "attitude": dataclasses.replace(a, time_s=a.time_s[m], heading_rad=a.heading_rad[m], pitch_rad=a.pitch_rad[m],
                                        roll_rad=a.roll_rad[m]),
    }
    env = case.environment
    if env.water_depth_per_ping_m is not None:
        changes["environment"] = dataclasses.replace(env, water_depth_per_ping_m=env.water_depth_per_ping_m[k])
    if case.water is not None:
        changes["water"] = dataclasses.replace(case.water, radial_m_s=case.water.radial_m_s[k])
    r = case.reference
    if r is not None and r.time_s is not None:
        j = r.time_s <= p.time_s[0] + seconds
        changes["reference"] = dataclasses.replace(r, time_s=r.time_s[j],
                                                   velocity_m_s=None if r.velocity_m_s is None else r.velocity_m_s[j])
    if case.truth is not None:
        t = case.truth
        changes["truth"] = dataclasses.replace(t, vessel_velocity_m_s=t.vessel_velocity_m_s[k],
                                               water_velocity_m_s=None if t.water_velocity_m_s is None
                                               else t.water_velocity_m_s[k])
    assert np.any(k)
    return case.replace(**changes)


REAL = Path(os.environ.get("ADCPDYN_REAL_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real"))


def real(name: str) -> Path:
    """A shared real instrument file, or a skip where it (or the reader) is absent."""
    path = REAL / name
    if not path.is_file():
        pytest.skip(f"{path} absent")
    pytest.importorskip("mhkit")
    return path


@functools.lru_cache(maxsize=None)
def _dolfyn_dataset(path: Path):
    from adcpdyn.cases.importers.reader import read_dolfyn

    return read_dolfyn(path)[0]


def dolfyn_dataset(name: str):
    """dolfyn's dataset of a real file by name, read once per test process; not to be modified
    (:func:`dolfyn_reference.dolfyn_earth` works on a deep copy)."""
    return _dolfyn_dataset(real(name))


@pytest.fixture(scope="module")
def imported():
    """import_file of a real file by name, once per test module."""
    from adcpdyn.cases.importers import import_file

    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = import_file(real(name))
        return cache[name]

    return get


def assert_provenance(calib, h5, nc, m0, m1, m0_path=None) -> None:
    """CALIB.json, a corrected HDF5 and a netCDF written under umask 027 from pool_m0 / pool_m1
    record the version, the source cases and their SHA-256, and the calibration applied."""
    import json

    import h5py

    import adcpdyn
    from adcpdyn.cases.hashing import sha256_of

    for p in (calib, h5, nc):
        assert p.stat().st_mode & 0o777 == 0o640, p.name  # the umask's permissions, not 0600
    prov = json.loads(calib.read_text())["provenance"]
    assert prov["adcpdyn_version"] == adcpdyn.__version__ and prov["written_utc"].endswith("Z")
    assert prov["cases"][0]["name"] == "pool_m0" and prov["cases"][0]["sha256"] == sha256_of(m0)
    if m0_path is not None:
        assert prov["cases"][0]["path"] == str(m0_path)
    with h5py.File(h5, "r") as f:
        assert f.attrs["adcpdyn_version"] == adcpdyn.__version__ and "written_utc" in f.attrs
        g = f["corrected"]
        assert g.attrs["source_case_sha256"] == sha256_of(m1) and g.attrs["source_case_name"] == "pool_m1"
        settings = json.loads(g.attrs["settings"])
    assert settings["calibration_file"] == str(calib) and settings["calibration_sha256"] == sha256_of(calib)
    assert settings["calibration_provenance"]["cases"][0]["sha256"] == sha256_of(m0)
    for key in ("heading_misalignment_applied_rad", "magnetic_declination_rad", "moving_bed_velocity_m_s"):
        assert key in settings, key  # recorded, null when none applied
    xr = pytest.importorskip("xarray")
    with xr.open_dataset(nc, engine="h5netcdf") as ds:
        a = ds.attrs
        assert a["adcpdyn_version"] == adcpdyn.__version__ and a["source_case"] == "pool_m1"
        assert a["source_case_sha256"] == sha256_of(m1) and a["calibration_sha256"] == sha256_of(calib)
        assert a["processing_method"] == "asc"
        for key in ("heading_misalignment_deg", "magnetic_declination_deg", "moving_bed_velocity_north_east_m_s"):
            assert key in a, key


def calibrated_pool_m0(folder, n_starts: int):
    """pool_m0 (seed 1) calibrated with ``n_starts`` starts and its CALIB.json in ``folder``."""
    import warnings

    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.cases.simulation import simulate
    from adcpdyn.estimators.calibration.config import CalibrationConfig
    from adcpdyn.estimators.calibration.problem import CalibrationProblem

    m0 = simulate(get_scenario("pool_m0"), seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = CalibrationProblem(m0, CalibrationConfig(n_starts=n_starts)).solve()
    path = folder / "CALIB.json"
    result.to_json(path)
    return result, path, m0


def without_pings(case, drop):
    """``case`` without the pings where ``drop`` is True (every per-ping array cut alike) and without its
    water profile (whose cells must lie above the kept pings' beds)."""
    keep, n = ~np.asarray(drop), case.pings.n

    def cut(group):
        per_ping = {f.name: getattr(group, f.name)[keep] for f in dataclasses.fields(group)
                    if isinstance(getattr(group, f.name), np.ndarray) and getattr(group, f.name).shape[:1] == (n,)}
        return dataclasses.replace(group, **per_ping)

    return case.replace(pings=cut(case.pings), water=None, environment=cut(case.environment))
