"""Built diagnosis models kept by shape, so that one graph, its Jacobian and its solver serve every
run of that shape (issue 25: data as parameters).

A :class:`~.model.GapModel` takes the recorded numbers (radials, ranges, depths, the sensor's
segments, reference velocities) as NLP parameters, so two models differ in their graph only by
what is baked into it: the unknowns' scales and pins, the navigation's knots, the reference's
times and weights, the effects' own constants. A model is taken from here only when its cheap
symbolic residuals agree with the kept model's at random unknowns on its own data (and the
constraints too): two graphs that agree at random points are the same function, so its
Jacobian, colouring and solver are the same. What differs is rebuilt, never guessed.

``ADCPDYN_MODEL_CACHE`` sets how many are kept (0: none); :func:`stats` counts hits and misses.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from dataclasses import dataclass

import casadi as ca
import numpy as np

CACHE_ENV = "ADCPDYN_MODEL_CACHE"
DEFAULT_SIZE = 32  # a diagnosis builds about 30 graphs (16 candidates, 14 again at other reference delays); ~22 MB each at 3000 pings
CHECK_POINTS = 2
CHECK_RTOL = 1e-9

# what a model built and another of its graph takes (:meth:`.model.GapModel._take_built`): symbols, graph,
# Functions and the solver whose derivatives a new solver shares; never the runs or their numbers
PARTS = ("_z", "_x_of_z", "_p", "_w", "_d", "_groups", "residual_fun", "jacobian_fun", "raw_fun", "constraint_fun",
         "weighted_fun", "nlp", "solver")
_kept: OrderedDict = OrderedDict()  # shape key -> [Built]
_lock = threading.Lock()
_stats = {"hits": 0, "misses": 0, "rejected": 0}


@dataclass(eq=False)
class Built:
    """A built model's graph without its runs: :data:`PARTS`, what :func:`same_graph` compares first, and
    how often another model took it (``taken``)."""

    parts: dict
    n_unknowns: int
    n_data: int
    constant: np.ndarray
    taken: int = 0

    @classmethod
    def of(cls, model) -> "Built":
        return cls({name: getattr(model, name) for name in PARTS}, model.scale.size, model.data.size,
                   model.constant.copy())


def capacity() -> int:
    try:
        return max(0, int(os.environ.get(CACHE_ENV, DEFAULT_SIZE)))
    except ValueError:
        raise ValueError(f"${CACHE_ENV}: expected a whole number of models to keep, got "
                         f"{os.environ[CACHE_ENV]!r}") from None


def stats() -> dict:
    """Hits, misses and rejected candidates (a model of the same shape whose graph differed) so far."""
    with _lock:
        return {**_stats, "kept": sum(len(v) for v in _kept.values())}


def clear() -> None:
    with _lock:
        _kept.clear()
        for k in _stats:
            _stats[k] = 0


def find(key, model) -> Built | None:
    """A kept graph of ``key`` that is ``model``'s (:func:`same_graph`), or None."""
    if capacity() == 0:
        return None
    with _lock:
        candidates = list(_kept.get(key, ()))
    points = probe(model) if candidates else []  # the new model's own numbers, once for every candidate
    for other in candidates:
        if same_graph(model, other, points):
            with _lock:
                _stats["hits"] += 1
                other.taken += 1
                if key in _kept:
                    _kept.move_to_end(key)
            return other
        with _lock:
            _stats["rejected"] += 1
    with _lock:
        _stats["misses"] += 1
    return None


def keep(key, model) -> None:
    """Keep ``model``'s graph; over :func:`capacity`, drop the least recently used graph that no model has
    taken yet (else the least recently used): a field self-test's clean-run graphs, taken by every injected
    run, outlive a run whose error makes graphs of other shapes (a motion model's attitude latency)."""
    n = capacity()
    if n == 0:
        return
    new = Built.of(model)
    with _lock:
        _kept.setdefault(key, []).append(new)
        _kept.move_to_end(key)
        while sum(len(v) for v in _kept.values()) > n:
            kept = [(k, b) for k, bs in _kept.items() for b in bs if b is not new]
            k, b = next(((k, b) for k, b in kept if b.taken == 0), kept[0])
            _kept[k] = [x for x in _kept[k] if x is not b]
            if not _kept[k]:
                del _kept[k]


def probe(model) -> list:
    """``model``'s residuals and constraints from its own symbolic graph (not differentiated: cheap) at
    random unknowns (within the bounds, pins at theirs) on its recorded numbers: per point (z, the NLP's
    parameters with unit weights, residuals, constraints)."""
    sm = model.model
    fresh = ca.Function("check", [sm.x, sm.data_sym], [sm.raw, sm.g])
    rng = np.random.default_rng(20261201)
    lbz, ubz = model.lbx / model.scale, model.ubx / model.scale
    points = []
    for _ in range(CHECK_POINTS):
        z = np.clip(rng.uniform(-1.0, 1.0, model.scale.size), lbz, ubz)
        x = np.where(model.constant, model.lbx, z * model.scale)
        raw, g = (np.asarray(v, dtype=float).ravel() for v in fresh(x, model.data))
        points.append((z, model.parameters_at(np.ones(raw.size)), raw, g))
    return points


def same_graph(model, built: Built, points: list | None = None) -> bool:
    """Whether the ``built`` graph computes ``model``'s residuals and constraints at the :func:`probe`
    ``points`` (made here when not given)."""
    if built.n_unknowns != model.scale.size or built.n_data != model.data.size or \
            not np.array_equal(built.constant, model.constant):
        return False
    for z, p, raw, g in points if points is not None else probe(model):
        raw_o = np.asarray(built.parts["raw_fun"](z, p), dtype=float).ravel()
        g_o = np.asarray(built.parts["constraint_fun"](z), dtype=float).ravel()
        if raw_o.shape != raw.shape or g_o.shape != g.shape or np.mean(np.isfinite(raw)) < 0.9:
            return False
        for a, b in ((raw, raw_o), (g, g_o)):
            if not np.allclose(a, b, rtol=CHECK_RTOL, atol=CHECK_RTOL * max(np.nanmax(np.abs(a), initial=0.0), 1e-12),
                               equal_nan=True):
                return False
    return True
