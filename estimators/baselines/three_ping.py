"""The paper's exact radius-vector solve from three pings (Eqs. 53-58 shallow, 72-76 deep).

For each transducer, three pings give three equations linear in its lever arm r_i:
shallow (Eq. 52, frame-consistent): r_i . (dLambda^T d_i) = v_i - V_a . d_i;
deep (Eq. 70 multiplied out; the printed Eq. 71 is dimensionally inconsistent), with
rho = f / f0 = (c + v) / (c - v):
r_i . (dLambda_R^T d_R + rho dLambda_T^T d_T) = (rho - 1) c - V_a . (d_R + rho d_T).
The attitude comes from the two-stage fit (one mode per axis).

In the frame-consistent form every row dLambda^T d_i is orthogonal to the beam's
direction in the sensor frame (Lambda^T d_i is constant), so each 3x3 system has rank
2: a transducer sliding along its own beam changes no measurement. The paper's
systems are invertible only because Omega r (Eq. 31) mixes frames;
``tangential="paper_literal"`` reproduces that. The consistent solve returns the
minimum-norm solution and says the along-beam component is undetermined. The three
pings are the triple, among the ``candidates`` strongest-rotation pings, with the
best-conditioned determinable part. As the paper says, this is only as good as
Omega-hat: a baseline, not an estimator to use.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ...cases.case import Case
from ...models.doppler import ratio_from_radial, receive_time_paper, slant_range
from ...models.motion import evaluate_attitude
from ..attitude_fit import fit_attitude


@dataclass(frozen=True)
class ThreePingResult:
    lever_arms_sensor_m: np.ndarray  # (4, 3) in the sensor frame
    pings: tuple
    ranks: np.ndarray  # (4,) numerical rank of each transducer's system
    condition_numbers: np.ndarray  # (4,) of the determinable part
    timing: str
    tangential: str
    undetermined: list  # words for what the systems cannot fix


RANK_RTOL = 1e-8


def three_ping_solve(case: Case, timing: str = "shallow", tangential: str = "consistent",
                     candidates: int = 12) -> ThreePingResult:
    """Solve each transducer's lever arm from the best-conditioned three pings."""
    fit = fit_attitude(case, fixed_modes=1, per_axis=True)
    t = case.pings.time_s
    att = evaluate_attitude(fit.params, t)
    B = case.instrument.beam_directions()
    d_T = np.einsum("nij,kj->nki", att["Lambda"], B)  # sensor-frame attitude, nominal installation
    v = case.pings.bt_radial_m_s
    ref = case.reference
    if ref is not None and ref.velocity_m_s is not None:
        v_a = np.column_stack([np.interp(t, ref.time_s, ref.velocity_m_s[:, j]) for j in range(3)])
    else:
        v_a = np.zeros((t.size, 3))
    tang = att["dLambda_dt"] if tangential == "consistent" else att["Omega"]  # Omega r: Eq. 31 as printed
    A = np.einsum("nji,nkj->nki", tang, d_T)  # rows dLambda^T d_i (or Omega^T d_i)
    if timing == "shallow":
        b = v - np.einsum("nj,nkj->nk", v_a, d_T)
    elif timing == "deep":
        c = case.instrument.sound_speed_m_s
        depth = case.environment.depth_at_pings(t.size)[:, None]
        l = slant_range(depth, case.environment.transducer_depth_m, d_T[..., 2])
        t_R = receive_time_paper(t[:, None], l, c)
        rx = evaluate_attitude(fit.params, t_R.reshape(-1))
        Lr = rx["Lambda"].reshape(t.size, 4, 3, 3)
        dLr = (rx["dLambda_dt"] if tangential == "consistent" else rx["Omega"]).reshape(t.size, 4, 3, 3)
        d_R = np.einsum("nkij,kj->nki", Lr, B)
        rho = ratio_from_radial(v, c)
        A = np.einsum("nkji,nkj->nki", dLr, d_R) + rho[..., None] * A
        b = (rho - 1) * c - np.einsum("nj,nkj->nk", v_a, d_R + rho[..., None] * d_T)
    else:
        raise ValueError(f"timing: expected 'shallow' or 'deep', got {timing!r}")
    strength = np.linalg.norm(att["omega"], axis=1)
    pool = [i for i in np.argsort(strength)[::-1][:candidates] if np.all(np.isfinite(v[i]))]
    rank_used = 2 if tangential == "consistent" else 3

    def determinable_cond(trio):
        sv = [np.linalg.svd(A[list(trio), k], compute_uv=False) for k in range(4)]
        return max(s[0] / max(s[rank_used - 1], 1e-300) for s in sv)

    trios = list(itertools.combinations(pool, 3))
    if not trios:
        raise ValueError("/pings/bt_radial_m_s: fewer than three pings with all four beams; cannot solve")
    idx = list(min(trios, key=determinable_cond))
    r, ranks, conds = [], [], []
    for k in range(4):  # Eqs. 57-58 / 75-76, minimum norm where singular
        sol, _, rank, sv = np.linalg.lstsq(A[idx, k], b[idx, k], rcond=RANK_RTOL)
        r.append(sol)
        ranks.append(rank)
        conds.append(sv[0] / sv[rank - 1])
    undetermined = [f"transducer {k + 1}: its component along its own beam (system rank {ranks[k]})"
                    for k in range(4) if ranks[k] < 3]
    return ThreePingResult(np.array(r), tuple(int(i) for i in idx), np.array(ranks), np.array(conds), timing,
                           tangential, undetermined)
