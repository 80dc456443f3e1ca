"""The words of a diagnosis's statement beyond its numbers: why an effect cannot be told from
what it is confounded with (a compass error or a bed on one course), what a remaining gap on a
random-walk base is not, a sound-speed
estimate in the field's terms, and the note when the runs diagnosed are a calibration's own,
calibrated on another navigation than the base's. Apart from the orchestrator (:mod:`.diagnose`),
which composes them with the numbers.
"""

from __future__ import annotations

import numpy as np

from ..attitude_fit import undersampled_axes
from .model import DiagnosisBase, GapModel
from ..calibration.moving_bed_decision import mean_flow
from ..measurement_model import ANGLE_NAMES
from .readings import bed_reading, sound_speed_reading
from .selection import EffectScore


def _courses(base: DiagnosisBase) -> list:
    """Each moving-reference run's mean course over ground (deg, as text)."""
    courses = []
    for r in base.runs:
        if r.moving_reference:
            v = r.reference_velocity_m_s[:, :2]
            ok = np.all(np.isfinite(v), axis=1)
            courses.append(f"{np.rad2deg(np.angle(np.mean(np.exp(1j * np.arctan2(v[ok, 1], v[ok, 0]))))) % 360:.0f}")
    return courses


def confounding_reason(effect: str, names: list, base: DiagnosisBase) -> str:
    """Why two things are not told apart here, in the field's words."""
    joined = ", ".join(names)
    if effect == "moving_bed" and any(n.startswith(("heading_misalignment", "installation_yaw")) for n in names):
        courses = _courses(base)
        return (f"moving bed vs {'heading misalignment' if base.spec.heading != 'off' else 'installation yaw'}: "
                f"{'one course' if len(courses) == 1 else 'courses'} over ground {', '.join(courses)} deg, along which a bed "
                "moving under the bottom track and a heading error look alike; calibrate transects in several directions "
                "together (calibrate --joint) and diagnose with that calibration")
    return f"{effect} vs {joined}: these data do not tell them apart"


HEADING_EFFECTS = ("compass_offset", "compass_deviation")


def compass_or_bed(chosen: str, significant: list, base: DiagnosisBase) -> dict | None:
    """On one run, the words for a compass error chosen while a moving bed is significant too (or the
    other way round): across one course both turn the bottom track against the reference alike
    (a bed u across a course at speed s looks like a heading error of atan(u / s)), and only
    runs on other courses tell what is constant across runs (the bed may change, the compass does
    not): ``{"chosen", "significant_too", "statement"}``, None with several runs or no such pair."""
    if len(base.runs) != 1 or chosen not in (*HEADING_EFFECTS, "moving_bed"):
        return None
    rivals = [s for s in significant if s != chosen and (s == "moving_bed") != (chosen == "moving_bed")
              and s in (*HEADING_EFFECTS, "moving_bed")]
    if not rivals:
        return None
    courses = _courses(base)
    where = f" (course over ground {courses[0]} deg)" if courses else ""
    words = (f"{' and '.join(rivals)} {'is' if len(rivals) == 1 else 'are'} significant too: on one run{where} a compass "
             f"error and a bed moving across the course turn the bottom track against the reference alike, so this run "
             f"cannot say which it is; calibrate runs on several courses together (calibrate --joint) and diagnose with "
             f"that calibration")
    return {"chosen": chosen, "significant_too": rivals, "statement": words}


def not_the_base(model: GapModel) -> str:
    """What a remaining gap on a random-walk base is not: the boat's ping-to-ping motion (the
    base's velocity per ping follows it) nor noise levels set by hand (they are the data's)."""
    if not model.random_walk:
        return ""
    return ("; not the boat's ping-to-ping motion (the base gives it a velocity at every ping) nor noise levels "
            "set by hand (each channel's is the data's own)")


BED_KEYS = ("moving_bed.velocity_north_m_s", "moving_bed.velocity_east_m_s")


def base_flow(cases: list, base_model: GapModel, base_fit) -> dict | None:
    """What a named bed is read against, on one run: ``{"flow"}`` the run's flow in the base's
    true-Earth frame (its heading misalignment, or its installation angles, estimated, pinned or
    nominal, turning the sensed one, :func:`...calibration.moving_bed_decision.mean_flow`) and
    ``{"bed"}`` the base's own bed (the calibration's, pinned), or None (several runs, or no water
    profile)."""
    if len(cases) != 1:
        return None
    values = base_fit.values
    nominal = base_model.base.spec.nominal_installation_ypr_rad
    flow = mean_flow(cases, [values.get(n, a) for n, a in zip(ANGLE_NAMES, nominal)], values.get("heading_misalignment", 0.0))
    if flow is None:
        return None
    return {"flow": flow, "bed": np.array([values.get("moving_bed_north", 0.0), values.get("moving_bed_east", 0.0)])}


