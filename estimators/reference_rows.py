"""The numbers a run's reference rows take at a reference shift.

A reference row compares the reference's velocity sample with the navigation at the time the
sample holds, t - shift (the current estimate of a reference latency): the sensor's attitude
there, the navigation's interpolation weights there (their mean over each window for
differenced positions) and, where an effect asks, the navigation's slope. Nothing else in the
model depends on the shift, so a model at another shift rebuilds these rows only
(:meth:`.measurement_model.SurveyModel.at_reference_shift`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .knots import hat_basis_sparse, slope_basis_sparse, sparse_dm, window_basis_sparse

ROTATION_STEP_S = 0.05  # central-difference step of the reference point's rotational velocity (its slope)


def reference_numbers(run, slope: bool) -> dict:
    """The numbers of ``run``'s reference rows at its ``reference_shift_s``: ``shift`` (1, 1);
    the times the samples hold (``t``, or each window's ends ``a``, ``b``: (1, L)) and, for the
    central difference of the rotational velocity, ``t-`` and ``t+``; ``segment <key>``: the
    sensor's segments at those times (samples only); ``basis``: the navigation's weights there
    (scipy sparse, L x knots); with ``slope`` its time derivative's, ``slope``."""
    d, knots = float(run.reference_shift_s), run.knots
    out = {"shift": np.array([[d]])}
    if run.reference_window_s is None:
        t = run.reference_time_s - d
        times = {"t": t}
        out["basis"] = hat_basis_sparse(t, knots)
        if slope:
            out["slope"] = slope_basis_sparse(t, knots)
            times.update({"t-": t - ROTATION_STEP_S, "t+": t + ROTATION_STEP_S})
    else:
        w = run.reference_window_s - d
        times = {"a": w[:, 0], "b": w[:, 1]}
        out["basis"] = window_basis_sparse(w, knots)
        if slope:  # d/dt of a window mean: (x(b) - x(a)) / (b - a)
            ends = [hat_basis_sparse(w[:, j], knots) for j in (0, 1)]
            out["slope"] = sp.csr_matrix(sp.diags(1.0 / (w[:, 1] - w[:, 0])) @ (ends[1] - ends[0]))
    for key, t in times.items():
        out[key] = t[None, :]
        if run.attitude_source == "samples":
            out["segment " + key] = run.samples.params_at(t + run.sample_shift_s, run.sample_tilt_lead_s)
    return out


def as_constants(numbers: dict) -> dict:
    """:func:`reference_numbers` as CasADi constants (the weights keep their sparsity)."""
    return {key: sparse_dm(v) if sp.issparse(v) else ca.DM(v) for key, v in numbers.items()}
