"""A per-ping CasADi Function evaluated over many pings at once.

The Function takes one column per ping for each per-ping input and one parameter column
shared by every ping. The pings are cut into equal blocks of at most ``CHUNK``; one plain
map over a block (built once per block size, the shared column repeated for it) is evaluated
through CasADi's buffer interface straight from and into numpy arrays: the DM round trip of
an ordinary call costs more than the evaluation itself for the small per-ping models here.
When the run is long enough to repay the compiler, the Function is evaluated as machine code
from the per-machine cache (:mod:`.compiled`: compiled once, then loaded by every process).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .compiled import available, compiled

CHUNK = 16384  # pings per mapped evaluation at most
MAX_MAPS = 64  # block sizes whose maps a PingFunction keeps


@dataclass(frozen=True)
class MapOptions:
    """How a per-ping Function is evaluated over the pings.

    Parameters
    ----------
    threads : int
        Threads sharing each block of pings (CasADi ``thread`` map).
    compile : str
        ``auto`` (compile with the system C compiler when there are at least
        ``compile_min_pings`` pings and a compiler is found), ``always`` or ``never``.
    compile_min_pings : int
        Below this the interpreted evaluation finishes before the compiler would.
    """

    threads: int = 2
    compile: str = "auto"
    compile_min_pings: int = 100_000

    def __post_init__(self):
        if self.compile not in ("auto", "always", "never"):
            raise ValueError(f"{type(self).__name__}.compile: expected 'auto', 'always' or 'never', got {self.compile!r}")
        if self.threads < 1:
            raise ValueError(f"{type(self).__name__}.threads: expected >= 1, got {self.threads}")

    def compiled(self, n_pings: int) -> bool:
        if self.compile == "never" or not available():
            return False
        return self.compile == "always" or n_pings >= self.compile_min_pings


class PingFunction:
    """``f(per-ping inputs..., shared) -> outputs``: an SX Function whose inputs and outputs are
    column vectors, the last input shared by every ping.

    Call it with one (N, k) array per per-ping input (row n: ping n) and the shared column;
    it returns one (N, k_out) array per output (outputs made dense).
    """

    def __init__(self, fun: ca.Function):
        if any(fun.size2_in(i) != 1 for i in range(fun.n_in())) or any(fun.size2_out(i) != 1 for i in range(fun.n_out())):
            raise ValueError(f"{fun.name()}: inputs and outputs must be column vectors")
        ins = fun.sx_in()
        self.fun = ca.Function(fun.name(), ins, [ca.densify(o) for o in fun.call(ins)], fun.name_in(), fun.name_out())
        self._maps = {}

    @functools.cached_property
    def _compiled(self) -> ca.Function:
        return compiled(self.fun)

    def _mapped(self, size: int, compiled: bool, threads: int) -> ca.Function:
        """A plain Map node over ``size`` pings, built at once (CasADi's map with an input shared by
        the pings is an MX graph whose construction grows faster than the size: 0.2 s at 16384)."""
        key = (size, compiled, threads)
        if key not in self._maps:
            if len(self._maps) >= MAX_MAPS:
                self._maps.clear()
            f = self._compiled if compiled else self.fun
            self._maps[key] = f.map(size, "thread", threads) if threads > 1 else f.map(size)
        return self._maps[key]

    def __call__(self, *args, options: MapOptions | None = None) -> list[np.ndarray]:
        options = options or MapOptions()
        *per_ping, shared = args
        per_ping = [np.ascontiguousarray(a, dtype=float).reshape(a.shape[0], -1) for a in per_ping]
        n = per_ping[0].shape[0]
        outputs = [np.empty((n, self.fun.nnz_out(i))) for i in range(self.fun.n_out())]
        if n == 0:
            return outputs
        threads = max(1, min(options.threads, n))
        size = -(-n // -(-n // CHUNK))  # equal blocks of at most CHUNK: the last one padded by fewer pings than blocks
        f = self._mapped(size, options.compiled(n), threads)
        shared = np.ascontiguousarray(np.tile(np.asarray(shared, dtype=float).ravel(), (size, 1)))  # one column per ping
        buffer, evaluate = f.buffer()
        buffer.set_arg(len(per_ping), memoryview(shared))
        for start in range(0, n, size):
            stop = min(start + size, n)
            ins = [a[start:stop] for a in per_ping]
            outs = [o[start:stop] for o in outputs]
            if stop - start < size:  # the last block, padded with its last ping
                ins = [np.concatenate([a, np.repeat(a[-1:], size - a.shape[0], axis=0)]) for a in ins]
                outs = [np.empty((size, o.shape[1])) for o in outs]
            for i, a in enumerate(ins):
                buffer.set_arg(i, memoryview(a))
            for i, o in enumerate(outs):
                buffer.set_res(i, memoryview(o))
            evaluate()
            if stop - start < size:
                for o, block in zip(outputs, outs):
                    o[start:stop] = block[:stop - start]
        return outputs
