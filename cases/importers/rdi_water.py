"""TRDI water profile -> the case's ``/water`` group, back in beam coordinates.

Each cell's velocities go back to per-beam radial velocities with exactly the inverse
transforms the bottom track uses (:func:`.rdi_frames.to_beam` with the same per-ping
rotation: levelling, heading alignment EA and heading undone for ship and Earth files),
RDI beams reordered into case beams, positive toward the transducer (TRDI's and the
case's convention). What the instrument rejected is NaN:

- the -32768 mm/s marker (dolfyn reads it as NaN): the instrument's own screening
  (correlation threshold WC, and in ship/Earth coordinates the error-velocity
  threshold WE and "more than one beam bad") shows there;
- in beam coordinates the instrument's screening is re-applied from the file's own
  numbers (correlation below WC, percent good 0), which on every file here adds nothing;
- in ship, instrument or Earth coordinates, a cell the instrument solved with three
  beams (its error velocity is the marker) cannot go back to four beams: the file holds
  the velocity but not which beam was missing, so all four radials are NaN there, as for
  the bottom track.

Cell depths: transducer depth + dolfyn's ``range`` (TRDI's bin-1 distance + i * cell
size: the vertical distance from the transducer face to the cell centre, as TRDI defines
depth cells). Only cells above the deepest bed of the run are kept.
"""

from __future__ import annotations

import contextlib

import numpy as np

from ..case import Water
from . import rdi_frames

MM = 1000.0


@contextlib.contextmanager
def cell_size_history():
    """Capture the cell-size changes dolfyn's TRDI reader saw, as ``[(first ensemble, cell size m), ...]``.

    dolfyn (mhkit 1.1.2) depth-averages the smaller cells of a file whose cell size
    changed into the largest cell size and keeps only that configuration's bin-1 distance;
    it does not report which ensembles were merged. This wraps its reader's ``cleanup``
    to read the list it keeps. The list stays empty when the reader is not the expected
    one (nothing is patched then).
    """
    history: list = []
    try:
        from mhkit.dolfyn.io.rdi import _RDIReader
    except ImportError:  # the reader is absent: import_trdi reports that itself
        yield history
        return
    original = getattr(_RDIReader, "cleanup", None)
    if original is None:
        yield history
        return

    def cleanup(self, dat, cfg):
        history.extend((int(i), float(s)) for i, s in getattr(self, "cs", []))
        return original(self, dat, cfg)

    _RDIReader.cleanup = cleanup
    try:
        yield history
    finally:
        _RDIReader.cleanup = original


def _restore(raw32: np.ndarray) -> tuple[np.ndarray, int]:
    """float32 m/s -> float64: the PD0's integer mm/s where that round-trips, else the value as read."""
    raw = np.asarray(raw32)
    mm = np.round(raw.astype(np.float64) * MM)
    exact = np.isfinite(raw) & (np.asarray(mm / MM, dtype=raw.dtype) == raw)
    out = np.where(exact, mm / MM, raw.astype(np.float64))
    out[np.isfinite(out) & (np.round(out * MM) == rdi_frames.BAD_VELOCITY_MM_S)] = np.nan
    return out, int(np.sum(np.isfinite(raw) & ~exact))


def _merged_pings(history, keep: np.ndarray) -> tuple[np.ndarray, str]:
    """Which kept pings dolfyn merged from smaller cells, and a note."""
    n_read = keep.size
    merged = np.zeros(n_read, dtype=bool)
    if len(history) <= 1:
        return merged[keep], "one cell size throughout (no cells merged)"
    starts = [i for i, _ in history] + [n_read]
    sizes = [s for _, s in history]
    largest = max(sizes)
    for (i0, size), i1 in zip(history, starts[1:]):
        if size < largest:
            merged[i0:i1] = True
    parts = ", ".join(f"{size:g} m from ensemble {i0}" for i0, size in history)
    note = (f"the cell size changed within the file ({parts}); dolfyn depth-averaged the smaller cells into "
            f"{largest:g} m cells and gave every ping the depths of the {largest:g} m configuration, so the "
            f"{int(merged[keep].sum())} kept pings recorded with smaller cells hold averages whose centres are only "
            "approximately at /water/cell_depth_m (the file's bin-1 distance of their configuration is not kept by dolfyn)")
    return merged[keep], note


