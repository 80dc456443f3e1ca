"""How good is a calibration, judged on what the data determine (simulated cases).

Raw lever-arm coordinates are partly unobservable, so the primary figure is the one
that matters for the correction: the per-beam tangential radial velocity
(dLambda/dt r_i) . d_i that the estimated lever arms predict along the TRUE motion,
against the truth's (``docs/notes-on-the-paper.md``).
"""

from __future__ import annotations

import json

import numpy as np

from ...cases.case import Case
from ...models.motion import AttitudeParams, evaluate_attitude
from ...models.rotations import euler_matrix


def true_attitude(case: Case) -> AttitudeParams:
    """The simulator's vessel attitude model, from ``/truth`` attributes."""
    if case.truth is None or "attitude_model" not in case.truth.extra_attrs:
        raise ValueError(f"{case.name}: /truth.attrs[\"attitude_model\"]: missing; expected a case simulated by adcpdyn")
    return AttitudeParams.from_dict(json.loads(case.truth.extra_attrs["attitude_model"]))


def tangential_radial_velocity(case: Case, lever_arms_sensor_m: np.ndarray, frame: str) -> np.ndarray:
    """(N, 4) tangential radial velocities along the true motion for lever arms in the sensor frame."""
    truth = case.truth
    out = evaluate_attitude(true_attitude(case), case.pings.time_s)
    Ltb = np.asarray(euler_matrix(*truth.installation_ypr_rad))
    r_body = lever_arms_sensor_m @ Ltb.T if frame == "transducer" else lever_arms_sensor_m
    d = np.einsum("nij,kj->nki", out["Lambda"] @ Ltb, case.instrument.beam_directions())
    v = np.einsum("nij,kj->nki", out["dLambda_dt"], r_body)
    return np.sum(v * d, axis=-1)


def calibration_errors(case: Case, result) -> dict:
    """Errors of a :class:`~adcpdyn.estimators.calibration.result.CalibrationResult` against truth."""
    truth = case.truth
    frame = result.attitude_frame
    Ltb = np.asarray(euler_matrix(*truth.installation_ypr_rad))
    true_sensor = truth.radius_vectors_m @ Ltb if frame == "transducer" else truth.radius_vectors_m
    v_true = tangential_radial_velocity(case, true_sensor, frame)
    v_est = tangential_radial_velocity(case, result.lever_arms_sensor_m, frame)
    err = result.lever_arms_sensor_m - true_sensor
    se = result.lever_arms_sensor_se_m
    ok = np.isfinite(se) & (se > 0)
    # error in the observable subspace, in units of the reported covariance (the bound)
    lam, V = np.linalg.eigh(result.lever_arms_cov_m2)
    keep = lam > 1e-12 * max(lam.max(), 1e-300)
    proj = V[:, keep].T @ err.reshape(-1)
    out = {
        "observable_rank": int(keep.sum()),
        "observable_mahalanobis2": float(np.sum(proj**2 / lam[keep])),
        "tangential_radial_rms_m_s": float(np.sqrt(np.mean((v_est - v_true) ** 2))),
        "tangential_radial_signal_rms_m_s": float(np.sqrt(np.mean(v_true**2))),
        "lever_arm_rms_error_m": float(np.sqrt(np.mean(err**2))),
        "lever_arm_max_abs_z": float(np.max(np.abs(err[ok] / se[ok]))) if ok.any() else float("nan"),
        "lever_arm_z": np.where(ok, err / np.where(ok, se, 1.0), np.nan).reshape(-1).tolist(),
    }
    if frame == "vessel" and result.installation_determined:
        d = result.installation_ypr_rad - truth.installation_ypr_rad
        out["installation_error_rad"] = d.tolist()
        out["installation_z"] = (d / result.installation_ypr_se_rad).tolist()
    return out
