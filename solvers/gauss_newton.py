"""IPOPT's least-squares oracle from an assembled residual Jacobian, as callbacks.

For f = 0.5 |e(x, p)|^2 the Gauss-Newton Hessian is sigma J^T J (constraint curvature
left out). When J is a CasADi Function, :func:`~adcpdyn.solvers.multistart.build_solver`
forms it as a CasADi graph; an assembled Jacobian
(:class:`~adcpdyn.estimators.row_jacobian.RowJacobian`: scipy, per-row blocks chained
numerically) needs callbacks: :class:`GaussNewtonHessian` forms triu(J^T J) with
numpy/scipy products, and :class:`AssembledLeastSquares` gives IPOPT f and its gradient
J^T e from the same Jacobian, so IPOPT never differentiates the residual graph: building
the solver no longer derives a reverse sweep through 10^5 pings (4 s), and each iteration
evaluates the per-row Jacobians once for the gradient and the Hessian together.
"""

from __future__ import annotations

import threading

import casadi as ca
import numpy as np
import scipy.sparse as sp

DENSE_GRAM_MAX_UNKNOWNS = 3000  # up to here J^T J is formed dense from the Jacobian's blocks ...
DENSE_GRAM_MAX_KNOT_COLUMNS = 600  # ... when no run has more velocity columns than this


def dense_gram(jacobian) -> bool:
    """Whether J^T J is formed dense from an assembled Jacobian's blocks: few unknowns, and each
    block's velocity columns few (knots), since every block adds its velocity columns' square to
    the dense matrix. A velocity per ping (a random walk) gives one run thousands of them: dense,
    an 830-ping transect took 90 s, sparse 5.5 s; twenty transects on knots (1897 unknowns, 2 %
    filled, ~90 velocity columns each) take 42.5 s dense, 49.2 s sparse."""
    if not hasattr(jacobian, "gram_and_gradient") or jacobian.n_z > DENSE_GRAM_MAX_UNKNOWNS:
        return False
    return getattr(jacobian, "max_knot_columns", 0) <= DENSE_GRAM_MAX_KNOT_COLUMNS


