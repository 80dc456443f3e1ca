"""Tests of the case file reader/writer (``adcpdyn.cases.io``)."""

from __future__ import annotations

import dataclasses
import os

import h5py
import numpy as np
import pytest

from adcpdyn.cases import io as case_io
from adcpdyn.cases.case import (
    Attitude,
    Case,
    Environment,
    Instrument,
    Pings,
    Reference,
    Truth,
    Vessel,
    Water,
)
from adcpdyn.cases.checks import CaseFormatError
from adcpdyn.cases.io import read_case, write_case
from adcpdyn.cases.validation import validate_case
from fuzzlib import _del, _del_attr, _replace, _set_attr  # the malformed files' edits, one copy

N, M, K, L = 20, 15, 3, 10


def make_case() -> Case:
    rng = np.random.default_rng(1)
    a = float(np.deg2rad(20.0))
    dirs = np.array([[-np.sin(a), 0, np.cos(a)], [np.sin(a), 0, np.cos(a)],
                     [0, np.sin(a), np.cos(a)], [0, -np.sin(a), np.cos(a)]])
    bt = rng.normal(0.0, 0.5, (N, 4))
    bt[3, 1] = np.nan
    bt[7, :] = np.nan
    tm = np.linspace(0.0, 19.0, M) + 0.1
    radial = rng.normal(0.0, 0.3, (N, 4, K))
    radial[5, 2, 1] = np.nan
    return Case(
        name="unit",
        description="hand-made test case",
        instrument=Instrument(beam_angle_rad=a, transducer_radius_m=0.05,
                              frequency_hz=600e3, sound_speed_m_s=1500.0,
                              beam_dirs_t=dirs),
        environment=Environment(water_depth_m=30.0, transducer_depth_m=1.2,
                                water_depth_per_ping_m=np.linspace(29.0, 31.0, N)),
        vessel=Vessel(length_m=12.0, mass_kg=8000.0),
        pings=Pings(time_s=np.arange(N, dtype=float),
                    bt_radial_m_s=bt,
                    bt_range_m=np.full((N, 4), 30.0)),
        water=Water(cell_depth_m=np.array([4.0, 6.0, 8.0]), radial_m_s=radial),
        attitude=Attitude(time_s=tm,
                          heading_rad=np.linspace(0.0, 6.0, M),
                          pitch_rad=0.03 * np.sin(tm),
                          roll_rad=0.05 * np.cos(tm),
                          frame="transducer"),
        reference=Reference(time_s=np.linspace(0.0, 19.0, L),
                            velocity_m_s=np.column_stack([np.full(L, 2.0), np.zeros(L),
                                                          np.r_[np.nan, np.zeros(L - 1)]]),
                            point_body_m=np.array([1.0, 0.0, -2.0])),
        truth=Truth(radius_vectors_m=rng.normal(size=(4, 3)),
                    installation_ypr_rad=np.array([0.7, 0.01, -0.02]),
                    vessel_velocity_m_s=rng.normal(size=(N, 3)),
                    water_velocity_m_s=rng.normal(size=(N, K, 3)),
                    effects=[],
                    extra_attrs={"seed": "1", "simulator": "hand"}),
    )


@pytest.fixture
def case() -> Case:
    return make_case()


@pytest.fixture
def case_file(case, tmp_path):
    path = tmp_path / "case.h5"
    write_case(case, path)
    return path


def assert_same(a, b, where="case"):
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype == np.float64, where
        assert a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=True), where
    else:
        assert a == b, where
        assert type(a) is type(b) or a is None, where


def test_round_trip_bit_for_bit(case, tmp_path):
    p1, p2 = tmp_path / "a.h5", tmp_path / "b.h5"
    write_case(case, p1)
    back = read_case(p1)
    assert_same(case, back)
    assert np.isnan(back.pings.bt_radial_m_s[3, 1])
    assert np.isnan(back.pings.bt_radial_m_s[7]).all()
    write_case(back, p2)
    assert_same(back, read_case(p2))


