"""The instrument's own Earth-frame velocities of a TRDI file, through dolfyn, like for like.

dolfyn (mhkit 1.1.2) keeps velocities, angles and its rotation matrices in float32, so its
Earth velocities carry float32 rounding: up to 1.8e-6 m/s on the real files here (the
velocities reach 30 m/s in the cells below the bed, where a float32 step is 1.9e-6).
:func:`dolfyn_earth` runs dolfyn's own ``rotate2`` (its orientation matrix from heading,
gimbal pitch and roll, heading alone for ship coordinates with tilts applied, its beam
matrix) on the file's numbers restored to float64 (velocities to the PD0's whole mm/s,
angles to its 0.01 deg, where they round-trip): dolfyn's formulas, evaluated in float64.
The file's own ``-32768`` bottom-track marker (dolfyn keeps it as -32.768 m/s in
``vel_bt``) is NaN, as it is in ``vel``.
"""

from __future__ import annotations

import contextlib
import io
from unittest import mock

import numpy as np


class _Float64Numpy:
    """numpy with ``float32`` meaning ``float64``: dolfyn's rotation module evaluated in double precision."""

    def __getattr__(self, name):
        return np.float64 if name == "float32" else getattr(np, name)


def _restored(values, step):
    """float32 values on a grid of ``step`` restored exactly where they round-trip, else as read."""
    x = np.asarray(values)
    grid = np.round(x.astype(np.float64) / step) * step
    same = np.asarray(grid, dtype=x.dtype) == x
    return np.where(same, grid, x.astype(np.float64))


def dolfyn_earth(ds, float64: bool = True):
    """dolfyn's Earth-frame (E, N, U, error) ``vel`` and ``vel_bt`` of a dataset read by dolfyn.

    Returns
    -------
    (vel (4, K, N), vel_bt (4, N)) float64 arrays, NaN where the instrument rejected a value.
    """
    from mhkit import dolfyn
    from mhkit.dolfyn.rotate import rdi as rotate_rdi

    ds = ds.copy(deep=True)
    bt = np.asarray(ds["vel_bt"].values)
    ds["vel_bt"] = ds["vel_bt"].copy(data=np.where(np.round(bt.astype(np.float64) * 1000) == -32768, np.nan, bt))
    if float64:
        for name in ("vel", "vel_bt"):
            ds[name] = ds[name].copy(data=_restored(ds[name].values, 1e-3))
        for name in ("heading", "pitch", "roll"):
            ds[name] = ds[name].copy(data=_restored(ds[name].values, 1e-2))
        with mock.patch.object(rotate_rdi, "np", _Float64Numpy()):
            ds["orientmat"] = rotate_rdi._calc_orientmat(ds)
            ds["beam2inst_orientmat"] = ds["beam2inst_orientmat"].copy(
                data=rotate_rdi._calc_beam_orientmat(ds.attrs["beam_angle"], ds.attrs["beam_pattern"] == "convex"))
    if ds.attrs["coord_sys"] != "earth":
        with contextlib.redirect_stdout(io.StringIO()):
            dolfyn.rotate2(ds, "earth", inplace=True)
    assert list(ds["dir"].values) == ["E", "N", "U", "err"]
    return np.asarray(ds["vel"].values, dtype=np.float64), np.asarray(ds["vel_bt"].values, dtype=np.float64)