class AssembledLeastSquares:
    """f = 0.5 |e|^2, its gradient J^T e and J^T J at one point, each computed once there.

    ``residual_fun``: (x, p) -> e (first output); ``jacobian``: the assembled Jacobian
    (``jacobian(x, p)`` a scipy sparse de/dx; with ``gram_and_gradient(x, p, e)`` J^T J and
    J^T e come from one pass over its blocks). IPOPT evaluates f at a trial point, then, once
    it is accepted, the gradient and the Hessian there: the residuals of the last point and
    the Gram matrix of the last gradient are kept, per thread (multistart solves in threads).
    """

    def __init__(self, residual_fun: ca.Function, jacobian):
        self._residual_fun = residual_fun
        self._jac = jacobian
        self._dense = dense_gram(jacobian)
        self._local = threading.local()

    @staticmethod
    def _same(entry, x: np.ndarray, p: np.ndarray) -> bool:
        return entry is not None and np.array_equal(entry[0], x) and np.array_equal(entry[1], p)

    def residuals(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """e at (x, p), evaluated into this thread's buffers (no copies through DM: 1e6 weights are
        45 ms each way)."""
        local = self._local
        entry = getattr(local, "residuals", None)
        if not self._same(entry, x, p):
            if entry is None or entry[1].size != p.size:
                e = np.empty(self._residual_fun.nnz_out(0))
                buf, run = self._residual_fun.buffer()
                entry = local.residuals = (np.empty(x.size), np.empty(p.size), e)
                buf.set_arg(0, memoryview(entry[0]))
                buf.set_arg(1, memoryview(entry[1]))
                buf.set_res(0, memoryview(e))
                local.run = (buf, run)  # the buffer holds pointers into entry's arrays: both live as long
            entry[0][...], entry[1][...] = x, p
            local.run[1]()
        return entry[2]

    def gradient(self, x: np.ndarray, p: np.ndarray) -> tuple[float, np.ndarray]:
        """(f, J^T e); J^T J kept for :meth:`gram` at the same point when it comes from the same pass."""
        e = self.residuals(x, p)
        if self._dense:
            G, grad = self._jac.gram_and_gradient(x, p, e)
            self._local.gram = (x.copy(), p.copy(), G)
        else:
            grad = np.asarray(self._jac(x, p).T @ e).ravel()
        return 0.5 * float(e @ e), grad

    def gram(self, x: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """J^T J at (x, p) if the last gradient was taken there, else None."""
        entry = getattr(self._local, "gram", None)
        return entry[2] if self._same(entry, x, p) else None

    def functions(self, objective: ca.Function) -> tuple:
        """The callbacks ``objective: (x, p) -> f`` and ``nlp_grad_f: (x, p) -> (f, grad_f_x)``;
        ``objective`` is f's graph (x, p) -> 0.5 |e|^2, differentiated only for df/dp if asked."""
        n_x, n_p = objective.size1_in(0), objective.size1_in(1)
        return _Objective(self, n_x, n_p, objective), _Gradient(self, n_x, n_p)


def _arrays(buffers, sizes=None) -> list:
    """numpy views of a buffer callback's memoryviews; an input CasADi passes as null (``sizes``
    given) is zeros, an output it does not ask for is None."""
    if sizes is None:
        return [None if b is None else np.frombuffer(b, dtype=np.float64) for b in buffers]
    return [np.zeros(n) if b is None else np.frombuffer(b, dtype=np.float64) for b, n in zip(buffers, sizes)]


class _BufferCallback(ca.Callback):
    """A callback on dense column inputs (and outputs, unless a subclass says otherwise) of the given
    sizes, evaluated straight on the solver's buffers: the weights (one per residual) pass without a
    copy. Subclasses set their own fields before calling this constructor (it constructs)."""

    def __init__(self, name: str, inputs: dict, outputs: dict):
        ca.Callback.__init__(self)
        self._inputs, self._outputs = list(inputs.items()), list(outputs.items())
        self.construct(name, {})

    def get_n_in(self):
        return len(self._inputs)

    def get_n_out(self):
        return len(self._outputs)

    def get_name_in(self, i):
        return self._inputs[i][0]

    def get_name_out(self, i):
        return self._outputs[i][0]

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self._inputs[i][1], 1)

    def get_sparsity_out(self, i):
        return ca.Sparsity.dense(self._outputs[i][1], 1)

    def has_eval_buffer(self):
        return True

    def _args(self, arg) -> list:
        return _arrays(arg, [n for _, n in self._inputs])


class _Objective(_BufferCallback):
    """f = 0.5 |e|^2, with its reverse derivative (:class:`_ObjectiveReverse`): CasADi builds the
    Lagrangian's gradient Function when IPOPT is created, though with ``grad_f`` given and
    ``calc_lam_p`` off it never calls it."""

    def __init__(self, oracle: AssembledLeastSquares, n_x: int, n_p: int, objective: ca.Function):
        self._oracle, self._objective = oracle, objective  # the graph: only its derivative in p is taken from it
        self._reverse = None  # the reverse callback, kept alive here as long as CasADi may call it
        super().__init__("least_squares_objective", {"x": n_x, "p": n_p}, {"f": 1})

    def eval_buffer(self, arg, res):
        (out,) = _arrays(res)
        if out is not None:
            e = self._oracle.residuals(*self._args(arg))
            out[0] = 0.5 * float(e @ e)
        return 0

    def has_reverse(self, nadj):
        return nadj == 1

    def get_reverse(self, nadj, name, inames, onames, opts):
        self._reverse = _ObjectiveReverse(self._oracle, self._objective, name, inames, onames)
        return self._reverse


class _ObjectiveReverse(_BufferCallback):
    """``(x, p, f, adj_f) -> (adj_f J^T e, adj_f df/dp)``: the x part from the assembled Jacobian, the
    p part from the objective's graph, whose reverse sweep is derived on the first call that needs it."""

    def __init__(self, oracle: AssembledLeastSquares, objective: ca.Function, name: str, inames, onames):
        self._oracle, self._objective, self._by_p = oracle, objective, None
        n_x, n_p = objective.size1_in(0), objective.size1_in(1)
        super().__init__(name, dict(zip(inames, (n_x, n_p, 1, 1))), dict(zip(onames, (n_x, n_p))))

    def eval_buffer(self, arg, res):
        x, p, f, adj = self._args(arg)
        by_x, by_p = _arrays(res)
        if by_x is not None:
            by_x[...] = adj[0] * self._oracle.gradient(x, p)[1]
        if by_p is not None:
            if self._by_p is None:
                self._by_p = self._objective.reverse(1)
            by_p[...] = np.asarray(self._by_p(x, p, f, adj)[1]).ravel()
        return 0


class _Gradient(_BufferCallback):
    def __init__(self, oracle: AssembledLeastSquares, n_x: int, n_p: int):
        self._oracle = oracle
        super().__init__("nlp_grad_f", {"x": n_x, "p": n_p}, {"f": 1, "grad_f_x": n_x})

    def eval_buffer(self, arg, res):
        f_out, grad_out = _arrays(res)
        x, p = self._args(arg)
        if grad_out is not None:
            f, grad_out[...] = self._oracle.gradient(x, p)
        elif f_out is not None:
            e = self._oracle.residuals(x, p)
            f = 0.5 * float(e @ e)
        if f_out is not None:
            f_out[0] = f
        return 0


class GaussNewtonHessian(_BufferCallback):
    """``nlp_hess_l(x, p, lam_f, lam_g) -> sigma * triu(J^T J)`` (or the whole J^T J, ``upper=False``,
    for solvers that take a symmetric Hessian) from an assembled Jacobian."""

    def __init__(self, jacobian, n_g: int, name: str = "nlp_hess_l", upper: bool = True,
                 oracle: AssembledLeastSquares | None = None):
        """``jacobian``: a callable (x, p) -> scipy sparse J with attributes ``sparsity`` (its
        structural pattern, scipy) and ``n_z``, ``n_p``; if it has ``gram(x, p)`` (dense J^T J)
        that is used instead of forming J, and ``gram_sparsity()`` J^T J's pattern. ``oracle``:
        where the gradient at the same point already formed J^T J."""
        self._jac = jacobian
        self._oracle = oracle
        self._n_x = jacobian.n_z
        self._dense = dense_gram(jacobian)
        if hasattr(jacobian, "gram_sparsity"):  # the Jacobian knows J^T J's pattern from its blocks
            PtP = jacobian.gram_sparsity().astype(float)
        else:
            P = jacobian.sparsity.astype(float)
            PtP = P.T @ P
        H = (sp.triu(PtP) if upper else sp.csr_matrix(PtP)).tocoo()
        self._hess_sp = ca.Sparsity.triplet(self._n_x, self._n_x, H.row.tolist(), H.col.tolist())
        rows, cols = self._hess_sp.get_triplet()
        self._rows, self._cols = np.asarray(rows), np.asarray(cols)
        super().__init__(name, {"x": self._n_x, "p": jacobian.n_p, "lam_f": 1, "lam_g": n_g},
                         {"triu_hess_gamma_x_x" if upper else "hess_gamma_x_x": None})

    def get_sparsity_out(self, i):
        return self._hess_sp

    def eval_buffer(self, arg, res):
        x, p, lam_f, _ = self._args(arg)
        (out,) = _arrays(res)
        if out is not None:
            out[...] = self._values(x, p) * lam_f[0]
        return 0

    def _values(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """J^T J's nonzeros in the output's pattern (column-major)."""
        G = self._oracle.gram(x, p) if self._oracle is not None else None
        if G is None and hasattr(self._jac, "gram") and self._dense:  # J^T J without forming J
            G = self._jac.gram(x, p)
        if G is not None:
            return G[self._rows, self._cols]
        J = self._jac(x, p)
        if J.nnz > 0.05 * J.shape[0] * J.shape[1]:  # dense enough for BLAS to beat the sparse product
            Jd = J.toarray()
            return (Jd.T @ Jd)[self._rows, self._cols]
        return np.asarray(sp.csr_matrix(J.T @ J)[self._rows, self._cols]).ravel()
