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
exactly per ping (:mod:`adcpdyn.solvers.rootfinder`). ``oracle`` is that exact solve
with the true attitude, lever arms and installation angles of a simulated case: the
floor the others are judged against. Water cells are corrected the same way from Eq. 88 multiplied out (Eq. 95,
four beams by least squares; the paper's Eq. 98 uses three) with the corrected vessel
velocity.
"""

from __future__ import annotations

import json

import numpy as np

from ..cases.case import Case
from ..models.doppler import ratio_from_radial
from ..models.janus import beam_to_instrument
from ..models.motion import AttitudeParams, evaluate_attitude
from ..models.rotations import euler_matrix
from .asc import Correction
from .attitude_fit import fit_attitude

METHODS = ("adc", "paper_literal", "rootfinder", "oracle")


def _geometry(case: Case, attitude: AttitudeParams, lever_arms_s, ypr_st, tangential: str, timing: str = "deep"):
    """A (N, 4, 3) and b (N, 4) of Eq. 89 for every ping and beam, and the beam geometry."""
    t = case.pings.time_s
    N = t.size
    c = case.instrument.sound_speed_m_s
    B = case.instrument.beam_directions()
    Lst = np.asarray(euler_matrix(*ypr_st))
    r = np.asarray(lever_arms_s, dtype=float)
    tx = evaluate_attitude(attitude, t)

    def beams(state, n_leading):
        L = state["Lambda"]
        d = np.einsum("...ij,kj->...ki", L @ Lst, B) if n_leading == 1 else np.einsum("...ij,...j->...i", L @ Lst, B)
        tang = state["dLambda_dt"] if tangential == "consistent" else state["Omega"]
        if n_leading == 1:
            v = np.einsum("nij,kj->nki", tang, r)
        else:
            v = np.einsum("...ij,...j->...i", tang, r)
        return d, np.sum(v * d, axis=-1), L

    d_T, u_T, L_T = beams(tx, 1)  # (N, 4, 3), (N, 4)
    g_depth = case.environment.transducer_depth_m - r[:, 2].mean()
    z_T = g_depth + np.einsum("nj,kj->nk", L_T[:, 2, :], r)  # Eq. 66
    depth = case.environment.depth_at_pings(N)[:, None]
    v_meas = case.pings.bt_radial_m_s
    l = (depth - z_T) / d_T[..., 2] * (1 - np.nan_to_num(v_meas) / c)  # Eq. 67, moving transducer
    t_R = t[:, None] + (2 * l / c if timing == "deep" else np.zeros_like(l))  # Eq. 68; "shallow": no flight
    rx_flat = evaluate_attitude(attitude, t_R.reshape(-1))
    rx = {k: v.reshape((N, 4) + v.shape[1:]) for k, v in rx_flat.items()}
    d_R, u_R, _ = beams(rx, 2)
    rho = ratio_from_radial(v_meas, c)
    A = d_R + rho[..., None] * d_T
    b = (rho - 1) * c - (u_R + rho * u_T)
    return {"A": A, "b": b, "d_T": d_T, "d_R": d_R, "u_T": u_T, "u_R": u_R}


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
    tx = evaluate_attitude(attitude, t)
    d_T = np.einsum("nij,kj->nki", tx["Lambda"] @ Lst, B)
    tang = "dLambda_dt" if tangential == "consistent" else "Omega"
    u_T = np.sum((np.einsum("nij,kj->nki", tx[tang], r) + vessel_velocity[:, None, :]) * d_T, axis=-1)  # (N, 4)
    g_depth = case.environment.transducer_depth_m - r[:, 2].mean()
    z_T = g_depth + np.einsum("nj,kj->nk", tx["Lambda"][:, 2, :], r)
    l = (cells[None, None, :] - z_T[..., None]) / d_T[..., 2][..., None]  # Eq. 86, (N, 4, K)
    t_R = t[:, None, None] + (2 * l / c if timing == "deep" else np.zeros_like(l))  # Eq. 87
    rx_flat = evaluate_attitude(attitude, t_R.reshape(-1))
    L_R = rx_flat["Lambda"].reshape(N, 4, K, 3, 3)
    T_R = rx_flat[tang].reshape(N, 4, K, 3, 3)
    beam = np.broadcast_to(B[None, :, None, :], (N, 4, K, 3))
    d_R = np.einsum("nkcij,nkcj->nkci", L_R @ Lst, beam)
    v_tan_R = np.einsum("nkcij,kj->nkci", T_R, r)
    u_R = np.sum((v_tan_R + vessel_velocity[:, None, None, :]) * d_R, axis=-1)  # (N, 4, K)
    rho = ratio_from_radial(case.water.radial_m_s, c)  # (N, 4, K)
    uT = u_T[..., None]
    A = rho[..., None] * (c - uT)[..., None] * d_R + (c + u_R)[..., None] * d_T[:, :, None, :]
    b = c * ((c + u_R) - rho * (c - uT))
    A = A.transpose(0, 2, 1, 3).reshape(N * K, 4, 3) / (2 * c)  # per (ping, cell): ~ d, radial units
    b = b.transpose(0, 2, 1).reshape(N * K, 4) / (2 * c)
    V, _, _ = _solve(A, b, B, [True] * 4)
    return V.reshape(N, K, 3)


def _solve(A, b, beam_dirs_t, beams_allowed):
    """Least squares per ping with error velocity; exact three-beam fallback."""
    N = A.shape[0]
    use = np.isfinite(b) & np.asarray(beams_allowed)[None, :]
    n_good = use.sum(axis=1)
    V = np.full((N, 3), np.nan)
    err = np.full(N, np.nan)
    _, e_row = beam_to_instrument(beam_dirs_t)
    full = n_good == 4
    if full.any():
        V[full] = np.einsum("nij,nj->ni", np.linalg.pinv(A[full]), b[full])
        resid = (b[full] - np.einsum("nkj,nj->nk", A[full], V[full])) / 2  # A ~ 2 d: back to radial units
        err[full] = resid @ e_row
    three = n_good == 3
    if three.any():
        Ai = A[three][use[three]].reshape(-1, 3, 3)
        bi = b[three][use[three]].reshape(-1, 3)
        V[three] = np.linalg.solve(Ai, bi[..., None])[..., 0]
    return V, err, n_good


def _rootfind(case: Case, geo: dict, V, err, n_good):
    """Exact four-beam solve of every complete ping, started from the closed form."""
    from ..solvers.rootfinder import doppler_rootfinder, error_direction, pack

    full = np.flatnonzero(n_good == 4)
    if full.size == 0:
        return V, err
    _, e_row = beam_to_instrument(case.instrument.beam_directions())
    rf = doppler_rootfinder(error_direction(e_row), case.instrument.sound_speed_m_s, full.size)
    p = pack(geo["d_T"][full], geo["d_R"][full], geo["u_T"][full], geo["u_R"][full], case.pings.bt_radial_m_s[full])
    x = np.asarray(rf(np.vstack([V[full].T, err[full][None, :]]), p))
    V, err = V.copy(), err.copy()
    V[full], err[full] = x[:3].T, x[3]
    return V, err


def lever_arms_from_calibration(calibration: dict, case: Case) -> tuple[np.ndarray, np.ndarray]:
    """(lever arms in the case's sensor frame, installation angles for beams) from CALIB.json contents."""
    def arr(key):
        value = calibration.get(key)
        if value is None:
            raise ValueError(f"calibration: {key}: missing; expected the output of `adcpdyn calibrate`")
        a = np.array(value, dtype=float)
        if np.any(~np.isfinite(a)):
            raise ValueError(f"calibration: {key}: contains undetermined (null) values; this calibration cannot correct")
        return a

    if case.attitude.frame == "transducer":
        return arr("radius_vectors_head_m"), np.zeros(3)
    return arr("radius_vectors_m"), arr("installation_ypr_rad")


def dynamic_correction(case: Case, method: str = "adc", calibration: dict | None = None,
                       attitude: AttitudeParams | None = None, timing: str = "deep") -> Correction:
    """Correct every ping of a case (see module docstring).

    Parameters
    ----------
    case : Case
    method : str
        ``adc``, ``paper_literal`` or ``oracle``.
    calibration : dict
        Contents of CALIB.json (lever arms, installation angles); not used by ``oracle``.
    attitude : AttitudeParams, optional
        Attitude model of this run in the sensor frame (default: fitted to its samples).
    timing : str
        ``deep`` (transmit and receive at their own times, Eqs. 66-70) or ``shallow``
        (the paper's shallow-water approximation: the round trip taken as instantaneous).
    """
    if timing not in ("deep", "shallow"):
        raise ValueError(f"timing: expected 'deep' or 'shallow', got {timing!r}")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {list(METHODS)}, got {method!r}")
    if method == "oracle":
        if case.truth is None or "attitude_model" not in case.truth.extra_attrs:
            raise ValueError(f"{case.name}: /truth: the oracle needs a case simulated by adcpdyn (true attitude model)")
        attitude = AttitudeParams.from_dict(json.loads(case.truth.extra_attrs["attitude_model"]))
        lever, ypr_st = case.truth.radius_vectors_m, case.truth.installation_ypr_rad  # vessel frame
    else:
        if calibration is None:
            raise ValueError(f"calibration: required for method {method!r} (run `adcpdyn calibrate` first)")
        lever, ypr_st = lever_arms_from_calibration(calibration, case)
        attitude = attitude or fit_attitude(case).params
    tangential = "paper_literal" if method == "paper_literal" else "consistent"
    geo = _geometry(case, attitude, lever, ypr_st, tangential, timing)
    allowed = [False, True, True, True] if method == "paper_literal" else [True] * 4
    V, err, n_good = _solve(geo["A"], geo["b"], case.instrument.beam_directions(), allowed)
    if method in ("rootfinder", "oracle"):
        V, err = _rootfind(case, geo, V, err, n_good)
    water = None
    if case.water is not None:
        water = _water(case, attitude, lever, ypr_st, V, tangential, timing)
    return Correction(method=method, time_s=case.pings.time_s.copy(), vessel_velocity_m_s=V, error_velocity_m_s=err,
                      beams_used=n_good, water_velocity_m_s=water, attrs={"lever_arms_sensor_m": np.asarray(lever).tolist(),
                                                "installation_ypr_rad": np.asarray(ypr_st).tolist(), "timing": timing})
