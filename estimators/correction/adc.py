"""Attitude dynamic correction (ADC): every ping corrected for the tangential velocity of
each transducer and for the turning of the beams between transmit and receive
(Section 3.3).

Per ping and beam, with d_T, d_R the beam directions at transmit and receive (t_R from
the geometry, Eqs. 66-68, with the transducer's motion along the beam, see
:mod:`adcpdyn.models.measurement`), u_T, u_R the tangential velocities along them and
rho = f / f0 = (c + v) / (c - v) from the measured radial velocity (Eq. 84), the
two-way Doppler equation (Eq. 70) multiplied out is linear in the vessel velocity:

    V_a . (d_R + rho d_T) = (rho - 1) c - (u_R + rho u_T)          (Eq. 89, four beams)

``adc`` solves the four equations by least squares with an error velocity, as real
four-beam ADCPs do (the paper's Eq. 94 uses beams 2, 3, 4 only; erratum 4), vectorised
over pings; a ping with one beam lost falls back to the exact three-beam solution and
says so in ``beams_used``. ``paper_literal`` is Eqs. 79-81 and 94 as printed: beams 2,
3, 4 and the frame-mixing Omega r. ``rootfinder`` solves the unmultiplied four-beam equations
exactly per ping by inverting the measurement model the calibration fits (:mod:`adcpdyn.solvers.rootfinder`). ``oracle`` is that exact solve
with the true attitude, lever arms and installation angles of a simulated case: the
floor the others are judged against. Water cells are corrected the same way from Eq. 88 multiplied out (Eq. 95,
four beams by least squares; the paper's Eq. 98 uses three) with the corrected vessel
velocity.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ...cases.case import Case
from ...models.doppler import ratio_from_radial, receive_time_paper, slant_range
from ...models.janus import beam_to_instrument
from ...models.kinematics import centre_of_rotation_depth
from ...models.motion import AttitudeParams, SampledAttitude, evaluate_attitude
from ...models.rotations import euler_matrix
from ...models.sensors import compass_correction
from ...cases.corrected import Correction, CorrectionProvenance
from ..attitude_fit import fit_attitude, sampled_attitude
from ..calibration.record import AppliedCalibration, CalibrationRecord

METHODS = ("adc", "paper_literal", "rootfinder", "oracle")


def _beam_state(attitude: AttitudeParams, times: np.ndarray, Lst, B, r, tangential: str, ping_time_s=None):
    """Beam directions d (..., 3), tangential velocities (..., 3) and Lambda at ``times``.

    ``times`` is (N, 1) (one time per ping, all beams), (N, 4) or (N, 4, K): beams along
    axis 1. Directions d_i = Lambda Lambda_st b_i (Eqs. 26-29), tangential velocity
    dLambda/dt r_i (Eq. 24), or Omega r_i when ``tangential="paper_literal"``. With the
    sensor's samples as attitude, each ping's sample segment at ``ping_time_s`` (N,) is
    extended to its receive times, as in the calibration's measurement model.
    """
    anchor = None
    if ping_time_s is not None:
        anchor = np.broadcast_to(np.reshape(ping_time_s, (-1,) + (1,) * (times.ndim - 1)), times.shape).reshape(-1)
    flat = evaluate_attitude(attitude, times.reshape(-1), anchor)
    Lam = flat["Lambda"].reshape(times.shape + (3, 3))
    tang = flat["dLambda_dt" if tangential == "consistent" else "Omega"].reshape(times.shape + (3, 3))
    shape = (1, 4) + (1,) * (times.ndim - 2) + (3, 1)
    d = ((Lam @ Lst) @ B.reshape(shape))[..., 0]
    v = (tang @ r.reshape(shape))[..., 0]
    return d, v, Lam


def _transducer_depths(case: Case, Lam_T: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Depth of each transducer at transmit, (N, 4) (Eq. 66); G sits below the level head by r_z."""
    return _g_depth(case, r) + np.einsum("nj,kj->nk", Lam_T[:, 0, 2, :], r)


def _g_depth(case: Case, r: np.ndarray) -> float:
    """Depth of the centre of rotation G (:func:`~adcpdyn.models.kinematics.centre_of_rotation_depth`)."""
    return centre_of_rotation_depth(case.environment.transducer_depth_m, r)


