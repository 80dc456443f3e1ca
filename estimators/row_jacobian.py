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

import functools
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..solvers.compiled import compiled


_POOLS: dict[int, ThreadPoolExecutor] = {}
DENSE_BASIS_ENTRIES = 500_000  # a block's velocity basis (pings x knots) up to this size is summed through dense
PIECE_ROWS = 1024  # rows per evaluation of a per-row Jacobian map (its output a few MB: stays in cache for the sums)


def _pattern_of(sparsity: ca.Sparsity) -> sp.csr_matrix:
    """A CasADi sparsity pattern as a scipy CSR matrix of ones."""
    rows, cols = sparsity.get_triplet()
    return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=sparsity.shape)


def _pool(threads: int) -> ThreadPoolExecutor:
    """One pool per thread count for the process (problems come and go, threads stay few)."""
    if threads not in _POOLS:
        _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="row-jacobian")
    return _POOLS[threads]


@dataclass
class RowBlock:
    """Residual rows ``offset + i * n + j`` (output i of row j) of one mapped per-row model.

    ``fun(d, v, s) -> y (k,)``: d the row's data (n_d,), v its velocity (3,) and s its share
    of the shared vector (``shared_index``: which entries; None: all of it); only derivatives
    matter, so measured values and constants may be left out of y. ``data`` is (n_d, n);
    ``velocity_basis`` (n, K) interpolates the K knot velocities to the rows (None: no
    velocity) and ``knot_columns`` (K, 3) are those knots' columns of z (None: the
    Jacobian's own); ``sign`` multiplies each output. With several runs in one problem each
    run's blocks take their run's attitude and knots only: the Jacobian stays block-sparse.
    """

    fun: ca.Function
    data: np.ndarray
    offset: int
    velocity_basis: sp.csr_matrix | None = None
    sign: np.ndarray | None = None
    shared_index: np.ndarray | None = None
    knot_columns: np.ndarray | None = None