def water_profile(ds, coord: str, beam_angle_rad: float, convex: bool, rotation, keep: np.ndarray,
                  transducer_depth_m: float, deepest_bed_m: float, history=()) -> tuple[Water | None, dict]:
    """The case's ``/water`` from a dolfyn TRDI dataset, and its audit attributes.

    Parameters
    ----------
    ds : xarray.Dataset
        dolfyn's dataset (``vel`` (4, K, N) in ``coord`` coordinates, ``range`` (K,)).
    coord : str
        ``beam``, ``inst``, ``ship`` or ``earth``: the file's frame.
    beam_angle_rad, convex : float, bool
        Janus geometry of the head.
    rotation : (n, 3, 3) array or None
        The per-ping matrix the instrument applied (the bottom track's), for the kept pings.
    keep : (N,) bool array
        The pings kept by the window.
    transducer_depth_m, deepest_bed_m : float
        Depth of the transducer and of the deepest bed of the kept pings, m.
    history : sequence of (ensemble, cell size)
        From :func:`cell_size_history`.

    Returns
    -------
    (Water or None, dict)
        None with the reason when the file has no usable profile.
    """
    if "vel" not in ds or "range" not in ds.coords:
        return None, {"water_profile": "none: no TRDI velocity profile in this file"}
    vel = np.asarray(ds["vel"].values)
    if vel.ndim != 3 or vel.shape[0] < 4:
        return None, {"water_profile": f"none: vel: expected (4, cells, pings), got shape {vel.shape}"}
    rng = np.asarray(ds["range"].values, dtype=np.float64)
    depth_all = transducer_depth_m + rng
    cells = np.flatnonzero(depth_all < deepest_bed_m)
    if cells.size == 0:
        return None, {"water_profile": f"none: no cell above the deepest bed ({deepest_bed_m:.2f} m); first cell at "
                                       f"{depth_all[0]:.2f} m"}
    raw = vel[:4][:, cells][:, :, keep].transpose(2, 1, 0)  # (N, K, 4) as recorded
    values, n_inexact = _restore(raw)
    n_marker = int(np.sum(~np.isfinite(raw)))
    screened, n_corr, n_pg = _instrument_screening(ds, coord, cells, keep, values)
    N, K, _ = values.shape
    three_beam = 0
    if coord != "beam":
        three_beam = int(np.sum(np.all(np.isfinite(values[..., :3]), axis=-1) & ~np.isfinite(values[..., 3])))
    rot = None if rotation is None else np.repeat(rotation, K, axis=0)
    beams = rdi_frames.to_beam(screened.reshape(N * K, 4), coord, beam_angle_rad, convex, rot).reshape(N, K, 4)
    radial = rdi_frames.case_beams(beams).transpose(0, 2, 1)  # (N, 4, K)
    merged, merge_note = _merged_pings(list(history), keep)
    attrs = {
        "velocity_source": f"dolfyn vel in {coord} coordinates (float32), restored to the PD0's integer mm/s where "
                           f"that round-trips, float64 ({n_inexact} values are not whole mm/s: dolfyn's averages of "
                           "merged cells, kept as read)",
        "sign": "positive toward the transducer (TRDI beam convention = case convention)",
        "beam_mapping": "case beams 1,2,3,4 = RDI beams 4,3,2,1 (as the bottom track)",
        "transforms_undone": ("none (recorded in beam coordinates)" if coord == "beam" else
                              "the bottom track's: the same per-ping matrix transposed, then the inverse of TRDI's 4x4 "
                              "beam matrix (error velocity kept)"),
        "bad_value_marker": f"-32768 mm/s (dolfyn: NaN) -> NaN: {n_marker} of {raw.size} recorded values",
        "instrument_screening": _screening_note(ds, coord, n_corr, n_pg),
        "three_beam_solutions": (f"{three_beam} cells solved by the instrument with three beams (error velocity = "
                                 "marker): the file does not say which beam was missing, so all four radials are NaN "
                                 "there, as for the bottom track" if coord != "beam" else
                                 "not applicable (beam coordinates: a lost beam is NaN alone)"),
        "bin_mapping_EX": (f"{ds.attrs.get('bin_mapping', 'unknown')}: with bin mapping the instrument took each beam's "
                           "value from the bin at the cell's depth for the ping's tilt, so a cell is a depth level, "
                           "not one along-beam bin" if coord != "beam" else "not applied (beam coordinates)"),
        "cell_depth_convention": (f"transducer depth ({transducer_depth_m:.3f} m) + dolfyn range (TRDI bin-1 distance "
                                  "+ i * cell size: vertical distance from the transducer face to the cell centre); "
                                  f"cell size {float(ds.attrs.get('cell_size', np.nan)):g} m, blank "
                                  f"{float(ds.attrs.get('blank_dist', np.nan)):g} m"),
        "cells_kept": (f"{K} of {rng.size}: the cells above the deepest bed of the selected pings "
                       f"({deepest_bed_m:.2f} m); cells below the local bed or within its side-lobe layer are kept as "
                       "recorded (the instrument does not screen them)"),
        "cell_size_changes": merge_note,
        "merged_pings": int(merged.sum()),
        "marker_values": n_marker, "screened_values": n_corr + n_pg, "three_beam_cells": three_beam,
        "cells_in_file": int(rng.size),
        "not_imported": "surface-layer profile (vel_sl) and the vertical beam" if "vel_sl" in ds else "",
    }
    return Water(cell_depth_m=depth_all[cells], radial_m_s=radial), attrs


def _instrument_screening(ds, coord, cells, keep, values):
    """In beam coordinates, NaN where the file's own correlation (< WC) or percent good (0) rejects a value."""
    out = values.copy()
    if coord != "beam":
        return out, 0, 0
    n_corr = n_pg = 0
    thr = ds.attrs.get("min_corr_threshold")
    if "corr" in ds and thr is not None:
        corr = np.asarray(ds["corr"].values)[:4][:, cells][:, :, keep].transpose(2, 1, 0)
        low = (corr < float(thr)) & np.isfinite(out)
        n_corr = int(low.sum())
        out[low] = np.nan
    if "prcnt_gd" in ds:
        pg = np.asarray(ds["prcnt_gd"].values)[:4][:, cells][:, :, keep].transpose(2, 1, 0)
        none = (pg == 0) & np.isfinite(out)
        n_pg = int(none.sum())
        out[none] = np.nan
    return out, n_corr, n_pg


def _screening_note(ds, coord, n_corr, n_pg) -> str:
    thr = ds.attrs.get("min_corr_threshold", "?")
    if coord == "beam":
        return (f"the instrument's rejections are the marker; its correlation threshold (WC = {thr} counts) and "
                f"percent good re-applied from the file: {n_corr} more values below WC and {n_pg} more with 0 % "
                "good set to NaN")
    return (f"the instrument's rejections (correlation threshold WC = {thr} counts, error-velocity threshold "
            f"WE = {ds.attrs.get('max_error_vel', '?')} m/s, more than one beam bad) are the marker; per-beam "
            "correlation is not re-applied in ship/Earth coordinates (with bin mapping a cell's beams come from "
            "other bins)")