def _geometry(case: Case, attitude: AttitudeParams, lever_arms_s, ypr_st, tangential: str, timing: str = "deep",
              rows=slice(None), options=None):
    """A (N, 4, 3) and b (N, 4) of Eq. 89 for every ping (or the pings ``rows``) and beam, and their
    four-beam least squares V (N, 3), e (N,) (:func:`~adcpdyn.solvers.rootfinder.closed_form_bottom_track`)."""
    from ...solvers.rootfinder import closed_form_bottom_track

    return closed_form_bottom_track(**_ping_model(case, attitude, lever_arms_s, ypr_st, rows), timing=timing,
                                    tangential=tangential, options=options)


def _ping_model(case: Case, attitude: AttitudeParams, lever_arms_s, ypr_st, rows) -> dict:
    """Arguments of the per-ping solves (:mod:`adcpdyn.solvers.rootfinder`) for the pings ``rows``."""
    t = case.pings.time_s[rows]
    r = np.asarray(lever_arms_s, dtype=float)
    B = case.instrument.beam_directions()
    sampled = isinstance(attitude, SampledAttitude)
    return {"layout": None if sampled else attitude.layout, "attitude_p": np.zeros(0) if sampled else attitude.pack(),
            "lever_arms_m": r, "ypr_st_rad": ypr_st, "g_depth_m": _g_depth(case, r), "time_s": t,
            "depth_m": case.environment.depth_at_pings(case.pings.n)[rows], "radial_m_s": case.pings.bt_radial_m_s[rows],
            "sound_speed_m_s": case.instrument.sound_speed_m_s, "beam_dirs_t": B, "error_row": beam_to_instrument(B)[1],
            "ping_attitude": attitude.params_at(t) if sampled else None}


def _water(case: Case, attitude: AttitudeParams, lever_arms_s, ypr_st, vessel_velocity, tangential: str, timing: str):
    """Water velocity per ping and cell from Eq. 88 multiplied out (Eq. 95), four beams.

    With rho_n = f_n / f0 from the measured relative water radial (Eq. 85 in instrument
    sign), u the transducer's velocity along the beam at transmit (T) and at the cell's
    receive time (R, Eqs. 86-87) and d_T, d_R the beam directions then:
        V_n . [rho_n (c - u_T) d_R + (c + u_R) d_T] = c [(c + u_R) - rho_n (c - u_T)]
    """
    t = case.pings.time_s
    N = t.size
    cells = case.water.cell_depth_m
    K = cells.size
    c = case.instrument.sound_speed_m_s
    B = case.instrument.beam_directions()
    Lst = np.asarray(euler_matrix(*ypr_st))
    r = np.asarray(lever_arms_s, dtype=float)
    d_T, w_T, Lam_T = _beam_state(attitude, t[:, None], Lst, B, r, tangential)
    u_T = np.sum((w_T + vessel_velocity[:, None, :]) * d_T, axis=-1)  # (N, 4)
    l = slant_range(cells[None, None, :], _transducer_depths(case, Lam_T, r)[..., None], d_T[..., 2][..., None])  # Eq. 86
    t_R = np.broadcast_to(t[:, None, None], l.shape) if timing == "shallow" else receive_time_paper(t[:, None, None], l, c)  # Eq. 87
    d_R, w_R, _ = _beam_state(attitude, t_R, Lst, B, r, tangential, t)  # (N, 4, K, 3)
    u_R = np.sum((w_R + vessel_velocity[:, None, None, :]) * d_R, axis=-1)  # (N, 4, K)
    rho = ratio_from_radial(case.water.radial_m_s, c)  # (N, 4, K)
    uT = u_T[..., None]
    A = rho[..., None] * (c - uT)[..., None] * d_R + (c + u_R)[..., None] * d_T[:, :, None, :]
    b = c * ((c + u_R) - rho * (c - uT))
    A = A.transpose(0, 2, 1, 3).reshape(N * K, 4, 3) / (2 * c)  # per (ping, cell): ~ d, radial units
    b = b.transpose(0, 2, 1).reshape(N * K, 4) / (2 * c)
    V, _, _ = _solve(A, b, B, [True] * 4)
    return V.reshape(N, K, 3)


