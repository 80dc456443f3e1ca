"""Gauss-Newton Lagrangian Hessian for IPOPT from an assembled residual Jacobian, as a callback.

For f = 0.5 |e(x, p)|^2 the Gauss-Newton Hessian is sigma J^T J (constraint curvature
left out). When J is a CasADi Function, :func:`~adcpdyn.solvers.multistart.build_solver`
forms it as a CasADi graph; an assembled Jacobian
(:class:`~adcpdyn.estimators.row_jacobian.RowJacobian`: scipy, per-row blocks chained
numerically) needs this callback, which forms triu(J^T J) with numpy/scipy products.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp

DENSE_GRAM_MAX_UNKNOWNS = 3000  # up to here J^T J is formed dense from the Jacobian's blocks


class GaussNewtonHessian(ca.Callback):
    """``nlp_hess_l(x, p, lam_f, lam_g) -> sigma * triu(J^T J)`` (or the whole J^T J, ``upper=False``,
    for solvers that take a symmetric Hessian) from an assembled Jacobian."""

    def __init__(self, jacobian, n_g: int, name: str = "nlp_hess_l", upper: bool = True):
        """``jacobian``: a callable (x, p) -> scipy sparse J with attributes ``sparsity`` (its
        structural pattern, scipy) and ``n_z``, ``n_p``; if it has ``gram(x, p)`` (dense J^T J)
        that is used instead of forming J, and ``gram_sparsity()`` J^T J's pattern."""
        ca.Callback.__init__(self)
        self._jac = jacobian
        self._n_g = n_g
        self._n_x, self._n_p = jacobian.n_z, jacobian.n_p
        self._upper = upper
        if hasattr(jacobian, "gram_sparsity"):  # the Jacobian knows J^T J's pattern from its blocks
            PtP = jacobian.gram_sparsity().astype(float)
        else:
            P = jacobian.sparsity.astype(float)
            PtP = P.T @ P
        H = (sp.triu(PtP) if upper else sp.csr_matrix(PtP)).tocoo()
        self._hess_sp = ca.Sparsity.triplet(self._n_x, self._n_x, H.row.tolist(), H.col.tolist())
        rows, cols = self._hess_sp.get_triplet()
        self._rows, self._cols = np.asarray(rows), np.asarray(cols)
        self.construct(name, {})

    def get_n_in(self):
        return 4

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ("x", "p", "lam_f", "lam_g")[i]

    def get_name_out(self, i):
        return "triu_hess_gamma_x_x" if self._upper else "hess_gamma_x_x"

    def get_sparsity_in(self, i):
        return (ca.Sparsity.dense(self._n_x, 1), ca.Sparsity.dense(self._n_p, 1), ca.Sparsity.scalar(),
                ca.Sparsity.dense(self._n_g, 1))[i]

    def get_sparsity_out(self, i):
        return self._hess_sp

    def eval(self, arg):
        if hasattr(self._jac, "gram") and self._n_x <= DENSE_GRAM_MAX_UNKNOWNS:  # J^T J without forming J
            G = self._jac.gram(arg[0].full().ravel(), arg[1].full().ravel())
            return [ca.DM(self._hess_sp, G[self._rows, self._cols] * float(arg[2]))]
        J = self._jac(arg[0].full().ravel(), arg[1].full().ravel())
        if J.nnz > 0.05 * J.shape[0] * J.shape[1]:  # dense enough for BLAS to beat the sparse product
            Jd = J.toarray()
            values = (Jd.T @ Jd)[self._rows, self._cols]
        else:
            values = np.asarray(sp.csr_matrix(J.T @ J)[self._rows, self._cols]).ravel()
        return [ca.DM(self._hess_sp, values * float(arg[2]))]
