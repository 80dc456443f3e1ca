"""The decision vector as named blocks (:class:`Unknowns`: symbol, names, scales, bounds, slices)
and an attitude model's block."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..models.motion import AttitudeParams


def attitude_bounds(params: AttitudeParams, min_decay: float = 0.0, decay_scale: float = 0.05):
    """Names, scales and bounds of an attitude block (frequencies kept within -20/+25 % of the
    pre-fit's, decays in [min_decay, 3] 1/s, biases within +-90 deg)."""
    lay = params.layout
    s = lay.slices()
    scale, lo, hi = np.ones(lay.size), np.full(lay.size, -np.inf), np.full(lay.size, np.inf)
    for k, (w, _) in enumerate(params.modes):
        i = s["modes"].start + 2 * k
        scale[i], lo[i], hi[i] = 0.01 * w, 0.8 * w, 1.25 * w
        scale[i + 1], lo[i + 1], hi[i + 1] = decay_scale, min_decay, 3.0
    for axis in ("roll", "pitch", "yaw"):
        cs = getattr(params, f"{axis}_cs")
        scale[s[f"{axis}_cs"]] = np.repeat(np.maximum(np.hypot(cs[:, 0], cs[:, 1]), 1e-3), 2)
    for axis in ("roll", "pitch"):
        i = s[f"{axis}_bias"].start
        scale[i], lo[i], hi[i] = 0.01, -np.pi / 2, np.pi / 2
    scale[s["yaw_trend"]] = [1.0 if k == 0 else 0.01**k for k in range(lay.yaw_trend_order + 1)]
    return lay.names(), scale, lo, hi


class Unknowns:
    """The decision vector as named blocks: each block's symbol, names, scales and bounds,
    and where it sits (``slices[key]``)."""

    def __init__(self):
        self.symbols, self.names, self.slices = [], [], {}
        self._scale, self._lo, self._hi = [], [], []

    def add(self, key: str, names, scale, lo, hi, sym: ca.MX | None = None) -> ca.MX:
        """A block of unknowns (a new symbol, or ``sym`` when a model built it) -> its symbol."""
        n = len(names)
        sym = ca.MX.sym(key, n) if sym is None else sym
        start = len(self.names)
        self.slices[key] = slice(start, start + n)
        self.symbols.append(sym)
        self.names += list(names)
        for target, value in ((self._scale, scale), (self._lo, lo), (self._hi, hi)):
            target.extend(np.broadcast_to(np.asarray(value, dtype=float), (n,)).tolist())
        return sym

    @property
    def x(self) -> ca.MX:
        return ca.vertcat(*self.symbols) if self.symbols else ca.MX(0, 1)

    @property
    def scale(self) -> np.ndarray:
        return np.array(self._scale, dtype=float)

    @property
    def lower(self) -> np.ndarray:
        return np.array(self._lo, dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array(self._hi, dtype=float)

    def index(self, key: str) -> np.ndarray:
        s = self.slices.get(key)
        return np.arange(s.start, s.stop) if s is not None else np.zeros(0, dtype=int)