def _solve(A, b, beam_dirs_t, beams_allowed, four_beam=None):
    """Least squares per ping with error velocity; exact three-beam fallback. ``four_beam``:
    (V, e) of the pings' four-beam least squares when already solved (:func:`_geometry`)."""
    N = A.shape[0]
    use = np.isfinite(b) & np.asarray(beams_allowed)[None, :]
    n_good = use.sum(axis=1)
    V = np.full((N, 3), np.nan)
    err = np.full(N, np.nan)
    _, e_row = beam_to_instrument(beam_dirs_t)
    full = n_good == 4
    if full.any() and four_beam is not None:
        V[full], err[full] = four_beam[0][full], four_beam[1][full]
    elif full.any():
        Af, bf = A[full], b[full]
        At = Af.transpose(0, 2, 1)
        V[full] = np.linalg.solve(At @ Af, At @ bf[..., None])[..., 0]  # normal equations: A ~ 2 d, well conditioned
        resid = (bf - (Af @ V[full][..., None])[..., 0]) / 2  # A ~ 2 d: back to radial units
        err[full] = resid @ e_row
    three = n_good == 3
    if three.any():
        Ai = A[three][use[three]].reshape(-1, 3, 3)
        bi = b[three][use[three]].reshape(-1, 3)
        V[three] = np.linalg.solve(Ai, bi[..., None])[..., 0]
    return V, err, n_good


def _rootfind(case: Case, attitude: AttitudeParams, lever_arms_s, ypr_st, timing: str, options=None):
    """Exact four-beam solve of every complete ping; the closed form's three-beam solution elsewhere."""
    from ...solvers.rootfinder import solve_bottom_track

    bt = case.pings.bt_radial_m_s
    n_good = np.isfinite(bt).sum(axis=1)
    N = n_good.size
    V, err = np.full((N, 3), np.nan), np.full(N, np.nan)
    info = {"rootfinder_newton_pings": 0, "rootfinder_fallback_pings": 0, "rootfinder_unconverged_pings": 0}
    B = case.instrument.beam_directions()
    full = np.flatnonzero(n_good == 4)
    if full.size:
        rows = slice(None) if full.size == N else full  # views, not copies, when every ping has four beams
        out = solve_bottom_track(**_ping_model(case, attitude, lever_arms_s, ypr_st, rows), timing=timing, options=options)
        V[rows], err[rows] = out["V"], out["e"]
        info.update({f"rootfinder_{k}": out[k] for k in ("newton_pings", "fallback_pings", "unconverged_pings")},
                    rootfinder_max_residual_m_s=float(np.nanmax(out["residual"])))
    three = np.flatnonzero(n_good == 3)
    if three.size:
        geo = _geometry(case, attitude, lever_arms_s, ypr_st, "consistent", timing, rows=three)
        V[three], err[three], _ = _solve(geo["A"], geo["b"], B, [True] * 4)
    return V, err, n_good, info


def with_heading_misalignment(case: Case, applied: AppliedCalibration | None) -> Case:
    """The case with a head sensor's heading readings turned by the calibration's heading misalignment.

    For a sensor inside the head, the misalignment found against the reference (compass error,
    magnetic declination) is an Earth-frame heading offset, Rz(d) Lambda = Lambda(psi + d): it is
    applied to the readings, like TRDI's heading bias (EB), with the compass's one-cycle deviation
    when the calibration found one (:func:`~adcpdyn.models.sensors.compass_correction`). Other
    cases are returned unchanged.
    """
    delta = None if applied is None else applied.heading_misalignment_rad
    if delta is None or case.attitude.frame != "transducer":
        return case
    psi = case.attitude.heading_rad
    correction = compass_correction(psi, delta, *applied.compass_deviation)
    att = dataclasses.replace(case.attitude, heading_rad=psi + correction)
    return case.replace(attitude=att)