def test_round_trip_minimal(case, tmp_path):
    minimal = case.replace(vessel=Vessel(), water=None, reference=None, truth=None,
                           instrument=dataclasses.replace(case.instrument, beam_dirs_t=None))
    write_case(minimal, tmp_path / "m.h5")
    with h5py.File(tmp_path / "m.h5") as f:
        assert "vessel" not in f and "truth" not in f and "water" not in f
        assert f.attrs["version"] == 1 and f.attrs["format"] == "adcp-case"
    assert_same(minimal, read_case(tmp_path / "m.h5"))


def test_hand_written_file(tmp_path):
    path = tmp_path / "other.h5"
    t = np.arange(5.0)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = np.bytes_(b"adcp-case")
        f.attrs["version"] = np.int32(1)
        f.attrs["name"] = b"from-another-simulator"
        g = f.create_group("instrument")
        g.attrs.update(beam_angle_rad=0.35, transducer_radius_m=0.1, frequency_hz=3e5,
                       sound_speed_m_s=1480.0, n_beams=np.int16(4), layout=b"janus4")
        g = f.create_group("environment")
        g.attrs.update(water_depth_m=12, transducer_depth_m=0.5)
        g = f.create_group("pings")
        g["time_s"] = t.astype(np.float32)
        g["bt_radial_m_s"] = np.ones((5, 4), dtype=np.float32)
        g = f.create_group("attitude")
        g["time_s"] = t
        for k in ("heading_rad", "pitch_rad", "roll_rad"):
            g[k] = np.zeros(5)
        g.attrs["frame"] = b"vessel"
        f.create_group("reference").attrs["stationary"] = 1
    c = read_case(path)
    assert c.name == "from-another-simulator" and c.description == ""
    assert c.vessel == Vessel() and c.truth is None and c.water is None
    assert c.reference.stationary is True and c.reference.time_s is None
    assert c.reference.velocity_m_s is None
    assert np.array_equal(c.reference.point_body_m, np.zeros(3))
    assert c.pings.time_s.dtype == np.float64 and c.pings.bt_radial_m_s.dtype == np.float64
    assert c.instrument.n_beams == 4 and c.instrument.layout == "janus4"
    assert c.attitude.frame == "vessel" and c.environment.water_depth_m == 12.0
    write_case(c, tmp_path / "again.h5")
    assert_same(c, read_case(tmp_path / "again.h5"))


def test_unknown_groups_and_attrs_ignored(case, case_file):
    with h5py.File(case_file, "r+") as f:
        f.attrs["producer"] = "someone else"
        f.create_group("extras/deep")["x"] = np.arange(3)
        f["pings"].attrs["note"] = 3.5
        f["pings"]["snr_db"] = np.zeros((N, 4))
        f["instrument"].attrs["serial"] = b"A123"
        f["truth"].attrs["scale"] = np.array([1.0, 2.0])
    back = read_case(case_file)
    assert_same(case.replace(truth=None), back.replace(truth=None))
    assert back.truth.extra_attrs == {"seed": "1", "simulator": "hand", "scale": "[1.0, 2.0]"}


def _set_item(index, value):
    def fn(a):
        a = a.copy()
        a[index] = value
        return a
    return fn


