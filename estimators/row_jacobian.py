"""Residual Jacobian of a least-squares problem assembled from per-row Jacobians.

Expanding a whole calibration into one SX graph and differentiating it costs graph
nodes in proportion to rows x colours: about a minute for 600 deep-water pings and
gigabytes beyond a few thousand pings. Every residual row, though, depends on the
unknowns only through a short shared vector s(z) (attitude parameters, lever arms,
angles, ...) and at most one velocity interpolated from knots. So each block's per-row
Function is differentiated once (SX, a few thousand nodes), mapped over its rows, and
the chain rule through s(z) and the interpolation is applied numerically: the same
matrix as ``casadi.jacobian`` of the stacked residuals, in O(rows) time and memory.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp


@dataclass
class RowBlock:
    """Residual rows ``offset + i * n + j`` (output i of row j) of one mapped per-row model.

    ``fun(d, v, s) -> y (k,)``: d the row's data (n_d,), v its velocity (3,) and s the
    shared vector; only derivatives matter, so measured values and constants may be
    left out of y. ``data`` is (n_d, n); ``velocity_basis`` (n, K) interpolates the K
    knot velocities to the rows (None: no velocity); ``sign`` multiplies each output.
    """

    fun: ca.Function
    data: np.ndarray
    offset: int
    velocity_basis: sp.csr_matrix | None = None
    sign: np.ndarray | None = None


class RowJacobian:
    """``J(z, w) = diag(w) d residuals / dz`` as a scipy CSR matrix.

    ``shared`` is the MX expression s(z); ``knot_columns`` (K, 3) the columns of z holding
    the knot velocities and ``knot_scale`` their scale (x = scale z).
    """

    def __init__(self, z: ca.MX, shared: ca.MX, blocks: list[RowBlock], n_rows: int,
                 knot_columns: np.ndarray | None = None, knot_scale: np.ndarray | None = None):
        self.n_rows, self.n_z = n_rows, z.shape[0]
        self.n_p = n_rows  # the NLP's parameters are the residual weights, one per row
        self._shared = ca.Function("shared", [z], [shared, ca.jacobian(shared, z)])
        ds = self._shared.sparsity_out(1)
        self._shared_cols = np.unique(np.asarray(ds.get_triplet()[1], dtype=int))
        self.blocks = blocks
        self.knot_columns = knot_columns
        self.knot_scale = knot_scale
        self._jac = []
        for b in blocks:
            d, v, s = (ca.SX.sym(n, b.fun.sparsity_in(i)) for i, n in enumerate(("d", "v", "s")))
            y = b.fun(d, v, s)
            f = ca.Function("row_jacobian", [d, v, s], [ca.densify(ca.jacobian(y, v)), ca.densify(ca.jacobian(y, s))])
            self._jac.append(f.map("row_jacobians", "serial", b.data.shape[1], [2], []))  # s shared, not repeated
        self._data = [np.ascontiguousarray(b.data.T) for b in blocks]  # (n, n_d): CasADi's column-major (n_d, n)
        self._local = threading.local()  # evaluation buffers are per thread (multistart solves in threads)
        self.sparsity = self._pattern()

    def _evaluate(self, i: int, v: np.ndarray, s: np.ndarray):
        """Per-row Jacobians of block i, (n, 3, k) and (n, ns, k), through a zero-copy FunctionBuffer."""
        buffers = getattr(self._local, "buffers", None)
        if buffers is None:
            buffers = self._local.buffers = [None] * len(self._jac)
        if buffers[i] is None:
            f, b = self._jac[i], self.blocks[i]
            k, n = b.fun.size1_out(0), b.data.shape[1]
            buf, run = f.buffer()
            out = (np.empty((n, 3, k)), np.empty((n, f.size1_in(2), k)))
            buf.set_arg(0, memoryview(self._data[i]))
            buf.set_res(0, memoryview(out[0]))
            buf.set_res(1, memoryview(out[1]))
            buffers[i] = (buf, run, out)
        buf, run, out = buffers[i]
        v, s = np.ascontiguousarray(v), np.ascontiguousarray(s)
        buf.set_arg(1, memoryview(v))
        buf.set_arg(2, memoryview(s))
        run()
        return out

    def _pattern(self) -> sp.csr_matrix:
        """Structural pattern of J (rows x z): the shared columns and the row's knots."""
        rows, cols = [], []
        for b in self.blocks:
            k, n = b.fun.size1_out(0), b.data.shape[1]
            r = b.offset + np.arange(k * n)
            rows.append(np.repeat(r, self._shared_cols.size))
            cols.append(np.tile(self._shared_cols, r.size))
            if b.velocity_basis is not None and self.knot_columns is not None:
                H = b.velocity_basis.tocoo()
                for i in range(k):
                    for a in range(3):
                        rows.append(b.offset + i * n + H.row)
                        cols.append(self.knot_columns[H.col, a])
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        return sp.csr_matrix((np.ones(rows.size, dtype=bool), (rows, cols)), shape=(self.n_rows, self.n_z))

    def __call__(self, z, w) -> sp.csr_matrix:
        s, ds_dz = self._shared(z)
        s = s.full().ravel()
        ds_dz = ds_dz.full()[:, self._shared_cols]  # (ns, n_shared_cols)
        rows, cols, vals = [], [], []
        for index, b in enumerate(self.blocks):
            k, n = b.fun.size1_out(0), b.data.shape[1]
            v = np.zeros((n, 3))  # (n, 3): CasADi's column-major (3, n)
            if b.velocity_basis is not None and self.knot_columns is not None:
                knots = np.asarray(z, dtype=float).ravel()[self.knot_columns] * self.knot_scale[self.knot_columns]
                v = b.velocity_basis @ knots
            jv, js = self._evaluate(index, v, s)
            sign = np.ones(k) if b.sign is None else np.asarray(b.sign, dtype=float)
            js = js.transpose(2, 0, 1) * sign[:, None, None]  # (k, n, ns)
            dense = js @ ds_dz  # (k, n, n_shared_cols)
            r = b.offset + np.arange(k * n)
            rows.append(np.repeat(r, self._shared_cols.size))
            cols.append(np.tile(self._shared_cols, r.size))
            vals.append(dense.reshape(-1))
            if b.velocity_basis is not None and self.knot_columns is not None:
                jv = jv.transpose(2, 0, 1) * sign[:, None, None]  # (k, n, 3)
                H = b.velocity_basis.tocoo()
                for i in range(k):
                    for a in range(3):
                        rows.append(b.offset + i * n + H.row)
                        cols.append(self.knot_columns[H.col, a])
                        vals.append(jv[i, H.row, a] * H.data * self.knot_scale[self.knot_columns[H.col, a]])
        J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(self.n_rows, self.n_z))
        return sp.diags(np.asarray(w, dtype=float).ravel()) @ J