def dynamic_correction(case: Case, method: str = "adc", calibration: CalibrationRecord | AppliedCalibration | None = None,
                       attitude: AttitudeParams | None = None, timing: str = "deep",
                       rootfinder_options=None, water_reference: str = "bt") -> Correction:
    """Correct every ping of a case (see module docstring).

    Parameters
    ----------
    case : Case
    method : str
        ``adc``, ``paper_literal``, ``rootfinder`` or ``oracle``.
    calibration : CalibrationRecord or AppliedCalibration
        Lever arms, installation angles, heading correction, attitude source (a record is resolved
        for this run once, :meth:`~adcpdyn.estimators.calibration.record.CalibrationRecord.applied_to`);
        not used by ``oracle``.
    attitude : AttitudeParams, optional
        Attitude model of this run in the sensor frame (default: fitted to its samples).
    timing : str
        ``deep`` (transmit and receive at their own times, Eqs. 66-70), ``shallow``
        (the paper's shallow-water approximation: the round trip taken as instantaneous)
        or ``exact`` (rootfinder and oracle: the travel time solved with the transducer
        moving during the flight, :mod:`adcpdyn.models.measurement`).
    rootfinder_options : RootfinderOptions, optional
        Newton steps, threads and compilation of the exact solve (``rootfinder``, ``oracle``).
    water_reference : str
        Water cells solved with the corrected bottom-track vessel velocity (``bt``) or with
        the centre of rotation's velocity from the GNSS (``gnss``:
        :func:`~adcpdyn.estimators.water.centre_velocity_from_reference`); either way the
        velocity relative to G (solved with G at rest) is kept too.
    """
    if timing not in ("deep", "shallow", "exact"):
        raise ValueError(f"timing: expected 'deep', 'shallow' or 'exact', got {timing!r}")
    if timing == "exact" and method not in ("rootfinder", "oracle"):
        raise ValueError(f"timing: 'exact' (travel time with the moving transducer) is for the rootfinder and the "
                         f"oracle; method {method!r} uses Eq. 68's travel time ('deep')")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {list(METHODS)}, got {method!r}")
    if method == "oracle":
        if case.truth is None or "attitude_model" not in case.truth.extra_attrs:
            raise ValueError(f"{case.name}: /truth: the oracle needs a case simulated by adcpdyn (true attitude model)")
        from ..calibration.file import attitude_model_from

        attitude = attitude_model_from(case.truth.extra_attrs["attitude_model"],
                                       f'{case.name}: /truth.attrs["attitude_model"]')
        lever, ypr_st = case.truth.radius_vectors_m, case.truth.installation_ypr_rad  # vessel frame
    else:
        if calibration is None:
            raise ValueError(f"calibration: required for method {method!r} (run `adcpdyn calibrate` first)")
        if isinstance(calibration, CalibrationRecord):
            calibration = calibration.applied_to(case, case.attitude.frame, dynamic=True)
        if calibration.lever_arms_sensor_m is None:
            raise ValueError(f"calibration: resolved for the static correction (no lever arms); method {method!r} "
                             "needs CalibrationRecord.applied_to(..., dynamic=True)")
        case = with_heading_misalignment(case, calibration)
        lever, ypr_st = calibration.lever_arms_sensor_m, calibration.beam_installation_ypr_rad
        if attitude is None and calibration.attitude_source == "samples":  # as the calibration's beams
            attitude = sampled_attitude(case, interpolation=calibration.attitude_interpolation)
        attitude = attitude or fit_attitude(case).params
    tangential = "paper_literal" if method == "paper_literal" else "consistent"
    if method in ("rootfinder", "oracle"):
        V, err, n_good, info = _rootfind(case, attitude, lever, ypr_st, timing, rootfinder_options)
    else:
        geo = _geometry(case, attitude, lever, ypr_st, tangential, timing)
        allowed = [False, True, True, True] if method == "paper_literal" else [True] * 4
        V, err, n_good = _solve(geo["A"], geo["b"], case.instrument.beam_directions(), allowed, (geo["V"], geo["e"]))
        info = {}
    water, relative = None, None
    if case.water is not None:
        water, relative, info["water_reference"], info["water_reference_note"] = _referenced_water(
            case, attitude, lever, ypr_st, V, tangential, timing, water_reference, calibration, method == "oracle")
    provenance = CorrectionProvenance(lever_arms_sensor_m=np.asarray(lever), installation_ypr_rad=np.asarray(ypr_st),
                                      timing=timing, **info)
    return Correction(method=method, time_s=case.pings.time_s.copy(), vessel_velocity_m_s=V, error_velocity_m_s=err,
                      beams_used=n_good, water_velocity_m_s=water, provenance=provenance,
                      water_relative_velocity_m_s=relative)


def _referenced_water(case, attitude, lever, ypr_st, V, tangential, timing, reference, calibration, oracle):
    """Water cells referenced to the bottom track (``V``) or the GNSS, and relative to G (G at rest)."""
    from ..water import REFERENCE_NOTES, centre_velocity_from_reference, check_reference, reference_point_in_sensor_frame

    check_reference(reference, case)
    if reference == "gnss":
        nominal = None if calibration is None else calibration.nominal_installation_ypr_rad
        V = centre_velocity_from_reference(case, attitude, reference_point_in_sensor_frame(case, nominal, oracle))
    water = _water(case, attitude, lever, ypr_st, V, tangential, timing)
    relative = _water(case, attitude, lever, ypr_st, np.zeros_like(V), tangential, timing)
    note = REFERENCE_NOTES[reference] + ("; each cell solved with that vessel velocity (Eq. 95), the relative velocity "
                                         "with the centre of rotation at rest")
    return water, relative, reference, note