MALFORMED = {
    "missing /pings": (_del("pings"), "/pings"),
    "missing /environment": (_del("environment"), "/environment"),
    "missing bt_radial": (_del("pings/bt_radial_m_s"), "/pings/bt_radial_m_s"),
    "missing instrument attr": (_del_attr("instrument", "frequency_hz"),
                                '/instrument.attrs["frequency_hz"]'),
    "bt_radial (N, 3)": (_replace("pings/bt_radial_m_s", lambda a: a[:, :3]),
                         "/pings/bt_radial_m_s"),
    "pitch wrong shape": (_replace("attitude/pitch_rad", lambda a: a[:-1]),
                          "/attitude/pitch_rad"),
    "ping time not increasing": (_replace("pings/time_s", _set_item(5, 3.5)),
                                 "/pings/time_s"),
    "ping time NaN": (_replace("pings/time_s", _set_item(0, np.nan)), "/pings/time_s"),
    "duplicate attitude time": (_replace("attitude/time_s", lambda a: np.r_[a[0], a[:-1]]),
                                "/attitude/time_s"),
    "roll in degrees": (_replace("attitude/roll_rad", np.rad2deg), "/attitude/roll_rad"),
    "heading in degrees": (_replace("attitude/heading_rad", _set_item(0, 350.0)),
                           "/attitude/heading_rad"),
    "pitch Inf": (_replace("attitude/pitch_rad", _set_item(2, np.inf)), "/attitude/pitch_rad"),
    "pitch all NaN": (_replace("attitude/pitch_rad", lambda a: np.full_like(a, np.nan)), "/attitude/pitch_rad"),
    "beam angle in degrees": (_set_attr("instrument", "beam_angle_rad", 30.0),
                              '/instrument.attrs["beam_angle_rad"]'),
    "n_beams 3": (_set_attr("instrument", "n_beams", 3), '/instrument.attrs["n_beams"]'),
    "layout": (_set_attr("instrument", "layout", "piston5"), '/instrument.attrs["layout"]'),
    "all-NaN beam 2": (_replace("pings/bt_radial_m_s", _set_item((slice(None), 1), np.nan)),
                       "/pings/bt_radial_m_s"),
    "wrong format name": (_set_attr("/", "format", "adcp-caze"), '/.attrs["format"]'),
    "wrong version": (_set_attr("/", "version", 2), '/.attrs["version"]'),
    "bad attitude frame": (_set_attr("attitude", "frame", "ned"), '/attitude.attrs["frame"]'),
    "moving reference without velocity": (_del("reference/velocity_m_s"),
                                          "/reference/velocity_m_s"),
    "water radial wrong shape": (_replace("water/radial_m_s", lambda a: a[:, :, :-1]),
                                 "/water/radial_m_s"),
    "negative sound speed": (_set_attr("instrument", "sound_speed_m_s", -1500.0),
                             '/instrument.attrs["sound_speed_m_s"]'),
    "zero water depth": (_set_attr("environment", "water_depth_m", 0.0),
                         '/environment.attrs["water_depth_m"]'),
    "beam dirs not unit": (_replace("instrument/beam_dirs_t", lambda a: 2 * a),
                           "/instrument/beam_dirs_t"),
    "installation ypr in degrees": (_replace("truth/installation_ypr_rad", np.rad2deg),
                                    "/truth/installation_ypr_rad"),
    "effects not JSON": (_set_attr("truth", "effects", "[{"), '/truth.attrs["effects"]'),
    "string dataset": (_replace("pings/time_s", lambda a: np.array([b"x"] * len(a))),
                       "/pings/time_s"),
    # what no instrument records
    "sound speed 1e-3 m/s": (_set_attr("instrument", "sound_speed_m_s", 1e-3), '/instrument.attrs["sound_speed_m_s"]'),
    "beam angle 89 deg": (_set_attr("instrument", "beam_angle_rad", np.deg2rad(89.0)),
                          '/instrument.attrs["beam_angle_rad"]'),
    "transducer radius 1e6 m": (_set_attr("instrument", "transducer_radius_m", 1e6),
                                '/instrument.attrs["transducer_radius_m"]'),
    "identical beam directions": (_replace("instrument/beam_dirs_t", lambda a: np.tile(a[:1], (4, 1))),
                                  "/instrument/beam_dirs_t"),
    "beams in one plane": (_replace("instrument/beam_dirs_t", lambda a: a[[0, 1, 0, 1]]), "/instrument/beam_dirs_t"),
    "beam pointing sideways": (_replace("instrument/beam_dirs_t", _set_item(2, [0.0, 1.0, 0.0])),
                               "/instrument/beam_dirs_t"),
    "bt radial above the sound speed": (_replace("pings/bt_radial_m_s", _set_item((2, 1), 1600.0)),
                                        "/pings/bt_radial_m_s"),
    "bt radial 1e303": (_replace("pings/bt_radial_m_s", _set_item((4, 0), -1e303)), "/pings/bt_radial_m_s"),
    "water radial 1e3": (_replace("water/radial_m_s", _set_item((1, 1, 1), 1e3)), "/water/radial_m_s"),
    "reference velocity 1e303": (_replace("reference/velocity_m_s", _set_item((1, 0), 1e303)),
                                 "/reference/velocity_m_s"),
    "transducer below the bed": (_set_attr("environment", "transducer_depth_m", 40.0),
                                 '/environment.attrs["transducer_depth_m"]'),
    "water 1e5 m deep": (_set_attr("environment", "water_depth_m", 1e5), '/environment.attrs["water_depth_m"]'),
    "bed above the transducer at one ping": (_replace("environment/water_depth_m", _set_item(3, 1.0)),
                                             "/environment/water_depth_m"),
    "negative slant range": (_replace("pings/bt_range_m", _set_item((1, 1), -3.0)), "/pings/bt_range_m"),
    "slant range 1e303": (_replace("pings/bt_range_m", _set_item((1, 1), 1e303)), "/pings/bt_range_m"),
    "cell above the transducer": (_replace("water/cell_depth_m", _set_item(0, 0.5)), "/water/cell_depth_m"),
    "cell above the surface": (_replace("water/cell_depth_m", _set_item(0, -2.0)), "/water/cell_depth_m"),
    "cell below the bed": (_replace("water/cell_depth_m", _set_item(2, 40.0)), "/water/cell_depth_m"),
    "no cells": (lambda f: (_replace("water/cell_depth_m", lambda a: a[:0])(f),
                            _replace("water/radial_m_s", lambda a: a[:, :, :0])(f)), "/water/cell_depth_m"),
    "attitude 1000 s after the pings": (_replace("attitude/time_s", lambda a: a + 1000.0), "/attitude/time_s"),
    "reference 1e4 s after the pings": (_replace("reference/time_s", lambda a: a + 1e4), "/reference/time_s"),
    "reference 1e3 s before the pings": (_replace("reference/time_s", lambda a: a - 1e3), "/reference/time_s"),
}