class RowJacobian:
    """``J(z, w) = diag(w) d residuals / dz`` as a scipy CSR matrix, and ``gram(z, w)`` its
    J^T J formed block by block (the Gauss-Newton Hessian, without assembling J).

    ``shared`` is the MX expression s(z); ``knot_columns`` (K, 3) the columns of z holding
    the knot velocities (for blocks that do not name their own) and ``knot_scale`` the
    scale of z (x = scale z). Each block's rows are evaluated in pieces of ``PIECE_ROWS``;
    ``threads``: where the whole per-row Jacobians are asked for (J, its products, a block
    with knots), the pieces are shared out to this many threads in contiguous runs (CasADi
    releases Python's lock while it evaluates); the Gram pass of a block without knots
    evaluates and sums its pieces in the caller's thread (:meth:`_pieces`).
    With ``compile`` the per-row Jacobians run as machine code (:mod:`~adcpdyn.solvers.compiled`,
    cached per machine).
    """

    def __init__(self, z: ca.MX, shared: ca.MX, blocks: list[RowBlock], n_rows: int,
                 knot_columns: np.ndarray | None = None, knot_scale: np.ndarray | None = None, threads: int = 1,
                 compile: bool = False):
        self.n_rows, self.n_z = n_rows, z.shape[0]
        self.n_p = n_rows  # the NLP's parameters are the residual weights, one per row
        self._shared = ca.Function("shared", [z], [shared, ca.jacobian(shared, z)])
        ds = _pattern_of(self._shared.sparsity_out(1))
        self.blocks = blocks
        self.knot_scale = knot_scale
        self._index, self._cols, self._knots = [], [], []
        for b in blocks:
            index = np.arange(shared.shape[0]) if b.shared_index is None else np.asarray(b.shared_index, dtype=int)
            self._index.append(index)
            self._cols.append(np.unique(ds[index].indices) if index.size else np.zeros(0, dtype=int))
            self._knots.append(b.knot_columns if b.knot_columns is not None else knot_columns)
        self._jac, self._chunks, self._groups = [], [], []
        for b in blocks:
            d, v, s = (ca.SX.sym(n, b.fun.sparsity_in(i)) for i, n in enumerate(("d", "v", "s")))
            y = b.fun(d, v, s)
            # transposed: per row the k outputs' gradients one after another, so (n, k, ns) in numpy
            f = ca.Function("row_jacobian", [d, v, s], [ca.densify(ca.jacobian(y, v)).T, ca.densify(ca.jacobian(y, s)).T])
            n = b.data.shape[1]
            if compile:
                f = compiled(f)
            # pieces of PIECE_ROWS rows and the rest: two map sizes, cheap to build (a map's construction grows
            # faster than its size: 0.17 s for 14285 rows of the deep model), and a piece's per-row Jacobians
            # (1024 rows x 8 outputs x 28 inputs: 1.8 MB) are summed while they are still in cache
            chunks = [(lo, min(lo + PIECE_ROWS, n)) for lo in range(0, n, PIECE_ROWS)] or [(0, 0)]
            maps = {m: f.map("row_jacobians", "serial", m, [2], []) for m in {hi - lo for lo, hi in chunks}}  # s shared
            self._jac.append([maps[hi - lo] for lo, hi in chunks])
            self._chunks.append(chunks)
            # the pieces in one contiguous run per thread
            edges = np.linspace(0, len(chunks), min(threads, len(chunks)) + 1).astype(int)
            self._groups.append([range(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a])
        self._data = [np.ascontiguousarray(b.data.T) for b in blocks]  # (n, n_d): CasADi's column-major (n_d, n)
        self._pool = _pool(threads) if threads > 1 else None
        self._local = threading.local()  # evaluation buffers are per thread (multistart solves in threads)
        self._bases = {}  # block -> its velocity basis and transpose for the Gram sums (:meth:`_basis`)

    @property
    def max_knot_columns(self) -> int:
        """The most velocity (knot) columns any block's rows reach: a run's knots times three."""
        return max((k.size for i, k in enumerate(self._knots) if k is not None and self._has_knots(i)), default=0)

    @functools.cached_property
    def sparsity(self) -> sp.csr_matrix:
        """Structural pattern of J (rows x z), built on first use (J^T J's comes from :meth:`gram_sparsity`)."""
        return self._pattern()

    def _evaluate(self, i: int, v: np.ndarray, s: np.ndarray):
        """Per-row Jacobians of block i, (n, k, 3) and (n, k, ns), at the rows' velocities ``v`` (n, 3) and its
        share ``s`` of the shared vector: this thread's arrays (valid until its next call; allocating 10^5
        pings' afresh cost as much as filling them), filled piece by piece on the Jacobian's threads."""
        local = self._local.__dict__
        outputs = local.setdefault("outputs", {})
        if i not in outputs:
            b = self.blocks[i]
            k, n, ns = b.fun.size1_out(0), b.data.shape[1], self._jac[i][0].size1_in(2)
            outputs[i] = (np.empty((n, k, 3)), np.empty((n, k, ns)))
        out = outputs[i]
        v, s = np.ascontiguousarray(v, dtype=float), np.ascontiguousarray(s, dtype=float)

        def pieces(group):
            for c in group:
                lo, hi = self._chunks[i][c]
                self._piece(i, c, s, v[lo:hi], (out[0][lo:hi], out[1][lo:hi]))

        self._map(pieces, self._groups[i])
        return out

    def _map(self, fun, items) -> list:
        """``[fun(item) ...]`` on this Jacobian's threads (CasADi and numpy's products release Python's lock)."""
        return list(self._pool.map(fun, items)) if self._pool is not None else [fun(item) for item in items]

    def _piece(self, i: int, c: int, s: np.ndarray, v: np.ndarray | None = None, out: tuple | None = None):
        """Block i's per-row Jacobians on piece c's rows at its share ``s`` of the shared vector and the rows'
        velocities ``v`` (None: zero, a block without knots), into ``out`` (its two arrays' rows of the
        piece) or else this thread's scratch (valid until its next piece of that size); returns the
        Jacobians in s. One FunctionBuffer per thread and piece size, pointed at each piece's arrays."""
        pieces = self._local.__dict__.setdefault("pieces", {})
        lo, hi = self._chunks[i][c]
        key = (i, hi - lo)
        if key not in pieces:
            b, f = self.blocks[i], self._jac[i][c]
            k, ns = b.fun.size1_out(0), f.size1_in(2)
            buf, run = f.buffer()
            pieces[key] = (buf, run, (np.empty((hi - lo, k, 3)), np.empty((hi - lo, k, ns))), np.zeros((hi - lo, 3)))
        buf, run, scratch, zero = pieces[key]
        out = scratch if out is None else out
        buf.set_arg(0, memoryview(self._data[i][lo:hi]))  # the buffer holds pointers: each array outlives the run
        buf.set_arg(1, memoryview(zero if v is None else v))
        buf.set_arg(2, memoryview(s))
        buf.set_res(0, memoryview(out[0]))
        buf.set_res(1, memoryview(out[1]))
        run()
        return out[1]

    def _pieces(self, i: int, s: np.ndarray):
        """Block i's pieces in order, ``((lo, hi), per-row Jacobians in s)`` at velocity zero, each in this
        thread's scratch until the next, evaluated in the caller's thread: a Gram pass over 10^5 deep-model
        rows took 0.22 s with the pieces shared out to two threads (their products fight BLAS's own
        threads for the cores), 0.18 s in one, 0.19 s with a thread evaluating the next piece while the
        caller summed the last (2026-12-03, two cores)."""
        for c, piece in enumerate(self._chunks[i]):
            yield piece, self._piece(i, c, s)

    def _has_knots(self, index: int) -> bool:
        return self.blocks[index].velocity_basis is not None and self._knots[index] is not None

    def _knot_index(self, index: int):
        """Block ``index``'s knot entries: (rows within the block, columns of z, the velocity basis
        as COO), output by output and axis by axis; None without knots."""
        if not self._has_knots(index):
            return None
        b, knots = self.blocks[index], self._knots[index]
        k, n = b.fun.size1_out(0), b.data.shape[1]
        H = b.velocity_basis.tocoo()
        rows = np.concatenate([i * n + H.row for i in range(k) for _ in range(3)])
        cols = np.concatenate([knots[H.col, a] for _ in range(k) for a in range(3)])
        return rows, cols, H

    def _knot_pattern(self, index: int) -> sp.csr_matrix | None:
        """Block ``index``'s knot columns (k n, n_z) as a 0/1 pattern, None without knots."""
        entries = self._knot_index(index)
        if entries is None:
            return None
        rows, cols, _ = entries
        b = self.blocks[index]
        P = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(b.fun.size1_out(0) * b.data.shape[1], self.n_z))
        P.data[:] = 1.0
        return P

    def _pattern(self) -> sp.csr_matrix:
        """Structural pattern of J (rows x z): each block's shared columns and its rows' knots."""
        pieces = []
        for index, (b, sc) in enumerate(zip(self.blocks, self._cols)):
            m = b.fun.size1_out(0) * b.data.shape[1]
            pieces.append((b.offset, np.ones((m, sc.size)), sc, self._knot_pattern(index)))
        return self._stack(pieces) != 0

    def gram_sparsity(self) -> sp.csr_matrix:
        """Pattern of J^T J (n_z, n_z), from the blocks' structure (shared columns dense, knots
        sparse) without multiplying J's pattern out."""
        G = sp.csr_matrix((self.n_z, self.n_z))
        for index, sc in enumerate(self._cols):
            rows, cols = np.repeat(sc, sc.size), np.tile(sc, sc.size)
            parts = [sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(self.n_z, self.n_z))]
            P = self._knot_pattern(index)
            if P is not None:
                kc = np.unique(P.indices)
                rows, cols = np.repeat(kc, sc.size), np.tile(sc, kc.size)
                cross = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(self.n_z, self.n_z))
                parts += [cross, cross.T.tocsr(), sp.csr_matrix(P.T @ P)]
            for part in parts:
                G = G + part
        return G != 0

    def _stack(self, pieces) -> sp.csr_matrix:
        """J (n_rows, n_z) as CSR from (offset, shared part (m, len(c)), c, knot part or None) per
        block: each block's entries written once into J's own data and column-index arrays, row
        blocks in order (int32 indices, no triplets, no scipy stacking: a tenth of the memory at
        10^5 pings). Rows no block holds (none today) stay empty."""
        blocks = []
        for offset, shared, sc, knot_part in pieces:
            if knot_part is None:  # the same columns on every row: written below without a CSR of its own
                blocks.append((int(offset), shared, sc))
                continue
            m = shared.shape[0]
            block = sp.csr_matrix((shared.reshape(-1), np.tile(sc.astype(np.int32), m),
                                   np.arange(m + 1, dtype=np.int64) * sc.size), shape=(m, self.n_z)) + knot_part
            blocks.append((int(offset), block, None))
        blocks.sort(key=lambda p: p[0])
        counts = np.zeros(self.n_rows, dtype=np.int64)  # entries per row
        row = 0
        for start, block, sc in blocks:
            if start < row or start + block.shape[0] > self.n_rows:
                raise ValueError(f"RowJacobian: block rows {start}..{start + block.shape[0]} overlap another's or lie "
                                 f"outside 0..{self.n_rows}")
            row = start + block.shape[0]
            counts[start:row] = sc.size if sc is not None else np.diff(block.indptr)
        indptr = np.concatenate([[0], np.cumsum(counts)])
        index_type = np.int32 if indptr[-1] < np.iinfo(np.int32).max else np.int64
        data, indices = np.empty(indptr[-1]), np.empty(indptr[-1], dtype=index_type)
        for start, block, sc in blocks:
            lo, hi = indptr[start], indptr[start + block.shape[0]]
            if sc is not None:
                data[lo:hi] = block.reshape(-1)
                indices[lo:hi].reshape(block.shape)[...] = sc
            else:
                data[lo:hi], indices[lo:hi] = block.data, block.indices
        return sp.csr_matrix((data, indices, indptr.astype(index_type)), shape=(self.n_rows, self.n_z))

    def _scratch(self, index: int, shape: tuple) -> np.ndarray:
        """Block ``index``'s shared-column part, one array per thread reused from call to call
        (allocating 10^5 pings' afresh cost as much as filling it)."""
        scratch = getattr(self._local, "scratch", None)
        if scratch is None:
            scratch = self._local.scratch = {}
        if index not in scratch or scratch[index].shape != shape:
            scratch[index] = np.empty(shape)
        return scratch[index]

    def _parts(self, z, w, only=None):
        """Per block (those in ``only``; None: all): its rows r (k n,), its shared columns c, the
        weighted shared-column part (k n, len(c)) dense, and the weighted knot part (k n, n_z)
        sparse (None without knots). The shared-column part is this thread's scratch array: valid
        until the next call."""
        w = np.asarray(w, dtype=float).ravel()
        s, ds_dz = self._shared_at(z)
        for index, b in enumerate(self.blocks):
            if only is not None and index not in only:
                continue
            k, n, rows, sc, a, ds_b = self._block(index, w, ds_dz)
            entries = self._knot_index(index)
            jv, js = self._evaluate(index, self._velocity(index, z), s[self._index[index]])
            shared = self._shared_part(index, js, a, ds_b)
            knot_part = None
            if entries is not None:
                knot_rows, cols, H = entries
                jw = jv.transpose(1, 0, 2) * a.T[:, :, None]  # (k, n, 3): weighted and signed
                vals = np.concatenate([jw[i, H.row, ax] * H.data for i in range(k) for ax in range(3)])
                knot_part = sp.csr_matrix((vals * self.knot_scale[cols], (knot_rows, cols)), shape=(k * n, self.n_z))
            yield np.arange(rows.start, rows.stop), sc, shared, knot_part

    def _velocity(self, index: int, z) -> np.ndarray:
        """Block ``index``'s velocity at its rows, (n, 3) (CasADi's column-major (3, n)): the knots through its
        velocity basis, zero without knots."""
        if not self._has_knots(index):
            return np.zeros((self.blocks[index].data.shape[1], 3))
        knots = self._knots[index]
        return self.blocks[index].velocity_basis @ (np.asarray(z, dtype=float).ravel()[knots] * self.knot_scale[knots])

    def _shared_part(self, index: int, js: np.ndarray, a: np.ndarray, ds_b: np.ndarray) -> np.ndarray:
        """Block ``index``'s weighted part of J on its shared columns, (k n, len(sc)) output-major, from its per-row
        Jacobians in s ``js`` (n, k, ns), the weights times signs ``a`` (n, k) and ds/dz ``ds_b``: this thread's
        scratch array, valid until the next call."""
        n, k = a.shape
        shared = self._scratch(index, (k * n, ds_b.shape[1]))
        for i in range(k):  # js[:, i] is a strided (n, ns) matrix BLAS takes as it is
            out = shared[i * n:(i + 1) * n]
            np.matmul(js[:, i], ds_b, out=out)
            out *= a[:, i, None]
        return shared

    def __call__(self, z, w) -> sp.csr_matrix:
        return self._stack([(r[0], shared, sc, knot_part) for r, sc, shared, knot_part in self._parts(z, w)])

    def gram(self, z, w) -> np.ndarray:
        """J^T J (n_z, n_z) dense, block by block, without forming J: the shared columns'
        part by a dense product, the knots' through the velocity basis (knot and shared columns are disjoint)."""
        return self.gram_and_gradient(z, w)[0]

    def _block(self, index: int, w: np.ndarray, ds_dz) -> tuple:
        """A block as the passes over J take it: (k outputs, n rows,
        its slice of J's rows, its shared columns sc, the weights w times the outputs' signs as (n, k), and
        ds/dz of its share of s on columns sc, dense)."""
        b = self.blocks[index]
        k, n = b.fun.size1_out(0), b.data.shape[1]
        rows = slice(b.offset, b.offset + k * n)
        sign = np.ones(k) if b.sign is None else np.asarray(b.sign, dtype=float)
        a = (w[rows].reshape(k, n) * sign[:, None]).T  # (n, k): row j's output i weighted and signed
        sc = self._cols[index]
        return k, n, rows, sc, a, ds_dz[self._index[index]][:, sc].toarray()

    def gram_and_gradient(self, z, w, e: np.ndarray | None = None) -> tuple:
        """J^T J as :meth:`gram` and, with the residuals ``e`` (n_rows,), the gradient J^T e of
        0.5 |e|^2 from the same pass over the blocks (None without ``e``).

        A block without knots is summed in its own shared inputs first, ds^T (sum_rows w^2 js^T js)
        ds with js the per-row Jacobian in s: J's block (rows x its columns of z) is never formed."""
        G = np.zeros((self.n_z, self.n_z))
        grad = None if e is None else np.zeros(self.n_z)
        w = np.asarray(w, dtype=float).ravel()
        s, ds_dz = self._shared_at(z)
        knotted = []
        for index in range(len(self.blocks)):
            if self._has_knots(index):  # summed through the velocity basis below
                knotted.append(index)
                continue
            k, n, rows, sc, a, ds_b = self._block(index, w, ds_dz)
            if n == 0:
                continue
            s_b = np.ascontiguousarray(s[self._index[index]])
            ea = None if e is None else np.asarray(e[rows]).reshape(k, n).T
            M, g = np.zeros((s_b.size, s_b.size)), np.zeros(s_b.size)
            for (lo, hi), js in self._pieces(index, s_b):
                jw = (js * a[lo:hi, :, None]).reshape(-1, s_b.size)
                M += jw.T @ jw  # numpy takes A.T @ A to BLAS syrk
                if ea is not None:
                    g += jw.T @ ea[lo:hi].ravel()
            G[np.ix_(sc, sc)] += ds_b.T @ M @ ds_b
            if grad is not None:
                grad[sc] += ds_b.T @ g
        for index in knotted:
            self._knotted_sums(index, z, w, s, ds_dz, e, G, grad)
        return G, grad

    def _knotted_sums(self, index: int, z, w: np.ndarray, s: np.ndarray, ds_dz, e, G: np.ndarray, grad) -> None:
        """Add a block with knots to J^T J (and J^T e) in place. Its knot part is never formed: row (i, j)
        (output i, ping j) has d/dV[K, a] = jw[i, j, a] H[j, K] scale[K, a], with jw the weighted, signed
        per-row Jacobian in the velocity and H the velocity basis, so the knot-knot part is, per axis pair,
        H^T diag(sum_i jw_a jw_b) H, and the knot-shared part H^T (sum_i jw_a shared_i): sparse products
        of H (n x K), where the (k n, n_z) knot part (10^5 pings: 2.4e6 entries) cost a CSR build and two
        sparse products at every evaluation."""
        k, n, rows, sc, a, ds_b = self._block(index, w, ds_dz)
        knots, (H, Ht) = self._knots[index], self._basis(index)
        scale = self.knot_scale[knots]  # (K, 3)
        jv, js = self._evaluate(index, self._velocity(index, z), s[self._index[index]])
        shared = self._shared_part(index, js, a, ds_b)
        G[np.ix_(sc, sc)] += shared.T @ shared
        jw = jv.transpose(1, 0, 2) * a.T[:, :, None]  # (k, n, 3): weighted and signed
        by_ping = shared.reshape(k, n, sc.size)
        er = None if grad is None else np.asarray(e[rows]).reshape(k, n)
        if grad is not None:
            grad[sc] += shared.T @ np.asarray(e[rows])
        for p in range(3):
            cross = scale[:, p, None] * (Ht @ np.einsum("in,inc->nc", jw[:, :, p], by_ping))  # (K, len(sc))
            G[np.ix_(knots[:, p], sc)] += cross
            G[np.ix_(sc, knots[:, p])] += cross.T
            for q in range(p, 3):
                d = np.einsum("in,in->n", jw[:, :, p], jw[:, :, q])
                block = _dense(Ht @ (H.multiply(d[:, None]).tocsc() if sp.issparse(H) else H * d[:, None]))
                block *= np.outer(scale[:, p], scale[:, q])
                G[np.ix_(knots[:, p], knots[:, q])] += block
                if q != p:
                    G[np.ix_(knots[:, q], knots[:, p])] += block.T
            if grad is not None:
                grad[knots[:, p]] += scale[:, p] * (Ht @ np.einsum("in,in->n", jw[:, :, p], er))

    def _basis(self, index: int) -> tuple:
        """Block ``index``'s velocity basis H (n, K) and its transpose, kept: dense where small (a survey's
        500-ping transects: scipy's per-call cost would outweigh the products), else CSR."""
        cache = self._bases
        if index not in cache:
            H = sp.csr_matrix(self.blocks[index].velocity_basis)
            if H.shape[0] * H.shape[1] <= DENSE_BASIS_ENTRIES:
                H = H.toarray()
                cache[index] = (H, np.ascontiguousarray(H.T))
            else:
                cache[index] = (H, sp.csr_matrix(H.T))
        return cache[index]

    def matmul(self, z, w, M) -> np.ndarray:
        """J @ M (n_rows, q) for M (n_z, q), J never formed: a block without knots maps M through its
        shared inputs first, (w sign js) (ds M), the others go through :meth:`_parts`. The HAC
        sandwich needs only J @ P_q: a CSR J of 10^5 pings costs five times this to build and multiply."""
        M = np.asarray(M, dtype=float)
        M2 = M.reshape(M.shape[0], -1)
        out = np.zeros((self.n_rows, M2.shape[1]))  # rows no block holds (none today) are zero, as in J
        w = np.asarray(w, dtype=float).ravel()
        s, ds_dz = self._shared_at(z)
        knotted = []
        for index in range(len(self.blocks)):
            if self._has_knots(index):
                knotted.append(index)
                continue
            k, n, rows, sc, a, ds_b = self._block(index, w, ds_dz)
            _, js = self._evaluate(index, np.zeros((n, 3)), s[self._index[index]])
            jb = (js.reshape(n * k, -1) @ (ds_b @ M2[sc])).reshape(n, k, -1)  # one product; rows ping-major
            jb *= a[:, :, None]
            out[rows].reshape(k, n, -1)[...] = jb.transpose(1, 0, 2)  # output-major, as J's rows
        for r, sc, shared, knot_part in self._parts(z, w, only=knotted):
            part = out[r[0]:r[-1] + 1]
            part[...] = shared @ M2[sc]
            if knot_part is not None:
                part += knot_part @ M2
        return out.reshape((self.n_rows,) + M.shape[1:])

    def at(self, z, w) -> "JacobianAt":
        """J at (z, w) as an operator (``J @ M``, ``shape``), for what needs only its products."""
        return JacobianAt(self, z, w)

    def _shared_at(self, z):
        """s(z) (flat) and ds/dz (CSR)."""
        s, ds_dz = self._shared(z)
        return s.full().ravel(), ds_dz.sparse().tocsr()

    def jacobian_and_gram(self, z, w) -> tuple[sp.csr_matrix, np.ndarray]:
        """J as CSR and J^T J from one pass over the blocks (a sparse J^T J of 10^5 pings costs
        more than the pass)."""
        pieces = []
        G, _ = self._accumulate(self._parts(z, w), None, pieces)
        return self._stack([(r[0], shared, sc, knot_part) for r, sc, shared, knot_part in pieces]), G

    def _accumulate(self, parts, e: np.ndarray | None, keep: list | None = None) -> tuple:
        """(J^T J, J^T e or None) over ``parts`` (:meth:`_parts`); each part appended to ``keep`` if given."""
        G = np.zeros((self.n_z, self.n_z))
        grad = None if e is None else np.zeros(self.n_z)
        for part in parts:
            r, sc, shared, knot_part = part
            if keep is not None:
                keep.append(part)
            G[np.ix_(sc, sc)] += shared.T @ shared  # numpy takes A.T @ A to BLAS syrk
            if grad is not None:
                grad[sc] += shared.T @ e[r[0]:r[-1] + 1]  # a block's rows are contiguous
            if knot_part is not None:  # on the block's own knot columns only: a survey's other runs' stay untouched
                kc = np.unique(knot_part.indices)
                kp = knot_part[:, kc]
                cross = np.asarray(kp.T @ shared)  # (knot cols, shared cols)
                G[np.ix_(kc, sc)] += cross
                G[np.ix_(sc, kc)] += cross.T
                G[np.ix_(kc, kc)] += (kp.T @ kp).toarray()
                if grad is not None:
                    grad[kc] += kp.T @ e[r[0]:r[-1] + 1]
        return G, grad


def _dense(M) -> np.ndarray:
    return M.toarray() if sp.issparse(M) else np.asarray(M)


class JacobianAt:
    """J(z, w) of a :class:`RowJacobian` as an operator: ``J @ M`` from its blocks, J never formed."""

    def __init__(self, jacobian: RowJacobian, z, w):
        self._jac = jacobian
        self._z, self._w = np.array(z, dtype=float), np.array(w, dtype=float)

    @property
    def shape(self) -> tuple[int, int]:
        return self._jac.n_rows, self._jac.n_z

    def __matmul__(self, M) -> np.ndarray:
        return self._jac.matmul(self._z, self._w, M)
