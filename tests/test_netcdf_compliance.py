"""netCDF exports under the IOOS compliance-checker (cf:1.8, acdd:1.3, ioos:1.2), and the attribution
file that supplies what no instrument file holds (creator, publisher, licence, naming authority)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from conftest import real

from adcpdyn import api
from adcpdyn.benchmarks.compliance import SUITES, TARGET_PERCENT, checker_scores
from adcpdyn.cases.attribution import Attribution, read_attribution
from adcpdyn.cli import main

xr = pytest.importorskip("xarray")
ATTRIBUTION = Path(__file__).resolve().parents[1] / "docs" / "examples" / "attribution.toml"


def _exports(case_path: Path, tmp_path: Path) -> list[Path]:
    """The case and its static correction as netCDF, with the example attribution."""
    case_nc, corrected_nc = tmp_path / f"{case_path.stem}_case.nc", tmp_path / f"{case_path.stem}_asc.nc"
    assert main(["export", str(case_path), "--out", str(case_nc), "--attribution", str(ATTRIBUTION)]) == 0
    assert main(["correct", str(case_path), "--out", str(corrected_nc), "--attribution", str(ATTRIBUTION)]) == 0
    return [case_nc, corrected_nc]


def _assert_passes(path: Path) -> None:
    scores = checker_scores(path)
    low = {s: f"{v.scored}/{v.possible}" for s, v in scores.items() if v.percent < TARGET_PERCENT}
    assert set(scores) == set(SUITES) and not low, (path.name, low)


def test_a_simulated_export_with_dates_and_positions_passes_the_checker(tmp_path):
    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    for path in _exports(case_path, tmp_path):
        _assert_passes(path)


@pytest.mark.slow  # 6.7 s on 2026-12-02's host: `make test-slow`, CI's second step
def test_a_real_export_passes_the_checker(tmp_path):
    case_path = tmp_path / "rp.h5"
    api.import_file(real("RiverPro_test01.PD0"), out=case_path)
    for path in _exports(case_path, tmp_path):
        _assert_passes(path)
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            assert ds.attrs["featureType"] == "trajectoryProfile" and ds["vessel"].attrs["cf_role"] == "trajectory_id"
            # one trajectory on an instance dimension of length 1 (the IOOS profile's check), every ping on it
            assert ds["vessel"].dims == ("trajectory",) and ds.sizes["trajectory"] == 1
            assert ds["trajectory_index"].attrs["instance_dimension"] == "trajectory"
            assert ds["trajectory_index"].dims == ("time",) and not ds["trajectory_index"].values.any()
            assert Path(ds.attrs["source_file"]).is_absolute() and Path(ds.attrs["source_case_file"]).is_absolute()


def test_an_undated_simulated_export_passes_cf_with_no_high_priority_failure(tmp_path):
    """No UTC origin: no invented date, so no failed CF time check (was: time in s with no reference date)."""
    case_path = tmp_path / "ship.h5"
    api.simulate("deep_ship", seed=1, out=case_path)
    for path in (tmp_path / "case.nc", tmp_path / "asc.nc"):
        if path.stem == "case":
            api.export(case_path, path)
        else:
            api.correct(case_path, "asc", out=path)
        cf = checker_scores(path, ["cf:1.8"])["cf:1.8"]
        assert cf.percent >= TARGET_PERCENT and cf.high_failed == 0, (path.name, cf)


def test_the_checker_check_can_fail(tmp_path):
    """Without the discovery attributes the same export falls below the target: the assertion above bites."""
    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    ds = api.to_xarray(case_path, attribution=ATTRIBUTION)
    for key in ("title", "summary", "keywords", "creator_email", "publisher_url", "time_coverage_start", "featureType",
                "references", "platform_vocabulary", "instrument_vocabulary"):
        del ds.attrs[key]
    for var in ds.variables.values():
        var.attrs.pop("coverage_content_type", None)
    from adcpdyn.cases.netcdf import write_netcdf

    write_netcdf(ds, tmp_path / "bare.nc")
    scores = checker_scores(tmp_path / "bare.nc")
    assert scores["acdd:1.3"].percent < TARGET_PERCENT and scores["ioos:1.2"].percent < TARGET_PERCENT


def test_attribution_is_written_and_what_is_not_stated_says_so(tmp_path):
    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    stated = read_attribution(ATTRIBUTION)
    with_it = api.to_xarray(case_path, attribution=stated).attrs
    without = api.to_xarray(case_path).attrs
    assert with_it["creator_email"] == stated.creator_email and with_it["license"] == stated.license
    assert without["creator_name"] == "not stated" and without["license"] == "not stated"
    assert "creator_email" not in without and "infoUrl" not in without  # never invented
    assert without["creator_sector"] == "unknown" and with_it["id"] == without["id"]  # the id: of the data


@pytest.mark.parametrize("change, words", [
    ({"creator_email": "nobody"}, "creator_email: expected an e-mail address"),
    ({"infoUrl": "example.org"}, "infoUrl: expected an http(s) URL"),
    ({"creator_sector": "private"}, "creator_sector: expected one of"),
    ({"contributor_role": "helper"}, "contributor_role: expected roles from"),
    ({"naming_authority": "example"}, "naming_authority: expected reverse DNS"),
    ({"platform": "research vessel", "platform_vocabulary": "https://vocab.nerc.ac.uk/collection/L06/current/"},
     "platform: expected one word"),
    ({"platform": "ship"}, "platform, platform_vocabulary: expected both"),
    ({"creator_postalcode": 12345}, "creator_postalcode: expected a non-empty string"),
])
def test_bad_attribution_values_are_refused_in_one_line(tmp_path, change, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        dataclasses.replace(read_attribution(ATTRIBUTION), **change)
    text = "".join(f"{k} = {v!r}\n".replace("'", '"') for k, v in change.items())
    (tmp_path / "a.toml").write_text(text)
    with pytest.raises(ValueError, match=f"^--attribution: a.toml: {re.escape(words)}") as err:
        read_attribution(tmp_path / "a.toml")
    assert "\n" not in str(err.value)


def test_attribution_file_errors_and_misplaced_option(tmp_path, capsys):
    (tmp_path / "a.toml").write_text('creator = "me"\n')
    with pytest.raises(ValueError, match=r"^--attribution: a.toml: unknown attribute\(s\) \['creator'\]"):
        read_attribution(tmp_path / "a.toml")
    (tmp_path / "b.toml").write_text("creator_name = \n")
    with pytest.raises(ValueError, match=r"^--attribution: .*b.toml: expected TOML"):
        read_attribution(tmp_path / "b.toml")
    case_path = tmp_path / "c.h5"
    api.simulate("pool_still", seed=1, out=case_path)
    assert main(["correct", str(case_path), "--out", str(tmp_path / "c_asc.h5"), "--attribution", str(ATTRIBUTION)]) == 2
    err = capsys.readouterr().err
    assert "--attribution: only with one case and --out OUT.nc" in err and err.count("\n") == 1
    with pytest.raises(ValueError, match=r"^attribution: only with out=OUT.nc"):
        api.correct(case_path, "asc", attribution=Attribution())


@pytest.mark.slow  # 6 s: `make test-slow`, CI's second step
def test_a_correction_records_when_its_calibration_was_made(tmp_path):
    """The adcp variable's calibration_date is the applied CALIB.json's written_utc (ISO 8601, as IOOS asks);
    a correction without a calibration claims none."""
    import json

    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    api.calibrate(case_path, n_starts=1).to_json(tmp_path / "C.json")
    written = json.loads((tmp_path / "C.json").read_text())["provenance"]["written_utc"]
    api.correct(case_path, "asc", calibration=tmp_path / "C.json", out=tmp_path / "cal.nc")
    api.correct(case_path, "asc", out=tmp_path / "none.nc")
    with xr.open_dataset(tmp_path / "cal.nc", engine="h5netcdf") as ds:
        assert ds["adcp"].attrs["calibration_date"] == written
        assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?Z", written)
    with xr.open_dataset(tmp_path / "none.nc", engine="h5netcdf") as ds:
        assert "calibration_date" not in ds["adcp"].attrs  # an empty date would fail IOOS's ISO-8601 check alike
        assert ds["adcp"].attrs["calibration_date_comment"].startswith("no calibration date: no adcpdyn calibration")


def test_beams_used_declares_a_fill_value_it_never_holds(tmp_path):
    """IOOS asks every data variable for _FillValue and missing_value: beams_used (int8) has netCDF's byte fill,
    outside its valid range 0-4, and keeps its counts (as integers without xarray's masking)."""
    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    result = api.correct(case_path, "asc", out=tmp_path / "c.nc")
    with xr.open_dataset(tmp_path / "c.nc", engine="h5netcdf", mask_and_scale=False) as ds:
        used = ds["beams_used"]
        assert used.dtype == "int8" and used.attrs["_FillValue"] == used.attrs["missing_value"] == -127
        assert list(used.attrs["valid_range"]) == [0, 4]
        assert (used.values == result.beams_used).all()


def test_references_say_how_the_data_were_made(tmp_path):
    """references (IOOS-1.2) on every export with a known origin: the correction's paper, or the simulator's
    equations for a simulated case, and the reader of an imported instrument file; the user's first."""
    from adcpdyn.cases.discovery import METHOD_REFERENCE, SIMULATION_REFERENCE

    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    assert api.to_xarray(case_path).attrs["references"] == SIMULATION_REFERENCE
    corrected = api.correct(case_path, "asc")
    assert api.to_xarray(case_path, corrected).attrs["references"] == METHOD_REFERENCE
    stated = dataclasses.replace(read_attribution(ATTRIBUTION), references="https://example.org/report")
    assert api.to_xarray(case_path, attribution=stated).attrs["references"] == (
        f"https://example.org/report, {SIMULATION_REFERENCE}")
    imported = tmp_path / "rp.h5"
    api.import_file(real("RiverPro_test01.PD0"), out=imported)
    refs = api.to_xarray(imported).attrs["references"]
    assert refs.startswith("instrument file decoded by mhkit") and SIMULATION_REFERENCE not in refs


def test_platform_and_instrument_name_their_vocabularies(tmp_path):
    """The platform category (IOOS's ship unless the attribution states one) and the instrument (GCMD's ADCP
    keyword) come with the vocabularies they are from; the make and model stay in the title and on adcp."""
    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    plain = api.to_xarray(case_path)
    assert plain.attrs["platform"] == "ship"
    assert plain.attrs["platform_vocabulary"] == "https://mmisw.org/ont/ioos/platform"
    assert "size is not recorded" in plain.attrs["comment"]
    assert plain.attrs["instrument"] == "ADCP > Acoustic Doppler Current Profiler"
    assert plain.attrs["instrument_vocabulary"] == "GCMD Instrument Keywords"
    assert plain["adcp"].attrs["make_model"] in plain.attrs["title"]
    boat = dataclasses.replace(read_attribution(ATTRIBUTION), platform="boat",
                               platform_vocabulary="https://example.org/platforms")
    stated = api.to_xarray(case_path, attribution=boat).attrs
    assert (stated["platform"], stated["platform_vocabulary"]) == (boat.platform, boat.platform_vocabulary)
    assert "size is not recorded" not in stated["comment"]


def test_the_environment_names_a_default_attribution_and_the_export_names_the_file(tmp_path, monkeypatch, capsys):
    """ADCPDYN_ATTRIBUTION applies when --attribution is not given, checked the same way; the export records
    which file (absolute path, SHA-256, given by the option or the variable); --attribution wins."""
    from adcpdyn.cases.hashing import sha256_of

    case_path = tmp_path / "river.h5"
    api.simulate("river_survey", seed=2, out=case_path)
    stated = read_attribution(ATTRIBUTION)
    monkeypatch.setenv("ADCPDYN_ATTRIBUTION", str(ATTRIBUTION))
    assert main(["export", str(case_path), "--out", str(tmp_path / "env.nc")]) == 0
    assert main(["correct", str(case_path), "--out", str(tmp_path / "env_asc.nc")]) == 0
    for name in ("env.nc", "env_asc.nc"):
        with xr.open_dataset(tmp_path / name, engine="h5netcdf") as ds:
            assert ds.attrs["creator_email"] == stated.creator_email and ds.attrs["license"] == stated.license
            assert ds.attrs["attribution_file"] == str(ATTRIBUTION.resolve())
            assert ds.attrs["attribution_sha256"] == sha256_of(ATTRIBUTION)
            assert ds.attrs["attribution_from"] == "the environment variable ADCPDYN_ATTRIBUTION"
    (tmp_path / "own.toml").write_text('creator_name = "Someone Else"\n')
    own = api.to_xarray(case_path, attribution=tmp_path / "own.toml").attrs
    assert own["creator_name"] == "Someone Else" and own["attribution_from"] == "the attribution option"
    assert own["attribution_file"] == str((tmp_path / "own.toml").resolve())
    assert "attribution_file" not in api.to_xarray(case_path, attribution=stated).attrs  # no file, none named
    # a corrected HDF5 file holds no attribution: the variable is not read
    monkeypatch.setenv("ADCPDYN_ATTRIBUTION", str(tmp_path / "missing.toml"))
    assert main(["correct", str(case_path), "--out", str(tmp_path / "c.h5")]) == 0
    capsys.readouterr()
    assert main(["export", str(case_path), "--out", str(tmp_path / "bad.nc")]) == 2
    err = capsys.readouterr().err
    assert f"ADCPDYN_ATTRIBUTION: {tmp_path / 'missing.toml'}: no such file" in err and err.count("\n") == 1
    assert not (tmp_path / "bad.nc").exists()
    (tmp_path / "bad.toml").write_text('creator_email = "nobody"\n')
    monkeypatch.setenv("ADCPDYN_ATTRIBUTION", str(tmp_path / "bad.toml"))
    with pytest.raises(ValueError, match=r"^ADCPDYN_ATTRIBUTION: bad.toml: creator_email: expected an e-mail address"):
        api.to_xarray(case_path)
    monkeypatch.setenv("ADCPDYN_ATTRIBUTION", "")
    assert api.to_xarray(case_path).attrs["creator_name"] == "not stated"