def reading_of(score: EffectScore, cases: list, against: dict | None = None) -> dict:
    """``{"reading": {..., "text"}}``: a sound-speed error's estimate in the field's terms
    (:func:`.readings.sound_speed_reading`: the water's sound speed, and the salinity that gives it at
    the recorded temperature); a moving bed's direction against the flow's where ``against``
    (:func:`base_flow`) gives it (:func:`.readings.bed_reading`); ``{"aliased": {..., "text"}}``: an
    attitude latency on samples too sparse for the motion, where delays whole sample intervals apart
    fit nearly alike (winriver01's injected 0.3 and 1.0 s read -0.98 and -0.27 s, 1.3 s off); empty
    for other effects."""
    if score.effect == "moving_bed":
        if against is None or not all(k in score.params for k in BED_KEYS):
            return {}
        se = [score.params_se.get(k, np.nan) for k in BED_KEYS]
        return {"reading": bed_reading([score.params[k] for k in BED_KEYS], se, against["flow"], against["bed"])}
    if score.effect == "attitude_latency":
        fast = [(c, undersampled_axes(c)) for c in cases]
        fast = [(c, f) for c, f in fast if f]
        if not fast:
            return {}
        dt = max(float(np.median(np.diff(c.attitude.time_s))) for c, _ in fast)
        axes = ", ".join(dict.fromkeys(n for _, f in fast for n in f))
        return {"aliased": {"sample_interval_s": dt, "axes": axes,
                            "text": f"the attitude samples ({dt:.2f} s apart) are too sparse for the motion ({axes}: most "
                                    f"of its variance above half their Nyquist frequency), so delays whole sample intervals "
                                    f"apart fit nearly alike: this one may be off by a multiple of {dt:.2f} s"}}
    key = "sound_speed_error.relative_error"
    if score.effect != "sound_speed_error" or key not in score.params:
        return {}
    ins = cases[0].instrument
    return {"reading": sound_speed_reading(ins.sound_speed_m_s, score.params[key], score.params_se.get(key, float("nan")),
                                           ins.temperature_c, ins.salinity_psu, cases[0].environment.transducer_depth_m)}


RECALIBRATED = ("compass_offset", "compass_deviation", "moving_bed")  # effects on quantities a calibration fits


OTHER_BASE = "these are the calibration's own runs, calibrated on"  # the note's opening words (calibrate quotes it)


def calibration_base_note(calibration, base, chosen: list) -> str:
    """What to say when the runs diagnosed are the calibration's own, calibrated on another
    navigation than this base's, and an effect on a quantity the calibration fitted (heading, bed)
    is named: on the same data two bases can read that quantity apart (knots miss a real boat's
    motion between fixes), so the effect may be the bases' difference rather than a change since
    the calibration. ``chosen``: the selected effects' scores, each of the round that chose it
    (a bed significant from round 1 and chosen in round 2 is quoted as round 2 read it). '' otherwise."""
    named = [s for s in chosen if s.effect in RECALIBRATED]
    if calibration is None or not named:
        return ""
    own = [calibration.run_of(r.case) for r in base.runs]
    if any(o is None or o.navigation is None for o in own):  # not its runs, or a file older than the record
        return ""
    differs = {(o.navigation, r.navigation) for o, r in zip(own, base.runs) if o.navigation != r.navigation}
    if not differs:
        return ""
    calibrated, here = (", ".join(sorted({pair[i] for pair in differs})) for i in (0, 1))
    found = []
    for score in named:
        for key, value in score.params.items():
            se = score.params_se.get(key)
            angle = key.endswith("A_rad")
            if angle or "moving_bed" in key:
                label, unit, k = (key[:-4], "deg", np.degrees(1.0)) if angle else (key.removesuffix("_m_s"), "m/s", 1.0)
                found.append(f"{label} {k * value:+.3g}" + (f" +- {k * se:.2g}" if se is not None else "") + f" {unit}")
    extra = ""
    if calibration.heading_misalignment_se_rad is not None and any(s.effect.startswith("compass") for s in named):
        extra = f" (the calibration's heading misalignment: +- {np.degrees(calibration.heading_misalignment_se_rad):.2g} deg)"
    return (f"{OTHER_BASE} {calibrated} navigation while this base takes {here}: "
            f"{', '.join(found)}{extra} may be the two bases reading the same data apart rather than a change since the "
            f"calibration; to tell, calibrate with --navigation {here} (this base) and diagnose again: what is still "
            f"named then is in these runs' data, not the bases' difference")
