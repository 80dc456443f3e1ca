"""scipy's ``least_squares`` on an NLP's residual Function, called like a CasADi ``nlpsol``.

The NLP is min 0.5 |e(x, p)|^2 subject to lbx <= x <= ubx and lbg <= g(x, p) <= ubg.
``least_squares`` takes box bounds (``trf``) or none (``lm``), so the general constraints
are handled one of two ways, and what is then solved is exactly this:

* ``eliminate``: g affine in x and every row an equality. A pivoted QR of the constraint
  Jacobian picks r = rank unknowns x_D to express through the others, x_D = M x_F + m; the
  residuals are minimised over x_F, which keep their bounds; the bounds of x_D are not
  enforced (a violation shows in the caller's bound check).
* ``penalty``: the rows sqrt(penalty_weight) (g - clip(g, lbg, ubg)) are appended to the
  residuals (an exterior quadratic penalty, any g): the constraints then hold only to about
  |grad f| / penalty_weight, and ``f`` is reported without the penalty.

Unknowns with lbx == ubx are held at that value. ``lm`` drops every bound.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.optimize import least_squares

# Jacobian entries (80 MB) up to which it is dense and TRF solves its subproblem exactly; above, sparse with
# LSMR, inexact (on a 4-transect survey it stopped at 1e-5 relative above the optimum)
DENSE_MAX_ENTRIES = 10_000_000


class LeastSquaresSolver:
    """``solver(x0=, lbx=, ubx=, lbg=, ubg=, p=)`` -> ``{"x", "f", "g", "lam_g", "lam_x"}`` and
    ``solver.stats()`` (``success``, ``return_status``, ``iter_count``), as CasADi's nlpsol.

    Parameters
    ----------
    nlp : dict
        The CasADi NLP ``{"x", "p", "f", "g"}`` (its ``g`` is used; ``f`` must be 0.5 |e|^2).
    residual_fun : casadi.Function
        (x, p) -> e as its first output.
    jacobian : casadi.Function or callable
        (x, p) -> de/dx: a CasADi Function, or a callable returning a scipy sparse matrix
        (:class:`~adcpdyn.estimators.row_jacobian.RowJacobian`).
    method : str
        ``trf`` or ``lm``.
    constraints : str
        ``eliminate`` or ``penalty`` (see the module docstring).
    penalty_weight, tol, max_iter : float, float, int
        ``tol`` is least_squares' ftol, xtol and gtol; ``max_iter`` its max_nfev.
    """

    def __init__(self, nlp: dict, residual_fun: ca.Function, jacobian, method: str = "trf",
                 constraints: str = "eliminate", penalty_weight: float = 1e10, tol: float = 1e-7, max_iter: int = 500):
        x, p = nlp["x"], nlp.get("p", ca.MX.sym("p", 0))
        g = nlp["g"]
        jac_g = ca.jacobian(g, x)
        self._g = ca.Function("constraints", [x, p], [g, jac_g])
        self.affine = not ca.depends_on(jac_g, x)
        if constraints == "eliminate" and g.numel() and not self.affine:
            raise ValueError("SolverOptions.constraints: 'eliminate' needs constraints affine in x; these are not "
                             "(use 'penalty')")
        self._e, self._jac = residual_fun, jacobian
        self.method, self.constraints = method, constraints
        self.penalty_weight, self.tol, self.max_iter = float(penalty_weight), float(tol), int(max_iter)
        self._stats: dict = {}

    def stats(self) -> dict:
        return dict(self._stats)

    def _residuals(self, x, p) -> np.ndarray:
        return np.asarray(self._e.call([x, p])[0]).ravel()

    def _jacobian(self, x, p, dense: bool):
        J = self._jac.call([x, p])[0] if isinstance(self._jac, ca.Function) else self._jac(x, p)
        if isinstance(J, ca.DM):
            return J.full() if dense else sp.csr_matrix(J.sparse())
        return J.toarray() if dense else sp.csr_matrix(J)

    def _reduction(self, x0, lbx, ubx, lbg, ubg, p):
        """The unknowns searched, y = x[free], and x(y): x[free] = y, x[eliminated] = t + M y, the
        others held at t: (free, eliminated, M, t). The affine constraints are read off at x0
        (any point gives the same)."""
        fixed = lbx == ubx
        t = np.where(fixed, lbx, 0.0)
        eliminated, M = np.zeros(0, dtype=int), None
        loose = np.flatnonzero(~fixed)
        free = loose
        if self.constraints == "eliminate" and lbg.size:
            if np.any(lbg != ubg):
                raise ValueError("SolverOptions.constraints: 'eliminate' needs equality constraints; rows "
                                 f"{np.flatnonzero(lbg != ubg).tolist()} have lbg < ubg (use 'penalty')")
            g0, A = self._g.call([x0, p])
            g0, A = np.asarray(g0).ravel(), np.asarray(ca.DM(A).full())
            rhs = lbg - (g0 - A @ x0) - A[:, fixed] @ t[fixed]
            _, R, piv = sla.qr(A[:, loose], mode="economic", pivoting=True)
            diag = np.abs(np.diag(R))
            rank = int(np.sum(diag > max(A.shape) * np.finfo(float).eps * (diag[0] if diag.size else 0.0)))
            eliminated = np.sort(loose[piv[:rank]])
            free = np.setdiff1d(loose, eliminated)
            pinv = np.linalg.pinv(A[:, eliminated])
            M = -pinv @ A[:, free]
            M[np.abs(M) < 1e-14 * max(1.0, np.max(np.abs(M), initial=0.0))] = 0.0
            t[eliminated] = pinv @ rhs
        return free, eliminated, M, t

    def __call__(self, x0, lbx, ubx, lbg, ubg, p, **_warm):
        x0, lbx, ubx = (np.asarray(v, dtype=float).ravel() for v in (x0, lbx, ubx))
        lbg, ubg = np.asarray(lbg, dtype=float).ravel(), np.asarray(ubg, dtype=float).ravel()
        p = np.asarray(p, dtype=float).ravel()
        free, elim, M, t = self._reduction(x0, lbx, ubx, lbg, ubg, p)
        n_rows = self._e.size1_out(0) + lbg.size
        dense = self.method == "lm" or n_rows * free.size <= DENSE_MAX_ENTRIES
        M_sparse = sp.csr_matrix(M) if M is not None else None
        penalty = self.constraints == "penalty" and lbg.size > 0
        root = np.sqrt(self.penalty_weight)

        def x_of(y):
            x = t.copy()
            x[free] = y
            if elim.size:
                x[elim] += M @ y
            return x

        def reduce(J):
            """dx/dy applied on the right: J[:, free] + J[:, eliminated] M."""
            if dense:
                return J[:, free] + J[:, elim] @ M if elim.size else J[:, free]
            J = J.tocsc()
            return (J[:, free] + J[:, elim] @ M_sparse if elim.size else J[:, free]).tocsr()

        def fun(y):
            x = x_of(y)
            e = self._residuals(x, p)
            if not penalty:
                return e
            g = np.asarray(self._g.call([x, p])[0]).ravel()
            return np.concatenate([e, root * (g - np.clip(g, lbg, ubg))])

        def jac(y):
            x = x_of(y)
            J = reduce(self._jacobian(x, p, dense))
            if not penalty:
                return J
            g, A = self._g.call([x, p])
            g = np.asarray(g).ravel()
            A = np.asarray(ca.DM(A).full()) * (root * ((g < lbg) | (g > ubg)))[:, None]  # active rows only
            return np.vstack([J, A[:, free]]) if dense else sp.vstack([J, sp.csr_matrix(A[:, free])]).tocsr()

        y0 = x0[free]
        kw = dict(method=self.method, ftol=self.tol, xtol=self.tol, gtol=self.tol, max_nfev=self.max_iter)
        if self.method == "trf":
            lo, hi = lbx[free], ubx[free]
            kw.update(bounds=(lo, hi), tr_solver="exact" if dense else "lsmr")
            y0 = np.clip(y0, lo, hi)
        try:
            res = least_squares(fun, y0, jac=jac, **kw)
            y, status, success, njev = res.x, res.message, bool(res.success), int(res.njev or 0)
        except ValueError as err:  # e.g. residuals not finite at the start
            y, status, success, njev = y0, f"scipy least_squares: {err}", False, 0
        x = x_of(y)
        e = self._residuals(x, p)
        g = np.asarray(self._g.call([x, p])[0]).ravel()
        self._stats = {"success": success, "return_status": status, "iter_count": njev,
                       "unknowns_searched": int(free.size)}
        nan_g, nan_x = np.full(lbg.size, np.nan), np.full(x.size, np.nan)  # no multipliers from least_squares
        return {"x": x, "f": 0.5 * float(e @ e), "g": g, "lam_g": nan_g, "lam_x": nan_x}