@pytest.mark.parametrize("kind", list(MALFORMED))
def test_malformed_file_rejected(case_file, kind):
    edit, field = MALFORMED[kind]
    with h5py.File(case_file, "r+") as f:
        edit(f)
    with pytest.raises(CaseFormatError) as info:
        read_case(case_file)
    msg = str(info.value)
    assert msg.startswith(f"{case_file}: {field}: "), msg
    assert "\n" not in msg and "\r" not in msg
    if kind == "all-NaN beam 2":
        assert "beam 2" in msg
    if kind == "bad attitude frame":
        assert '"vessel"' in msg and '"transducer"' in msg
    if kind == "bt_radial (N, 3)":
        assert f"N={N}" in msg and "(20, 3)" in msg


def test_not_hdf5(tmp_path):
    path = tmp_path / "junk.h5"
    path.write_text("not hdf5\nat all\n")
    with pytest.raises(CaseFormatError) as info:
        read_case(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_validate_in_memory(case):
    validate_case(case)
    bad = case.replace(instrument=dataclasses.replace(case.instrument, n_beams=3))
    with pytest.raises(CaseFormatError, match=r'^<memory>: /instrument\.attrs\["n_beams"\]'):
        validate_case(bad)


def test_write_is_atomic(case, case_file, tmp_path):
    assert os.listdir(tmp_path) == ["case.h5"]
    write_case(case, case_file)  # overwrite in place
    assert os.listdir(tmp_path) == ["case.h5"]


def test_write_invalid_leaves_nothing(case, case_file, tmp_path):
    bad = case.replace(attitude=dataclasses.replace(case.attitude,
                                                    roll_rad=np.rad2deg(case.attitude.roll_rad)))
    with pytest.raises(CaseFormatError, match="/attitude/roll_rad"):
        write_case(bad, tmp_path / "new.h5")
    with pytest.raises(CaseFormatError):
        write_case(bad, case_file)
    assert os.listdir(tmp_path) == ["case.h5"]
    assert_same(case, read_case(case_file))  # old file untouched


def test_failed_replace_cleans_up(case, tmp_path, monkeypatch):
    def boom(src, dst):
        raise OSError("disk on fire")

    monkeypatch.setattr(case_io.os, "replace", boom)
    with pytest.raises(OSError, match="disk on fire"):
        write_case(case, tmp_path / "x.h5")
    assert os.listdir(tmp_path) == []
