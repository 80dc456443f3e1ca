"""Malformed inputs for every verb: case files, calibration files and instrument files.

Each variant is a file made from a valid one by one fault, with what a right answer is:

* ``ok``: the input is valid (the format allows it): exit status 0 with sane results;
* ``error``: the input is malformed or impossible: exit status 2 with one line on stderr
  naming one of ``fields``;
* ``either``: odd but defensible both ways (e.g. an optional group emptied): one of the two.

:func:`run` runs a verb in this process (``adcpdyn.cli.main``) and :func:`judge` says
what is wrong with its outcome, if anything: a traceback, a crash, exit 0 with NaN or
absurd velocities, an error of more than one line or not naming the field, a partial
or temporary file left behind.

``python tests/fuzzlib.py FOLDER`` runs everything and prints the table of outcomes.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import json
import random
import sys
import traceback
from pathlib import Path

import h5py
import numpy as np

SANE_M_S = 20.0  # no vessel in these cases (nor any ADCP survey) moves faster
TMP_TAG = ".adcpdyn-tmp-"


@dataclasses.dataclass
class Variant:
    name: str
    path: Path
    expect: str  # ok | error | either
    fields: tuple = ()  # an error must name one of these


@dataclasses.dataclass
class Outcome:
    code: int | None
    out: str
    err: str
    traceback: str | None = None


# ------------------------------------------------------------------------- base files
def base_files(folder: Path) -> dict:
    """Small valid inputs: a pool case with reference and truth (head sensor) and its
    calibration, a deep-ship case (vessel-frame sensor, installation angles) and its
    calibration, a deep-water case with a water profile."""
    import warnings

    from conftest import shortened

    from adcpdyn.cases.io import write_case
    from adcpdyn.cases.scenario import get_scenario
    from adcpdyn.estimators.calibration.config import CalibrationConfig
    from adcpdyn.estimators.calibration.problem import CalibrationProblem
    from adcpdyn.cases.simulation import simulate

    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for name, scenario, seconds in (("pool", "pool_m1", 20.0), ("ship", "deep_ship", 30.0), ("ocean", "deep_ocean", 15.0)):
        out[name] = folder / f"{name}.h5"
        sc = get_scenario(scenario)  # simulated for a little longer than kept: deep_ocean's whole run takes seconds
        sc = dataclasses.replace(sc, run=dataclasses.replace(sc.run, duration_s=min(sc.run.duration_s, seconds + 10.0)))
        write_case(shortened(simulate(sc, seed=1), seconds), out[name])
    for name, scenario, seconds in (("calib_pool", "pool_m0", 30.0), ("calib_ship", "deep_ship", 30.0)):
        out[name] = folder / f"{name}.json"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            calib = CalibrationProblem(shortened(simulate(get_scenario(scenario), seed=2), seconds),
                                       CalibrationConfig(n_starts=1)).solve()
        calib.to_json(out[name])
    return out


# ------------------------------------------------------------------------- case variants
def _attr_name(group, name):
    return f'{group}.attrs["{name}"]'


# (path, required, NaN allowed somewhere in it)
DATASETS = [
    ("/pings/time_s", True, False),
    ("/pings/bt_radial_m_s", True, True),
    ("/pings/bt_range_m", False, True),
    ("/attitude/time_s", True, False),
    ("/attitude/heading_rad", True, True),
    ("/attitude/pitch_rad", True, True),
    ("/attitude/roll_rad", True, True),
    ("/reference/time_s", True, False),  # required while /reference/velocity_m_s is there
    ("/reference/velocity_m_s", True, True),
    ("/truth/vessel_velocity_m_s", True, False),
    ("/truth/radius_vectors_m", True, False),
    ("/truth/installation_ypr_rad", True, False),
]
WATER_DATASETS = [("/water/cell_depth_m", True, False), ("/water/radial_m_s", True, True)]

# (group, attribute, required, zero allowed, negative allowed)
ATTRS = [
    ("/", "format", True, None, None),
    ("/", "version", True, False, False),
    ("/instrument", "beam_angle_rad", True, False, False),
    ("/instrument", "transducer_radius_m", True, True, False),
    ("/instrument", "frequency_hz", True, False, False),
    ("/instrument", "sound_speed_m_s", True, False, False),
    ("/instrument", "n_beams", True, False, False),
    ("/instrument", "layout", True, None, None),
    ("/environment", "water_depth_m", True, False, False),
    ("/environment", "transducer_depth_m", True, True, False),
    ("/attitude", "frame", True, None, None),
    ("/reference", "point_body_m", False, True, True),
    ("/reference", "stationary", False, True, False),
]


def _edit(src: Path, dst: Path, fn) -> Path:
    dst.write_bytes(src.read_bytes())
    with h5py.File(dst, "r+") as f:
        fn(f)
    return dst


def _replace(path, fn):
    def edit(f):
        data = fn(f[path][()])
        del f[path]
        f[path] = data
    return edit


def _set_attr(group, name, value):
    def edit(f):
        f[group].attrs[name] = value
    return edit


def _del(path):
    def edit(f):
        del f[path]
    return edit


def _del_attr(group, name):
    def edit(f):
        del f[group].attrs[name]
    return edit


def _at(index, value):
    def fn(a):
        a = np.array(a, dtype=float)
        a[index] = value
        return a
    return fn


def _dataset_faults(path: str, required: bool, nan_ok: bool, ndim: int):
    """(fault, edit, expect) for one dataset."""
    is_time = path.endswith("time_s")
    mid = (1,) * ndim
    yield "missing", _del(path), "error" if required else "ok"
    yield "wrong shape", _replace(path, lambda a: a[..., :-1] if a.ndim > 1 else a[:-1]), "error"
    yield "extra axis", _replace(path, lambda a: a[..., None]), "error"
    yield "strings", _replace(path, lambda a: np.full(a.shape, b"x")), "error"
    yield "empty", _replace(path, lambda a: a[:0]), "error"
    yield "one NaN", _replace(path, _at(mid, np.nan)), "ok" if nan_ok else "error"
    yield "all NaN", _replace(path, lambda a: np.full(a.shape, np.nan)), "error" if not nan_ok else "either"
    yield "one Inf", _replace(path, _at(mid, np.inf)), "error"
    yield "1e303", _replace(path, _at(mid, 1e303)), "error"
    if is_time:
        yield "reversed", _replace(path, lambda a: a[::-1]), "error"
        yield "+1e3 s", _replace(path, lambda a: a + 1e3), "error"
        yield "+1e4 s", _replace(path, lambda a: a + 1e4), "error"
        yield "duplicate", _replace(path, lambda a: np.r_[a[:1], a[:-1]]), "error"
    elif path.endswith("_rad"):
        yield "degrees", _replace(path, np.rad2deg), "error"


def _attr_faults(group, name, required, zero_ok, negative_ok):
    field = _attr_name(group, name)
    yield "missing", _del_attr(group, name), ("error" if required else "ok"), (field,)
    if zero_ok is None:  # a string attribute
        yield "number", _set_attr(group, name, 3.0), "error", (field,)
        yield "wrong word", _set_attr(group, name, "something-else"), "error", (field,)
        return
    yield "string", _set_attr(group, name, "1.5"), "error", (field,)
    yield "NaN", _set_attr(group, name, np.nan), "error", (field,)
    yield "Inf", _set_attr(group, name, np.inf), "error", (field,)
    yield "1e303", _set_attr(group, name, 1e303), "error", (field,)
    yield "array", _set_attr(group, name, np.array([1.0, 2.0])), "error", (field,)
    if name != "point_body_m":
        yield "zero", _set_attr(group, name, 0.0), "ok" if zero_ok else "error", (field,)
        yield "negative", _set_attr(group, name, -1.0), "ok" if negative_ok else "error", (field,)


def case_variants(base: Path, folder: Path, water: bool = False) -> list[Variant]:
    """One variant per fault of every dataset and attribute of a case file (the water profile's
    only with ``water``), plus impossible physics and damaged files."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    stem = base.stem

    def add(name, edit, expect, fields):
        slug = "".join(ch if ch.isalnum() else "_" for ch in name)
        path = folder / f"{stem}__{slug}.h5"
        _edit(base, path, edit)
        out.append(Variant(f"{stem}: {name}", path, expect, tuple(fields)))

    with h5py.File(base, "r") as f:
        present = {p: f[p].ndim for p, *_ in DATASETS + WATER_DATASETS if p in f}
    datasets = WATER_DATASETS if water else DATASETS
    for path, required, nan_ok in datasets:
        if path not in present:
            continue
        related = {"/pings/time_s": ("/pings/",), "/attitude/time_s": ("/attitude/",),
                   "/reference/time_s": ("/reference/",), "/water/cell_depth_m": ("/water/",)}
        for fault, edit, expect in _dataset_faults(path, required, nan_ok, present[path]):
            # a shorter time axis is reported where the lengths disagree; /truth follows /pings
            fields = related.get(path, (path,)) + (("/truth/",) if path == "/pings/time_s" else ())
            if path == "/pings/time_s" and fault.endswith(" s"):  # shifted: the records no longer overlap
                fields += ("/attitude/time_s", "/reference/time_s")
            if path == "/water/radial_m_s" and fault == "all NaN":
                expect = "either"
            if path == "/reference/velocity_m_s" and fault == "all NaN":
                expect = "either"
            add(f"{path} {fault}", edit, expect, fields)
    if water:
        return out
    for group, name, *flags in ATTRS:
        for fault, edit, expect, fields in _attr_faults(group, name, *flags):
            add(f"{_attr_name(group, name)} {fault}", edit, expect, fields)

    g = "/instrument"
    phys = [  # what no instrument records (name, edit, field)
        ("bt radial above the sound speed", _replace("/pings/bt_radial_m_s", _at((2, 1), 2000.0)), "/pings/bt_radial_m_s"),
        ("beam angle 89 deg", _set_attr(g, "beam_angle_rad", np.deg2rad(89.0)), _attr_name(g, "beam_angle_rad")),
        ("beam angle 0.5 deg", _set_attr(g, "beam_angle_rad", np.deg2rad(0.5)), _attr_name(g, "beam_angle_rad")),
        ("sound speed 1e-3 m/s", _set_attr(g, "sound_speed_m_s", 1e-3), _attr_name(g, "sound_speed_m_s")),
        ("identical beam directions", lambda f: f[g].create_dataset("beam_dirs_t", data=np.tile([[0.5, 0, 0.8660254037844386]], (4, 1))),
         "/instrument/beam_dirs_t"),
        ("beam directions not unit", lambda f: f[g].create_dataset("beam_dirs_t", data=np.full((4, 3), 0.9)),
         "/instrument/beam_dirs_t"),
        ("transducer below the bed", _set_attr("/environment", "transducer_depth_m", 50.0),
         _attr_name("/environment", "transducer_depth_m")),
        ("water shallower than the transducer", _set_attr("/environment", "water_depth_m", 0.05),
         _attr_name("/environment", "transducer_depth_m")),
        ("negative slant range", _replace("/pings/bt_range_m", _at((1, 2), -4.0)), "/pings/bt_range_m"),
        ("per-ping bed above the transducer", lambda f: f["/environment"].create_dataset(
            "water_depth_m", data=np.full(f["/pings/time_s"].shape, 0.01)), "/environment/water_depth_m"),
        ("vessel 1e6 m long", lambda f: f.require_group("vessel").attrs.__setitem__("length_m", 1e6),
         _attr_name("/vessel", "length_m")),
        ("reference point 1e6 m away", _set_attr("/reference", "point_body_m", np.array([1e6, 0, 0])),
         _attr_name("/reference", "point_body_m")),
        ("attitude 1000 s after the pings", _replace("/attitude/time_s", lambda a: a + 1000.0), "/attitude/time_s"),
    ]
    for name, edit, field in phys:
        add(name, edit, "error", (field,))
    valid = [  # what the format allows (foreign simulators and instruments write these)
        ("reference without vertical", _replace("/reference/velocity_m_s", _at((slice(None), 2), np.nan))),
        ("dropped beam at some pings", _replace("/pings/bt_radial_m_s", _at((slice(3, 6), 2), np.nan))),
        ("missing attitude samples", _replace("/attitude/pitch_rad", _at(slice(4, 7), np.nan))),
        ("missing per-ping bed depths", lambda f: f["/environment"].create_dataset(
            "water_depth_m", data=np.r_[np.nan, np.full(f["/pings/time_s"].shape[0] - 1, 5.0)])),
        ("attitude record ends early", lambda f: [_replace(f"/attitude/{k}", lambda a: a[: int(0.8 * len(a))])(f)
                                                  for k in ("time_s", "heading_rad", "pitch_rad", "roll_rad")]),
        ("reference record longer than the pings", lambda f: [
            _replace("/reference/time_s", lambda a: np.r_[a, a[-1] + (1 + np.arange(len(a))) * np.median(np.diff(a))])(f),
            _replace("/reference/velocity_m_s", lambda a: np.r_[a, a])(f)]),
        ("unknown groups and attributes", lambda f: (f.create_group("extra").attrs.__setitem__("x", 1),
                                                     f["/pings"].attrs.__setitem__("note", "hello"))),
        ("no truth", _del("/truth")),
        ("stationary reference without samples", lambda f: (_del("/reference/time_s")(f), _del("/reference/velocity_m_s")(f),
                                                            _set_attr("/reference", "stationary", 1)(f))),
        ("truth's attitude model not JSON (an attribute the format does not define)",
         _set_attr("/truth", "attitude_model", "{")),
        ("float32 datasets", lambda f: [_replace(p, lambda a: np.asarray(a, dtype=np.float32))(f)
                                        for p in ("/pings/bt_radial_m_s", "/attitude/roll_rad")]),
    ]
    for name, edit in valid:
        add(name, edit, "ok", ())

    def first(n):
        def edit(f):
            for p in ("/pings/time_s", "/pings/bt_radial_m_s", "/pings/bt_range_m", "/truth/vessel_velocity_m_s"):
                _replace(p, lambda a: a[:n])(f)
        return edit

    def two_beams(a):
        a = np.array(a)
        a[::2, :2] = np.nan
        a[1::2, 2:] = np.nan
        return a

    for name, edit, fields in (  # valid files that some verbs cannot use: a right answer or a one-line error
            ("only 2 pings", first(2), ("/pings/time_s",)),
            ("one ping", first(1), ("/pings/time_s",)),
            ("two beams per ping", _replace("/pings/bt_radial_m_s", two_beams), ("/pings/bt_radial_m_s",)),
            ("attitude never changes", lambda f: [_replace(f"/attitude/{k}", np.zeros_like)(f)
                                                  for k in ("heading_rad", "pitch_rad", "roll_rad")], ("/attitude",))):
        add(name, edit, "either", fields)

    damaged = [("empty file", b""), ("not HDF5", b"hello, world\n"), ("random bytes", bytes(random.Random(1).randbytes(4096))),
               ("truncated HDF5", base.read_bytes()[: base.stat().st_size // 2])]
    for name, data in damaged:
        path = folder / f"{stem}__{name.replace(' ', '_')}.h5"
        path.write_bytes(data)
        out.append(Variant(f"{stem}: {name}", path, "error", ("/",)))
    out.append(Variant(f"{stem}: missing file", folder / "no_such_case.h5", "error", ("no_such_case.h5",)))
    (folder / "a_folder.h5").mkdir(exist_ok=True)
    out.append(Variant(f"{stem}: a folder", folder / "a_folder.h5", "either", ("a_folder.h5",)))
    return out


# ------------------------------------------------------------------------- calibration variants
def calibration_variants(base: Path, folder: Path) -> list[Variant]:
    """A CALIB.json with each key of the wrong type, shape, NaN/Inf, absurd or null; damaged files."""
    folder.mkdir(parents=True, exist_ok=True)
    d = json.loads(base.read_text())
    out = []

    def add(name, content, expect, fields):
        slug = "".join(ch if ch.isalnum() else "_" for ch in name)
        path = folder / f"{base.stem}__{slug}.json"
        path.write_text(content if isinstance(content, str) else json.dumps(content, allow_nan=True))
        out.append(Variant(f"{base.stem}: {name}", path, expect, tuple(fields)))

    def setting(path, value):
        c = copy.deepcopy(d)
        node = c
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
        return c

    keys = {"radius_vectors_head_m": (4, 3), "radius_vectors_m": (4, 3), "installation_ypr_rad": (3,)}
    for key, shape in keys.items():
        if key not in d:  # a vessel-frame calibration has no head-frame lever arms
            continue
        add(f"{key} a string", setting([key], "abc"), "error", (key,))
        if len(shape) == 2:
            add(f"{key} flat", setting([key], [0.0] * int(np.prod(shape))), "error", (key,))
        add(f"{key} 9 numbers", setting([key], [[0.0] * 3] * 3) if len(shape) == 2 else setting([key], [0.0] * 9),
            "error", (key,))
        first = [key, 0, 0] if len(shape) == 2 else [key, 0]
        add(f"{key} NaN", setting(first, float("nan")), "error", (key,))
        add(f"{key} Inf", setting(first, float("inf")), "error", (key,))
        add(f"{key} 1e6", setting(first, 1e6), "error", (key,))
        add(f"{key} string number", setting(first, "0.1"), "error", (key,))
        add(f"{key} nested deeper", setting(first, [0.1]), "error", (key,))
    for key in ("heading_misalignment_rad",):
        add(f"{key} NaN", setting([key], float("nan")), "error", (key,))
        add(f"{key} string", setting([key], "5 deg"), "error", (key,))
        add(f"{key} 100 rad", setting([key], 100.0), "error", (key,))
        add(f"{key} a list", setting([key], [0.1]), "error", (key,))
        add(f"{key} 0.1 rad", setting([key], 0.1), "ok", ())
    add("attitude_source unknown", setting(["attitude_source"], "guess"), "error", ("attitude_source",))
    add("attitude_model broken", setting(["attitude_model"], {"modes": 3}), "error", ("attitude_model",))
    add("config not an object", setting(["config"], [1]), "error", ("config",))
    add("schema_version 7", setting(["schema_version"], 7), "error", ("schema_version",))
    add("schema_version 2", setting(["schema_version"], 2), "ok", ())
    add("unknown extra key", setting(["something_new"], {"x": 1}), "ok", ())
    add("lever arms not determined", setting(["radius_vectors_head_m"], [[None] * 3] * 4), "either",
        ("radius_vectors_head_m",))
    add("installation not determined", setting(["installation_ypr_rad"], [None] * 3), "either",
        ("installation_ypr_rad",))
    for name, text in (("empty", ""), ("null", "null"), ("a list", "[1, 2, 3]"), ("a number", "3.5"),
                       ("not JSON", "{radius: 1"), ("binary", "\x00\x01\x02"), ("no known key", '{"a": 1}'),
                       ("truncated", base.read_text()[: len(base.read_text()) // 2])):
        add(name, text, "error", ("calibration",))
    out.append(Variant(f"{base.stem}: missing file", folder / "no_such_calib.json", "error", ("no_such_calib.json",)))
    return out


# ------------------------------------------------------------------------- instrument files
def pd0_variants(src: Path, folder: Path) -> list[Variant]:
    """A real PD0 cut short, with flipped bytes, zeroed, emptied: import must read it or refuse in one line."""
    folder.mkdir(parents=True, exist_ok=True)
    data = src.read_bytes()
    rng = random.Random(7)
    out = []

    def add(name, content, expect="either"):
        path = folder / f"{src.stem}__{name.replace(' ', '_')}{src.suffix}"
        path.write_bytes(content)
        out.append(Variant(f"pd0: {name}", path, expect, (str(path.name),)))

    add("truncated to a third", data[: len(data) // 3 + 17])
    add("truncated to 5000 bytes", data[:5000])
    add("header only", data[:2], "error")
    add("empty", b"", "error")
    flipped = bytearray(data)
    for _ in range(10):
        flipped[rng.randrange(len(flipped))] ^= 0xFF
    add("10 flipped bytes", bytes(flipped))
    one = bytearray(data)
    one[len(one) // 2] ^= 0x55
    add("one flipped byte", bytes(one))
    zero = bytearray(data)
    zero[100000:100400] = bytes(400)
    add("zeroed block", bytes(zero))
    add("block cut out", data[:100000] + data[100500:])
    add("random bytes", bytes(rng.randrange(256) for _ in range(20000)), "error")
    return out


# ------------------------------------------------------------------------- running and judging
def run(argv: list[str]) -> Outcome:
    """``adcpdyn ARGV`` in this process: exit status, stdout, stderr, and a traceback if one escaped."""
    from adcpdyn.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
            tb = None
        except SystemExit as exc:  # argparse
            code, tb = (exc.code if isinstance(exc.code, int) else 2), None
        except Exception:  # noqa: BLE001 - a traceback is what is being looked for
            code, tb = None, traceback.format_exc()
    return Outcome(code, out.getvalue(), err.getvalue(), tb)


def _velocities(path: Path) -> list[np.ndarray]:
    """Velocity arrays of an output (corrected HDF5 or compare JSON)."""
    if path.suffix == ".h5":
        with h5py.File(path, "r") as f:
            if "corrected" not in f:  # an imported case: it must read back as a valid case
                from adcpdyn.cases.io import read_case

                read_case(path)
                return []
            g = f["corrected"]
            used = g["beams_used"][()]
            arrays = [g["vessel_velocity_m_s"][()][used >= 3]]
            if "water_velocity_m_s" in g:
                arrays.append(g["water_velocity_m_s"][()][used >= 3])
            return arrays
    return []


def judge(variant: Variant, verb: str, outcome: Outcome, outputs: list[Path], folder: Path) -> str | None:
    """What is wrong with one run (None: a right answer)."""
    if outcome.traceback:
        return "traceback: " + outcome.traceback.strip().splitlines()[-1]
    temporaries = [p.name for p in folder.rglob(f"*{TMP_TAG}*")]
    if temporaries:
        return f"temporary files left: {temporaries}"
    err = outcome.err.strip()
    if outcome.code == 0:
        if variant.expect == "error":
            return "exit 0 on an input that should be refused"
        for path in outputs:
            if not path.exists():
                return f"exit 0 without its output {path.name}"
            for k, v in enumerate(_velocities(path)):
                if k == 0 and (v.size == 0 or not np.all(np.isfinite(v))):  # vessel velocity of every usable ping
                    return f"exit 0 with NaN vessel velocities in {path.name}"
                if np.any(np.isinf(v)) or (np.isfinite(v).any() and np.nanmax(np.abs(v)) >= SANE_M_S):
                    return f"exit 0 with absurd velocities ({np.nanmax(np.abs(v)):.3g} m/s) in {path.name}"
                if k == 1 and not np.isfinite(v).any() and variant.expect == "ok":
                    return f"exit 0 with no finite water velocity in {path.name}"
        return None
    if outcome.code in (1,) and verb in ("calibrate", "diagnose"):
        return None  # the solver did not converge: said so, output written
    if outcome.code != 2:
        return f"exit status {outcome.code}"
    if variant.expect == "ok":
        return f"valid input refused: {err}"
    if err.count("\n") != 0 or not err:
        return f"error of {len(err.splitlines())} lines: {err[:200]!r}"
    if "Traceback" in err:
        return "traceback text on stderr"
    if variant.fields and not any(f in err for f in variant.fields):
        return f"error does not name {variant.fields}: {err}"
    for path in outputs:
        if path.exists():
            return f"exit 2 but output {path.name} written"
    return None


def plan(folder: Path, base: dict, real_pd0: Path | None = None) -> list[tuple[Variant, str]]:
    """Every variant with the kind of commands it goes through."""
    out = [(v, "case") for v in case_variants(base["pool"], folder / "cases")]
    out += [(v, "water") for v in case_variants(base["ocean"], folder / "water", water=True)]
    out += [(v, "calib_pool") for v in calibration_variants(base["calib_pool"], folder / "calibs")]
    out += [(v, "calib_ship") for v in calibration_variants(base["calib_ship"], folder / "calibs")]
    if real_pd0 is not None and real_pd0.exists():
        out += [(v, "pd0") for v in pd0_variants(real_pd0, folder / "pd0")]
    return out


def commands(variant: Variant, kind: str, base: dict, out: Path):
    """(verb, argv, outputs) to run on one variant: every verb that reads that kind of input."""
    out.mkdir(parents=True, exist_ok=True)
    p = str(variant.path)
    o, c, d = out / "o.h5", out / "c.json", out / "d.json"
    if kind == "case":
        calib = str(base["calib_pool"])
        yield "info", ["info", p], []
        yield "correct asc", ["correct", p, "--method", "asc", "--out", str(o)], [o]
        yield "correct adc", ["correct", p, "--method", "adc", "--calibration", calib, "--out", str(o)], [o]
        yield "calibrate", ["calibrate", p, "--starts", "1", "--out", str(c)], [c]
        if variant.expect == "error":  # refused on reading: cheap; a valid case's diagnosis is the slow test's
            yield "compare", ["compare", p, "--calibration", calib], []
            yield "diagnose", ["diagnose", p, "--effects", "heave", "--out", str(d)], [d]
        else:
            yield "compare", ["compare", p, "--calibration", calib, "--out", str(out / "cmp")], []
    elif kind == "water":
        yield "info", ["info", p], []
        yield "correct asc", ["correct", p, "--method", "asc", "--out", str(o)], [o]
    elif kind.startswith("calib_"):
        case = str(base[kind.split("_")[1]])
        yield "correct adc", ["correct", case, "--method", "adc", "--calibration", p, "--out", str(o)], [o]
        yield "correct asc", ["correct", case, "--method", "asc", "--calibration", p, "--out", str(o)], [o]
        yield "correct rootfinder", ["correct", case, "--method", "rootfinder", "--calibration", p, "--out", str(o)], [o]
        if variant.expect == "error":
            yield "compare", ["compare", case, "--calibration", p], []
            yield "diagnose", ["diagnose", case, "--effects", "heave", "--calibration", p, "--out", str(d)], [d]
    elif kind == "pd0":
        yield "import", ["import", p, "--out", str(out / "imported.h5")], [out / "imported.h5"]


def run_plan(items, base: dict, folder: Path, known=frozenset()) -> tuple[list[str], dict]:
    """Run every command of every variant; (problems, counts per verb and outcome). ``known``
    holds (variant name, verb) pairs whose problem is expected (reported apart)."""
    import collections

    counts, problems = collections.Counter(), []
    for variant, kind in items:
        for verb, argv, outputs in commands(variant, kind, base, folder / "out"):
            o = run(argv)
            problem = judge(variant, verb, o, outputs, folder)
            counts[(verb, "problem" if problem else ("exit 0" if o.code == 0 else f"exit {o.code}"))] += 1
            if problem and (variant.name, verb) not in known:
                problems.append(f"{variant.name} | {verb}: {problem}")
            for path in outputs:
                if path.is_file():
                    path.unlink()
    return problems, dict(counts)


def _main(folder: str) -> int:
    """Run every variant through every verb and print the outcomes."""
    import time

    sys.path.insert(0, str(Path(__file__).parent))
    folder = Path(folder)
    tic = time.perf_counter()
    base = base_files(folder / "base")
    real = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "RiverPro_test01.PD0"
    items = plan(folder, base, real)
    problems, counts = run_plan(items, base, folder)
    print(f"{len(items)} variants, {sum(counts.values())} runs in {time.perf_counter() - tic:.0f} s")
    for (verb, what), n in sorted(counts.items()):
        print(f"  {verb:<22} {what:<8} {n}")
    print("\n".join(problems) if problems else "no problems")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1] if len(sys.argv) > 1 else "/tmp/adcpdyn-fuzz"))
