"""Standard errors and identifiability from the Gauss-Newton reduced information matrix.

With J the Jacobian of the noise-weighted residuals and A that of the equality
constraints (both in scaled variables z), the information in the feasible tangent
space is F = Z^T J^T J Z with Z spanning null(A). Directions where F is
(numerically) singular, judged on F with unit diagonal so that one near-exact channel
does not set the threshold, or where the standard error exceeds ``UNDETERMINED_SE``
times the variable's scale, are reported as unobservable, in words and as vectors;
quantities that depend on them get an infinite standard error instead of a number.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import null_space, orth
from scipy.sparse.linalg import splu

RANK_RTOL = 1e-10
UNDETERMINED_SE = 1e2  # in units of the variable scales
WEAK_SE = 0.1  # a direction known no better than a tenth of its scale is "weakly determined"
NAVIGATION_SHARE = 0.9  # a direction this much (squared, unit vector) on the boat's own velocity unknowns
LEAK_RTOL = 0.01  # a quantity depends on an undetermined direction when its gradient leaks >1% into it
AXIS_WORDS = {"vessel": {0: "x_b (bow / roll axis)", 1: "y_b (starboard / pitch axis)", 2: "z_b (down / yaw axis)"},
              "transducer": {0: "the head's x_t (towards transducer 2)", 1: "the head's y_t (towards transducer 3)",
                             2: "the head's z_t (out of the face)"}}


@dataclass
class Uncertainty:
    cov_z: np.ndarray
    se_z: np.ndarray
    eigenvalues: np.ndarray
    null_directions_z: np.ndarray  # (k, n) unit directions the data do not fix
    unobservable: list = field(default_factory=list)
    warnings: list = field(default_factory=list)

    columns: Callable | None = None  # (index) -> covariance of every unknown with ``index``, when cov_z is not formed

    def cov_columns(self, index) -> np.ndarray:
        """Covariance (n, len(index)) of every unknown with the unknowns ``index``."""
        return self.columns(np.atleast_1d(index)) if self.columns is not None else self.cov_z[:, index]

    def determined_mask(self, Jd: np.ndarray) -> np.ndarray:
        """For each derived quantity (row of its Jacobian in z): does the data fix it?"""
        Jd = np.atleast_2d(Jd)
        if self.null_directions_z.size == 0:
            return np.ones(Jd.shape[0], dtype=bool)
        leak = np.abs(Jd @ self.null_directions_z.T).max(axis=1)
        return leak <= LEAK_RTOL * (np.linalg.norm(Jd, axis=1) + 1e-300)


def _describe(vec_x: np.ndarray, names: list, context: dict) -> str:
    """Words for one unobservable direction (given in unscaled variables, unit norm), its largest
    coefficients in brackets."""
    v = vec_x / np.linalg.norm(vec_x)
    big = np.argsort(np.abs(v))[::-1]
    text = " ".join(f"{v[i]:+.2f} {names[i]}" for i in big[:4] if abs(v[i]) > 0.05)
    return f"{_words(v, names, context, big)} ({text})"


def _words(v: np.ndarray, names: list, context: dict, big: np.ndarray) -> str:
    """A direction (unit vector ``v``, ``big`` its indices by size) in the field's words."""
    idx = {n: i for i, n in enumerate(names)}
    lever = np.array([idx[n] for n in names if n.startswith("r") and n[1:2].isdigit()])
    weight_lever = np.sum(v[lever] ** 2) if lever.size else 0.0
    if lever.size == 12 and weight_lever > 0.95:
        r = v[lever].reshape(4, 3)
        beams = context.get("beam_dirs_sensor")
        if beams is not None:
            along = np.sum(r * beams, axis=1)  # each transducer's move along its own beam
            if np.sum((r - along[:, None] * beams) ** 2) < 0.05 * weight_lever:
                who = [str(k + 1) for k in np.flatnonzero(np.abs(along) > 0.2 * np.abs(along).max())]
                if len(who) == 4 and np.all(np.sign(along) == np.sign(along[0])):
                    return "all four transducers sliding along their own beams together ('breathing')"
                return f"transducer(s) {', '.join(who)} sliding along their own beams"
        mean = r.mean(axis=0)
        if np.linalg.norm(mean) * 2 > 0.95 and np.allclose(r, mean, atol=0.1):
            axis = int(np.argmax(np.abs(mean)))
            return f"the whole head shifted along {AXIS_WORDS[context.get('frame', 'vessel')][axis]}"
    p_idx = [idx[n] for n in ("P_x", "P_y", "P_z") if n in idx]
    if p_idx and np.sum(v[p_idx] ** 2) > 0.95:
        axis = int(np.argmax(np.abs(v[p_idx])))
        return f"the head centre P along {AXIS_WORDS[context.get('frame', 'vessel')][axis]}"
    if any(n.startswith("installation") for n in (names[i] for i in big[:1])):
        return f"installation angle {names[big[0]].split('_')[1]}"
    if all(names[i].startswith(("roll", "pitch", "yaw")) for i in big[:2]):
        return "attitude-model parameters"
    return _in_words(v, names, big)


