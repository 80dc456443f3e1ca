"""The verbs on case files themselves: scenarios, cache, simulate, import, info, export."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..terminal import say, warn


def read(path):
    from ...cases.io import read_case

    return read_case(path)


def cmd_scenarios(args) -> int:
    from ...cases.scenario import load_scenarios

    from ...cases.survey import survey_names

    surveys = set(survey_names())
    for name, sc in load_scenarios().items():
        label = " [survey: simulate --runs K for K transects]" if name in surveys else ""
        say(f"{name:<20} {sc.platform.name:<14} {sc.run.description}{label}", indent=" " * 36)
    return 0


def cmd_cache(args) -> int:
    from ...solvers import compiled

    folder = compiled.cache_dir()
    if args.clear:
        print(f"{folder}: removed {compiled.clear()} compiled model(s)")
        return 0
    found = compiled.entries()
    size_mb = sum(p.stat().st_size for p in found) / 1e6
    cc = compiled.compiler() or "none found (models are evaluated interpreted)"
    print(f"cache of compiled per-ping models: {folder} (set ${compiled.CACHE_ENV} to move it)")
    print(f"C compiler: {cc}; {len(found)} model(s), {size_mb:.2f} MB")
    for p in found[:args.list]:
        print(f"  {p.name}  {p.stat().st_size / 1e3:.0f} kB")
    return 0


def cmd_simulate(args) -> int:
    from ...cases.io import write_case
    from ...cases.scenario import get_scenario
    from ...cases.atomic import check_output_file
    from ...cases.simulation import simulate

    survey_options = {"--compass-deg": args.compass_deg, "--bed-speed": args.bed_speed, "--bed-profile": args.bed_profile}
    if args.runs is None:
        given = [k for k, v in survey_options.items() if v is not None]
        if given:
            raise ValueError(f"{given[0]}: only with --runs (a survey's transects)")
        check_output_file(args.out)
        case = simulate(get_scenario(args.scenario), seed=args.seed)
        write_case(case, args.out)
        print(f"wrote {args.out}: {case.pings.n} pings, {case.attitude.time_s.size} attitude samples")
        return 0
    return _simulate_survey(args)


def _simulate_survey(args) -> int:
    """``--runs K``: the survey's K transects, ``OUT/NAME_run01.h5`` ..., and what they share."""
    from ...cases.atomic import check_output_folder
    from ...cases.io import write_case
    from ...cases.survey import is_survey, simulate_survey, survey_names

    if not is_survey(args.scenario):
        raise ValueError(f"--runs: scenario {args.scenario!r} is not a survey; surveys: {survey_names()}")
    out = check_output_folder(args.out)
    compass = None if args.compass_deg is None else tuple(np.deg2rad(args.compass_deg))
    cases = simulate_survey(args.scenario, args.runs, args.seed, compass_rad=compass, bed_speed_m_s=args.bed_speed,
                            bed_profile=args.bed_profile)
    out.mkdir(parents=True, exist_ok=True)
    for case in cases:
        path = out / f"{case.name}.h5"
        write_case(case, path)
        info = json.loads(case.truth.extra_attrs["survey"])
        print(f"wrote {path}: {case.pings.n} pings, course {np.rad2deg(info['course_over_ground_rad']) % 360:.1f} deg, "
              f"crab {np.rad2deg(info['crab_angle_rad']):+.1f} deg, UTC start {case.time_origin_utc}, effective heading "
              f"misalignment {np.rad2deg(float(case.truth.extra_attrs['effective_heading_misalignment_rad'])):+.2f} deg")
    effects = {e["name"]: e["params"] for e in cases[0].truth.effects}
    abc = effects["compass_deviation"]
    bed = effects["moving_bed"]
    print(f"shared: compass A {np.rad2deg(abc['A_rad']):+.2f}, B {np.rad2deg(abc['B_rad']):+.2f}, "
          f"C {np.rad2deg(abc['C_rad']):+.2f} deg; moving bed {np.hypot(bed['velocity_north_m_s'], bed['velocity_east_m_s']):.3f} "
          f"m/s ({bed.get('profile', 'uniform')}), north {bed['velocity_north_m_s']:+.3f}, east {bed['velocity_east_m_s']:+.3f} m/s")
    return 0


