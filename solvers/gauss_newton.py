"""Gauss-Newton Lagrangian Hessian for IPOPT as a CasADi callback.

For f = 0.5 |e(x, p)|^2 the Gauss-Newton Hessian is sigma J^T J. Forming J^T J
symbolically costs far more than the solve on long runs (every entry is a sum over
all residuals), so the callback evaluates the sparse residual Jacobian J numerically
and forms triu(J^T J) with scipy's sparse product. Constraint curvature is left out.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.sparse as sp


class GaussNewtonHessian(ca.Callback):
    """``nlp_hess_l(x, p, lam_f, lam_g) -> sigma * triu(J^T J)`` from a Jacobian Function."""

    def __init__(self, jacobian: ca.Function, n_g: int, name: str = "nlp_hess_l"):
        ca.Callback.__init__(self)
        self._jac = jacobian
        self._n_x = jacobian.size1_in(0)
        self._n_p = jacobian.size1_in(1)
        self._n_g = n_g
        ones = ca.DM(jacobian.sparsity_out(0), 1.0)
        self._hess_sp = ca.triu(ca.mtimes(ones.T, ones)).sparsity()
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
        return "triu_hess_gamma_x_x"

    def get_sparsity_in(self, i):
        return (ca.Sparsity.dense(self._n_x, 1), ca.Sparsity.dense(self._n_p, 1), ca.Sparsity.scalar(),
                ca.Sparsity.dense(self._n_g, 1))[i]

    def get_sparsity_out(self, i):
        return self._hess_sp

    def eval(self, arg):
        J = self._jac(arg[0], arg[1]).sparse()
        H = sp.triu(J.T @ J, format="csr")
        values = np.asarray(H[self._rows, self._cols]).ravel() * float(arg[2])
        return [ca.DM(self._hess_sp, values)]