def _in_words(v: np.ndarray, names: list, big: np.ndarray) -> str:
    """A direction by its largest unknowns: two that trade off or move together, else a mix."""
    word = lambda i: names[i].replace("_", " ")
    a, b = big[0], big[1] if big.size > 1 else big[0]
    if big.size == 1 or v[a] ** 2 > 0.9:
        return f"{word(a)} alone"
    if v[a] ** 2 + v[b] ** 2 > 0.8:
        if np.sign(v[a]) != np.sign(v[b]):
            return f"{word(a)} against {word(b)} (one up and the other down fits as well)"
        return f"{word(a)} and {word(b)} together"
    return "a mix of " + ", ".join(word(i) for i in big[:3] if abs(v[i]) > 0.05)


def uncertainty(J: np.ndarray, A: np.ndarray | None, names: list, scale: np.ndarray, context: dict | None = None,
                information: np.ndarray | None = None) -> Uncertainty:
    """Covariance of the scaled variables and the unobservable directions.

    Parameters
    ----------
    J : (m, n) Jacobian of the noise-weighted residuals w.r.t. the scaled variables z (dense or scipy sparse).
    A : (q, n) Jacobian of the equality constraints, or None.
    names : variable names; scale : (n,) variable scales (x = scale * z).
    information : (n, n), optional
        J^T J given instead of J (a Schur complement: :func:`uncertainty_eliminating`).
    """
    n = information.shape[0] if information is not None else J.shape[1]
    Z = null_space(A) if A is not None and A.size else np.eye(n)
    # sparse for an assembled Jacobian: a survey's is block-sparse, never densified (m x n)
    G = information if information is not None else J.T @ J
    F = Z.T @ (G.toarray() if sp.issparse(G) else G) @ Z
    # Numerical rank on the Jacobi-equilibrated F (unit diagonal): one near-exact channel (a
    # noise-free heading, information ~1e14) must not push ordinary directions below a
    # threshold relative to the largest eigenvalue.
    d = np.sqrt(np.diag(F))
    D = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 1.0)
    lam_eq, V_eq = np.linalg.eigh(D[:, None] * F * D[None, :])
    singular = lam_eq <= RANK_RTOL * max(lam_eq.max(initial=0.0), 1e-300)
    # In the rest, eigen-directions in z (unit length) and the absolute test: SE beyond
    # UNDETERMINED_SE scales is no estimate.
    null_singular = orth(D[:, None] * V_eq[:, singular]) if singular.any() else np.zeros((F.shape[0], 0))
    if null_singular.shape[1] > 1:  # within the null space, F's own directions (named one by one below)
        null_singular = null_singular @ np.linalg.eigh(null_singular.T @ F @ null_singular)[1]
    Q = null_space(null_singular.T) if singular.any() else np.eye(F.shape[0])  # the rest: F's range
    lam, W = np.linalg.eigh(Q.T @ F @ Q)
    V = Q @ W
    bad = lam <= 1.0 / UNDETERMINED_SE**2
    good = ~bad
    cov_z = (Z @ V[:, good]) @ np.diag(1.0 / lam[good]) @ (Z @ V[:, good]).T
    null_z = np.vstack([(Z @ null_singular).T, (Z @ V[:, bad]).T])
    se = np.sqrt(np.maximum(np.diag(cov_z), 0.0))
    if null_z.size:
        leak = np.abs(null_z).max(axis=0) > LEAK_RTOL
        se[leak] = np.inf
    unobs, warns = [], []
    context = context or {}
    attitude = np.array([n.startswith(("mode", "roll", "pitch", "yaw")) for n in names])
    weak = good & (lam < 1.0 / WEAK_SE**2)
    # a weak direction of the attitude coefficients alone is reported by their SEs, not named here
    weak &= np.array([np.sum(((Z @ V[:, j]) * scale)[~attitude] ** 2) / np.sum(((Z @ V[:, j]) * scale) ** 2) > 0.5
                      if weak[j] else False for j in range(len(lam))])
    for kind, dirs, se_dir in (("unobservable", null_z, np.full(len(null_z), np.inf)),
                               ("weak", (Z @ V[:, weak]).T, 1.0 / np.sqrt(lam[weak]))):
        for d, s_d in zip(dirs, se_dir):
            vec_x = d * scale
            unit = vec_x / np.linalg.norm(vec_x)
            unobs.append({"kind": kind, "description": _describe(vec_x, names, context),
                          "words": _words(unit, names, context, np.argsort(np.abs(unit))[::-1]),
                          "se_along": float(s_d * np.linalg.norm(vec_x)) if np.isfinite(s_d) else None,
                          "vector": {names[i]: float(unit[i]) for i in np.flatnonzero(np.abs(unit) > 1e-3)}})
    navigation = context.get("navigation")
    if navigation is not None and len(navigation) != len(names):
        raise ValueError(f"context['navigation']: expected a mask of {len(names)} unknowns, got {len(navigation)}")
    boat_names = set() if navigation is None else {names[i] for i in np.flatnonzero(navigation)}
    for kind, label in (("unobservable", "not determined by the data"), ("weak", "only weakly determined")):
        found = [u for u in unobs if u["kind"] == kind]
        boat = [u for u in found if sum(w * w for n, w in u["vector"].items() if n in boat_names) >= NAVIGATION_SHARE]
        said = [u["words"] for u in found if not any(u is b for b in boat)]
        items = ([_navigation_words(boat)] if boat else []) + [
            w + (f" ({said.count(w)} directions)" if said.count(w) > 1 else "") for w in dict.fromkeys(said)]
        if found:
            warns.append(f"{len(found)} direction(s) of the unknowns {label} (their coefficients in the "
                         "result's `unobservable` list): " + "; ".join(items[:6]) + ("; ..." if len(items) > 6 else ""))
    return Uncertainty(cov_z, se, lam, null_z, unobs, warns)


