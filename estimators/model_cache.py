"""Built NLPs kept by shape, so that one graph, its Jacobian and its solver serve every run or case of
that shape (issue 25: data as parameters): the diagnosis's models (:class:`~.diagnosis.model.GapModel`)
and the calibration's symbolic problems (:class:`~.calibration.problem.CalibrationProblem`).

Both take the recorded numbers as NLP parameters, so two of them differ in their graph only by what is
baked into it (knot times, basis matrices, the sensor's times, the effects' constants). A model takes a
kept graph only when its own cheap residuals agree with the kept graph's at random unknowns on its own
numbers (``model.same_graph``): two graphs that agree at random points are the same function, so its
Jacobian, colouring and solver are the same. What differs is rebuilt, never guessed.

A kept model provides ``graph_parts()`` (what another model takes: symbols, graph, Functions, solver;
never its runs or numbers), ``graph_signature()`` (compared first: sizes, pins), ``probe_points()``
and ``same_graph(parts, points)``.

``ADCPDYN_MODEL_CACHE`` sets how many are kept (0: none); :func:`stats` counts hits and misses.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

CACHE_ENV = "ADCPDYN_MODEL_CACHE"
DEFAULT_SIZE = 32  # a diagnosis builds about 30 graphs (16 candidates, 14 again at other reference delays); ~22 MB each at 3000 pings
CHECK_POINTS = 2
CHECK_RTOL = 1e-9

_kept: OrderedDict = OrderedDict()  # shape key -> [Built]
_lock = threading.Lock()
_stats = {"hits": 0, "misses": 0, "rejected": 0}


@dataclass(eq=False)
class Built:
    """A built model's graph without its runs (``parts``), its signature, and how often another model
    took it (``taken``)."""

    parts: dict
    signature: tuple
    taken: int = 0


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
    """A kept graph of ``key`` that is ``model``'s (its signature, then ``model.same_graph``), or None."""
    if capacity() == 0:
        return None
    with _lock:
        candidates = list(_kept.get(key, ()))
    signature, points = model.graph_signature(), None
    for other in candidates:
        if other.signature == signature:
            points = model.probe_points() if points is None else points  # the new model's own numbers, once
            if model.same_graph(other.parts, points):
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


def keep(key, model, most: int | None = None) -> None:
    """Keep ``model``'s graph; over :func:`capacity` (or over ``most`` graphs whose keys begin as this one's:
    a kind whose graphs are large), drop the least recently used graph that no model has taken yet (else the
    least recently used): a field self-test's clean-run graphs, taken by every injected run, outlive a run
    whose error makes graphs of other shapes (a motion model's attitude latency)."""
    n = capacity()
    if n == 0:
        return
    new = Built(model.graph_parts(), model.graph_signature())
    with _lock:
        _kept.setdefault(key, []).append(new)
        _kept.move_to_end(key)
        for alike, limit in ((lambda k: k[0] == key[0], most), (lambda k: True, n)):
            while limit is not None and sum(len(v) for k, v in _kept.items() if alike(k)) > limit:
                kept = [(k, b) for k, bs in _kept.items() if alike(k) for b in bs if b is not new]
                k, b = next(((k, b) for k, b in kept if b.taken == 0), kept[0])
                _kept[k] = [x for x in _kept[k] if x is not b]
                if not _kept[k]:
                    del _kept[k]


def probe(check, x_of_z, data, lbz, ubz, parameters_at) -> list:
    """A model's own values at ``CHECK_POINTS`` random unknowns z (uniform in [-1, 1], within the bounds
    [lbz, ubz]) on its recorded numbers: ``check(x_of_z(z), data)`` is its undifferentiated graph (cheap),
    its first output the residuals. Per point (z, the NLP's parameters with unit weights, the outputs)."""
    rng = np.random.default_rng(20261201)
    points = []
    for _ in range(CHECK_POINTS):
        z = np.clip(rng.uniform(-1.0, 1.0, lbz.size), lbz, ubz)
        values = [np.asarray(v, dtype=float).ravel() for v in check(x_of_z(z), data)]
        points.append((z, parameters_at(np.ones(values[0].size)), values))
    return points


def agree_at(points: list, evaluate) -> bool:
    """Whether ``evaluate(z, p)`` (a kept graph's outputs, in :func:`probe`'s order) gives the model's own
    values at every probe point; a point with more than a tenth of its residuals not finite proves nothing."""
    for z, p, values in points:
        if np.mean(np.isfinite(values[0])) < 0.9:
            return False
        if not all(_agree(a, b) for a, b in zip(values, evaluate(z, p), strict=True)):
            return False
    return True


def _agree(a, b) -> bool:
    """Two evaluations of a graph at one point agree (relative to the first's scale, NaN where NaN)."""
    a, b = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=CHECK_RTOL, equal_nan=True,
                                                   atol=CHECK_RTOL * max(np.nanmax(np.abs(a), initial=0.0), 1e-12)))
