"""CALIB.json: one validation for every reader; one-line errors naming the file and the key."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from adcpdyn.cli import main
from adcpdyn.estimators.calibration.file import KEYS, read_calibration, validate_calibration
from adcpdyn.estimators.calibration.record import CalibrationRecord, as_record
from conftest import calibrated_pool_m0


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """What `adcpdyn calibrate` writes (pool_m0, one start) and a case to correct with it."""
    folder = tmp_path_factory.mktemp("calib")
    _, path, _ = calibrated_pool_m0(folder, n_starts=1)
    m1 = folder / "m1.h5"
    assert main(["simulate", "pool_m1", "--seed", "1", "--out", str(m1)]) == 0
    return json.loads(path.read_text()), m1


def _write(tmp_path, d, name="c.json"):
    path = tmp_path / name
    path.write_text(d if isinstance(d, str) else json.dumps(d, allow_nan=True))
    return path


def test_what_calibrate_writes_is_valid_and_schema_version_3_with_new_keys_too(written, tmp_path):
    d, _ = written
    assert d["schema_version"] == 3  # what calibrate writes: whose it is too
    assert d["instrument"]["make"] == "adcpdyn simulator" and d["instrument"]["frequency_hz"] > 0
    assert set(d["site"]) == {"latitude_deg", "longitude_deg", "start_utc", "end_utc"}
    assert read_calibration(_write(tmp_path, d)) == d
    v1 = {k: v for k, v in d.items() if k != "schema_version"}  # files of earlier versions carry no version: 1
    assert read_calibration(_write(tmp_path, v1, "v1.json")) == v1
    v2 = {**d, "schema_version": 2, "moving_bed_velocity_m_s": [0.1, -0.05], "moving_bed_velocity_se_m_s": None,
          "compass_deviation_rad": {"sin": 0.01, "cos": -0.02}, "magnetic_declination_rad": None,
          "compass_error_rad": 0.03, "runs": [{"case": "a.h5", "moving_bed_velocity_m_s": [0.0, 0.2],
                                               "moving_bed_velocity_se_m_s": [0.01, 0.01]}, {"case": "b.h5"}],
          "a_key_of_a_later_version": {"anything": [1, 2]}}
    assert read_calibration(_write(tmp_path, v2, "v2.json"))["runs"][1] == {"case": "b.h5"}


def _set(path, value):
    """A copy of a calibration with the item at ``path`` (keys and indices) set, or deleted (``...``)."""
    def edit(d):
        d = copy.deepcopy(d)
        node = d
        for k in path[:-1]:
            node = node[k]
        if value is ...:
            del node[path[-1]]
        else:
            node[path[-1]] = value
        return d
    return edit


OWN = {"effects": ["compass_deviation", "sound_speed_error"], "navigation": "random_walk", "statement": "",
       "unknowns": {"compass_deviation.A_rad": {"value": 0.17, "se": 0.10}, "compass_deviation.B_rad": {"value": -0.14, "se": 0.1},
                    "compass_deviation.C_rad": {"value": -0.2, "se": 0.03},
                    "sound_speed_error.relative_error": {"value": 0.022, "se": None}}}


def _own(edit):
    """A calibration carrying ``OWN`` (what its runs showed on top of it), edited."""
    return lambda d: edit({**copy.deepcopy(d), "own_effects": copy.deepcopy(OWN)})


BAD = {  # variant: (edit, the key the one-line error must name)
    "string angle": (_set(["installation_ypr_rad", 0], "0.1"), "installation_ypr_rad[0]"),
    "NaN heading misalignment": (_set(["heading_misalignment_rad"], float("nan")), "heading_misalignment_rad"),
    "Inf lever arm": (_set(["radius_vectors_m", 1, 2], float("inf")), "radius_vectors_m[1][2]"),
    "lever arm 1e6 m": (_set(["radius_vectors_head_m", 0, 0], 1e6), "radius_vectors_head_m[0][0]"),
    "lever arms (4, 4)": (_set(["radius_vectors_m", 2], [0.0, 0.0, 0.0, 0.0]), "radius_vectors_m[2]"),
    "lever arms flat": (_set(["radius_vectors_m"], list(range(12))), "radius_vectors_m"),
    "lever arms a number": (_set(["radius_vectors_m"], 3.0), "radius_vectors_m"),
    "installation angle in degrees": (_set(["installation_ypr_rad"], [45.0, 0.0, 0.0]), "installation_ypr_rad[0]"),
    "installation two angles": (_set(["installation_ypr_rad"], [0.0, 0.0]), "installation_ypr_rad"),
    "bool as angle": (_set(["heading_misalignment_rad"], True), "heading_misalignment_rad"),
    "unknown frame": (_set(["attitude_frame"], "ned"), "attitude_frame"),
    "unknown attitude source": (_set(["attitude_source"], 3), "attitude_source"),
    "attitude model mode missing": (_set(["attitude_model", "roll", "modes"], []), "attitude_model.roll.modes"),
    "attitude model NaN omega": (_set(["attitude_model", "modes", 0, "omega_rad_s"], float("nan")),
                                 "attitude_model.modes[0].omega_rad_s"),
    "attitude model without yaw": (_set(["attitude_model", "yaw"], ...), "attitude_model.yaw"),
    "attitude model a list": (_set(["attitude_model"], [1, 2]), "attitude_model"),
    "nominal installation a string": (_set(["config", "nominal_installation_ypr_rad"], "zero"),
                                      "config.nominal_installation_ypr_rad"),
    "schema version 4": (_set(["schema_version"], 4), "schema_version"),
    "instrument frequency a string": (_set(["instrument", "frequency_hz"], "1200 kHz"), "instrument.frequency_hz"),
    "site latitude 95": (_set(["site", "latitude_deg"], 95.0), "site.latitude_deg"),
    "schema version null": (_set(["schema_version"], None), "schema_version"),
    "moving bed 6 m/s": (_set(["moving_bed_velocity_m_s"], [6.0, 0.0]), "moving_bed_velocity_m_s[0]"),
    "moving bed |v| > 5": (_set(["moving_bed_velocity_m_s"], [4.0, 4.0]), "moving_bed_velocity_m_s"),
    "moving bed 3 components": (_set(["moving_bed_velocity_m_s"], [0.0, 0.0, 0.0]), "moving_bed_velocity_m_s"),
    "compass deviation 1 rad": (_set(["compass_deviation_rad"], {"sin": 1.0, "cos": 0.0}), "compass_deviation_rad.sin"),
    "compass deviation a number": (_set(["compass_deviation_rad"], 0.1), "compass_deviation_rad"),
    "declination 4 rad": (_set(["magnetic_declination_rad"], 4.0), "magnetic_declination_rad"),
    "run without case": (_set(["runs"], [{"moving_bed_velocity_m_s": [0, 0]}]), "runs[0].case"),
    "run moving bed string": (_set(["runs"], [{"case": "a", "moving_bed_velocity_m_s": "slow"}]),
                              "runs[0].moving_bed_velocity_m_s"),
    "run attitude interpolation cubic": (_set(["runs"], [{"case": "a", "attitude_interpolation": "cubic"}]),
                                         "runs[0].attitude_interpolation"),
    "own effect not in the catalog": (_own(_set(["own_effects", "effects", 1], "salinity")), "own_effects.effects"),
    "own effect without its unknowns": (_own(_set(["own_effects", "effects"], ["compass_deviation", "sound_speed_error",
                                                                              "heave"])), "own_effects.unknowns"),
    "own unknown of another effect": (_own(_set(["own_effects", "unknowns", "moving_bed.velocity_north_m_s"],
                                                {"value": 0.1, "se": 0.01})), "own_effects.unknowns.moving_bed.velocity_north_m_s"),
    "own value NaN": (_own(_set(["own_effects", "unknowns", "compass_deviation.A_rad", "value"], float("nan"))),
                      "own_effects.unknowns.compass_deviation.A_rad.value"),
    "own value null": (_own(_set(["own_effects", "unknowns", "compass_deviation.A_rad", "value"], None)),
                       "own_effects.unknowns.compass_deviation.A_rad.value"),
    "own SE negative": (_own(_set(["own_effects", "unknowns", "compass_deviation.B_rad", "se"], -0.1)),
                        "own_effects.unknowns.compass_deviation.B_rad.se"),
    "own navigation": (_own(_set(["own_effects", "navigation"], "gnss")), "own_effects.navigation"),
}


def test_a_calibrations_own_effects_round_trip(written, tmp_path):
    """What the runs showed on top of their calibration (``own_effects``) is read back onto the record as
    written; a standard error not determined (null) stays null."""
    d, _ = written
    record = CalibrationRecord.from_json(_write(tmp_path, {**d, "own_effects": OWN}))
    assert record.own_effects == OWN
    assert CalibrationRecord.from_json(_write(tmp_path, d, "plain.json")).own_effects is None


@pytest.mark.parametrize("kind", list(BAD))
def test_malformed_calibration_is_one_line_naming_file_and_key(written, tmp_path, kind):
    d, _ = written
    edit, key = BAD[kind]
    path = _write(tmp_path, edit({**d, "schema_version": 1}))
    with pytest.raises(ValueError) as info:
        read_calibration(path)
    msg = str(info.value)
    assert msg.startswith(f"calibration {path}: {key}: expected "), msg
    assert "\n" not in msg and ", got " in msg


@pytest.mark.parametrize("text, words", [("", "empty file"), ("null", "got null"), ("[1, 2]", "got [1, 2]"),
                                         ("{", "invalid JSON"), ('{"foo": 1}', "at least one of"),
                                         ("[" * 100000, "nested too deeply"), (b"\xff\xfe\x00", "binary")])
def test_files_that_are_no_calibration(tmp_path, text, words):
    path = tmp_path / "c.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ValueError) as info:
        read_calibration(path)
    assert str(info.value).startswith(f"calibration {path}: ") and words in str(info.value)
    with pytest.raises(ValueError, match="cannot read the file"):
        read_calibration(tmp_path / "missing.json")


def test_null_means_not_determined_and_is_refused_only_where_needed(written, tmp_path, capsys):
    d, m1 = written
    head = {**d, "radius_vectors_head_m": [[None] * 3] * 4, "heading_misalignment_rad": None}
    path = _write(tmp_path, head)
    calib = CalibrationRecord.from_json(path)
    with pytest.raises(ValueError, match=rf"^calibration {path}: radius_vectors_head_m: contains undetermined \(null\)"):
        calib.lever_arms_in("transducer")
    # the static correction needs no lever arm: it runs; the dynamic one refuses in one line
    assert main(["correct", str(m1), "--method", "asc", "--calibration", str(path), "--out", str(tmp_path / "a.h5")]) == 0
    assert main(["correct", str(m1), "--method", "adc", "--calibration", str(path), "--out", str(tmp_path / "b.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"calibration {path}: radius_vectors_head_m" in err
    assert not (tmp_path / "b.h5").exists()


@pytest.mark.parametrize("argv", [["correct", "{case}", "--method", "adc", "--calibration", "{calib}", "--out", "{out}.h5"],
                                  ["correct", "{case}", "--method", "asc", "--calibration", "{calib}", "--out", "{out}.h5"],
                                  ["correct", "{case}", "{case}", "--scheduler", "none", "--calibration", "{calib}",
                                   "--out", "{out}"],
                                  ["compare", "{case}", "--calibration", "{calib}"],
                                  ["diagnose", "{case}", "--calibration", "{calib}", "--out", "{out}.json"]])
def test_every_reader_uses_the_validation(written, tmp_path, capsys, argv):
    d, m1 = written
    path = _write(tmp_path, {**d, "installation_ypr_rad": ["0.1", 0, 0]})
    args = [a.format(case=m1, calib=path, out=tmp_path / "out") for a in argv]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"calibration {path}: installation_ypr_rad[0]: expected a number" in err


def test_in_memory_calibrations_are_validated_too(written):
    from adcpdyn.cases.io import read_case
    from adcpdyn.estimators.correction.correct_case import correct_case

    d, m1 = written
    case = read_case(m1)
    with pytest.raises(ValueError, match=r"^calibration: radius_vectors_head_m\[0\]: expected a list of 3 numbers"):
        correct_case(case, "adc", as_record({**d, "radius_vectors_head_m": [[0.0, 0.0]] * 4}))
    assert np.all(np.isfinite(correct_case(case, "adc", as_record(d)).vessel_velocity_m_s))


def test_every_key_of_the_table_is_checked():
    """Each line of the table refuses a value of the wrong type (the table is what is enforced)."""
    wrong = {"number": "x", "integer": 1.5, "bool": 1, "string": 3, "array": "x", "object": [], "list": {}}
    for key, spec in KEYS.items():
        if spec.kind == "any":
            continue
        with pytest.raises(ValueError, match=rf"^calibration src: {key}: expected "):
            validate_calibration({"radius_vectors_m": None, key: wrong[spec.kind]}, "src")


def test_what_the_multi_run_writer_emits_is_valid():
    """The shape of a schema-2 CALIB.json of a joint survey calibration (keys as its writer emits
    them, undetermined numbers null), and the bed each run is corrected with."""
    d = {"schema_version": 2, "radius_vectors_m": [[0.1, 0.0, 0.5]] * 4, "radius_vectors_head_m": [[None] * 3] * 4,
         "installation_ypr_rad": [0.2, None, None], "heading_misalignment_rad": 0.2, "heading_misalignment_se_rad": None,
         "magnetic_declination_rad": 0.27, "magnetic_declination_note": "IGRF-14", "compass_error_rad": -0.07,
         "compass_deviation_rad": {"sin": 0.004, "cos": None, "mean_sin": 0.68, "mean_cos": -0.16},
         "compass_deviation_se_rad": {"sin": 0.017, "cos": None}, "moving_bed": {"model": "section", "velocity_m_s": []},
         "moving_bed_velocity_m_s": [0.05, -0.15], "moving_bed_velocity_se_m_s": [0.02, None],
         "standard_errors": {"method": "newey-west"}, "confounded": [],
         "runs": [{"case": "run01", "n_pings": 231, "moving_bed_velocity_m_s": [0.04, None],
                   "moving_bed_velocity_se_m_s": None, "heading_deg": {"mean": 20.0, "circular_sd": 1.0}},
                  {"case": "run02", "moving_bed_velocity_m_s": [0.06, -0.14]}]}
    calib = CalibrationRecord.from_dict(validate_calibration(d, "survey.json"))
    assert calib.moving_bed_for("run02")[0].tolist() == [0.06, -0.14]
    bed, source = calib.moving_bed_for("run01")  # its own bed is not determined: the site's
    assert bed.tolist() == [0.05, -0.15] and "site" in source
    assert CalibrationRecord.from_dict({**d, "moving_bed_velocity_m_s": [None, 0.1]}).moving_bed_for("other") == (None, "")
    with pytest.raises(ValueError, match=r"^calibration survey.json: compass_deviation_rad.mean_sin: expected"):
        validate_calibration({**d, "compass_deviation_rad": {"sin": 0.0, "cos": 0.0, "mean_sin": 3.0}}, "survey.json")
    with pytest.raises(ValueError, match=r"^calibration survey.json: runs\[1\].moving_bed_velocity_m_s\[0\]: expected"):
        validate_calibration({**d, "runs": [d["runs"][0], {"case": "run02", "moving_bed_velocity_m_s": [9.0, 0.0]}]},
                             "survey.json")