def _navigation_words(directions: list) -> str:
    """Directions in the boat's own velocity (its knots or pings) summarised in one phrase: which
    runs and components, not a coefficient vector each (they are in the result's JSON)."""
    runs, axes = set(), set()
    for u in directions:
        for n, w in u["vector"].items():
            if w * w >= 0.05:
                run, _, var = n.rpartition("/")
                runs.add(run or "the run")
                axes.add({"x": "north", "y": "east", "z": "vertical"}.get(var[-1], var[-1]))
    order = [a for a in ("north", "east", "vertical") if a in axes]
    return (f"{len(directions)} in the boat's own velocity between its samples ({', '.join(sorted(runs))}; "
            f"{', '.join(order)} component{'s' if len(order) > 1 else ''}), the base the calibration fits "
            "under the platform's unknowns")


def uncertainty_eliminating(J, A: np.ndarray | None, names: list, scale: np.ndarray, local: np.ndarray,
                            context: dict | None = None) -> Uncertainty:
    """:func:`uncertainty` with the ``local`` unknowns (a velocity per ping: thousands, each touching
    a few rows, no constraint) eliminated first: the rest's information is the Schur complement
    F = G_SS - G_SV G_VV^-1 G_VS (G = J^T J, G_VV sparse and banded), so nothing of size
    (unknowns x unknowns) is formed. The local unknowns' variances are diag(G_VV^-1) + diag(X C X^T)
    (X = G_VV^-1 G_VS, C the rest's covariance), their covariance with the rest -X C
    (:meth:`Uncertainty.cov_columns`); the rest's undetermined directions carry -X d into them."""
    from .normal_equations import inverse_diagonal, ridged

    J = sp.csr_matrix(J) if not sp.issparse(J) else J.tocsr()
    local = np.asarray(local, dtype=bool)
    V, S = np.flatnonzero(local), np.flatnonzero(~local)
    if A is not None and A.size and np.any(np.asarray(A)[:, V] != 0):
        raise ValueError("local: the eliminated unknowns must not enter the constraints")
    G = (J.T @ J).tocsr()
    G_V = G[V]  # the velocities' rows, sliced once
    G_VV = ridged(G_V[:, V])
    lu = splu(G_VV)
    G_VS = G_V[:, S].toarray()
    X = lu.solve(G_VS)
    F = G[S][:, S].toarray() - G_VS.T @ X
    kept = dict(context or {})
    if kept.get("navigation") is not None:  # per-unknown masks follow the unknowns kept
        kept["navigation"] = np.asarray(kept["navigation"], dtype=bool)[S]
    red = uncertainty(None, None if A is None or not np.size(A) else np.asarray(A)[:, S], [names[i] for i in S],
                      np.asarray(scale)[S], kept, information=0.5 * (F + F.T))
    n = len(names)
    se = np.empty(n)
    se[S] = red.se_z
    var_V = inverse_diagonal(G_VV, lu) + np.einsum("ij,jk,ik->i", X, red.cov_z, X)
    se[V] = np.sqrt(np.maximum(var_V, 0.0))
    null = np.zeros((red.null_directions_z.shape[0], n))
    if null.shape[0]:
        null[:, S] = red.null_directions_z
        null[:, V] = -red.null_directions_z @ X.T
        null /= np.linalg.norm(null, axis=1, keepdims=True)
        se[V[np.abs(null[:, V]).max(axis=0) > LEAK_RTOL]] = np.inf
    at = np.full(n, -1)
    at[S] = np.arange(S.size)

    def columns(index):
        pos = at[index]
        if np.any(pos < 0):
            raise ValueError("cov_columns: only the unknowns kept (not eliminated) have covariance columns here")
        out = np.empty((n, pos.size))
        out[S] = red.cov_z[:, pos]
        out[V] = -X @ red.cov_z[:, pos]
        return out

    return Uncertainty(None, se, red.eigenvalues, null, red.unobservable, red.warnings, columns=columns)