def cmd_import(args) -> int:
    """A real instrument file (TRDI PD0, Nortek AD2CP) into a case file, with its audit trail."""
    from ...cases.atomic import check_output_file
    from ...cases.importers import Window, import_file, resalted, write_imported

    path = Path(args.file)
    check_output_file(args.out, path)
    case, attrs = import_file(path, Window(start_s=args.start, end_s=args.end, every=args.every))
    if args.salinity_psu is not None:
        case, attrs = resalted(case, attrs, args.salinity_psu)
    write_imported(case, attrs, args.out, source=path)
    prov = attrs["/provenance"]
    say(f"wrote {args.out}: {case.pings.n} pings over {case.pings.time_s[-1]:.1f} s, BT from "
        f"{prov['coordinate_system_found']} coordinates, attitude frame {case.attitude.frame}, "
        f"{int(np.sum(np.all(np.isfinite(case.pings.bt_radial_m_s), axis=1)))} pings with 4 valid beams")
    if "clock_offset_s" in prov:
        say(f"GNSS: {prov['gnss']}; clock offset GNSS - ADCP {prov['clock_offset_s']:+.2f} s "
            f"(coarse {prov['clock_offset_coarse_s']:+.2f} s, speed correlation {prov['clock_offset_correlation']:.3f})")
        if "bt_vs_gnss_speed_ratio_bt_over_gnss" in prov:
            say(f"BT vs GNSS: speed ratio {prov['bt_vs_gnss_speed_ratio_bt_over_gnss']:.3f}, course offset (GNSS - BT) "
                f"{prov['bt_vs_gnss_course_offset_gnss_minus_bt_deg']:+.1f} +- {prov['bt_vs_gnss_course_offset_se_deg']:.1f} deg "
                f"over {prov['bt_vs_gnss_n']} samples")
    else:
        say(f"GNSS: {prov.get('gnss', 'none')}")
    warning = attrs.get("/attitude", {}).get("attitude_warning")
    if warning:
        warn(f"attitude: {warning}")
    if prov.get("reader_messages"):
        warn(prov["reader_messages"])
    if "sound_speed_changed" in prov:
        say(f"sound speed: {prov['sound_speed_changed']}")
    return 0


def cmd_info(args) -> int:
    from ...cases.coverage import restrict_to_coverage
    from ...cases.validation import case_warnings
    from ...cases.summary import summarise

    case = read(args.case)
    print(summarise(case))
    for w in case_warnings(case):
        warn(f"{w}")
    try:
        note = restrict_to_coverage(case, source=str(args.case))[1]
    except ValueError as exc:  # info still describes the file; the verbs that use the attitude will refuse it
        note = f"{exc} (correct, compare, calibrate and diagnose refuse this case)"
    if note:
        warn(f"{note}")
    return 0


def prepare(path, say: bool = True):
    """Read a case for a verb that uses the attitude: its warnings (printed when ``say``) and the
    case restricted to what the attitude record covers (never extrapolated)."""
    from ...cases.coverage import restrict_to_coverage
    from ...cases.validation import case_warnings

    case = read(path)
    notes = case_warnings(case)
    case, note = restrict_to_coverage(case, source=str(path))
    if note:
        notes.append(note)
    if say:
        for w in notes:
            warn(f"{w}")
    return case, notes


def cmd_export(args) -> int:
    """A case, or a corrected file with its case, as CF-1.8 / ACDD-1.3 / IOOS-1.2 netCDF (xarray, h5netcdf)."""
    from ...cases.atomic import check_output_file
    from ...cases.netcdf import export_file

    if Path(args.out).suffix.lower() != ".nc":
        raise ValueError(f"--out: expected a netCDF file name ending in .nc, got {args.out!r}")
    check_output_file(args.out, args.input, args.case)
    ds = export_file(args.input, args.out, case_path=args.case, attribution=args.attribution,
                     history="adcpdyn export " + " ".join([args.input, "--out", args.out]
                                                          + (["--case", args.case] if args.case else [])
                                                          + (["--attribution", args.attribution] if args.attribution
                                                             else [])))
    what = f"method {ds.attrs['processing_method']}, " if "processing_method" in ds.attrs else ""
    water = f"{ds.sizes['depth']} cells, " if "depth" in ds.sizes else "no water profile, "
    dated = "time" in ds.coords
    say(f"wrote {args.out}: {what}{ds['case_time'].size} pings, {water}time "
        f"{'UTC' if dated else 'in case-clock seconds (no UTC origin)'}, {ds.attrs['Conventions']} (h5netcdf)")
    return 0
