"""Output of a correction: ``/corrected`` in its own HDF5 file, written atomically.

Layout: ``/corrected/time_s`` (N,), ``vessel_velocity_m_s`` (N, 3),
``error_velocity_m_s`` (N,), ``beams_used`` (N,), and with a profile
``water_velocity_m_s`` (N, K, 3) (referenced: ``settings["water_reference"]``) and
``water_relative_velocity_m_s`` (N, K, 3) (not referenced); attributes ``method``,
``source_case`` and the method's own settings (JSON: heading misalignment, declination and
moving bed applied, calibration file and SHA-256, ...). Provenance: the root attributes
``adcpdyn_version`` and ``written_utc``, ``/corrected`` attributes ``source_case_name`` and
``source_case_sha256``.
"""

from __future__ import annotations

import json

from dataclasses import dataclass, field

import h5py
import numpy as np

from .atomic import atomic_path


@dataclass(frozen=True)
class Correction:
    """Per-ping velocities from one correction method (what ``/corrected`` holds).

    vessel_velocity_m_s (N, 3) Earth frame; water_velocity_m_s (N, K, 3) or None, referenced
    to the bottom track or the GNSS (``attrs["water_reference"]``);
    water_relative_velocity_m_s (N, K, 3) or None, the water relative to the transducer (not
    referenced); error_velocity_m_s (N,) (NaN where fewer than four beams); beams_used (N,) int.
    """

    method: str
    time_s: np.ndarray
    vessel_velocity_m_s: np.ndarray
    error_velocity_m_s: np.ndarray
    beams_used: np.ndarray
    water_velocity_m_s: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)
    water_relative_velocity_m_s: np.ndarray | None = None


def write_correction(correction, path, source_case: str = "") -> None:
    """Write a :class:`Correction` to ``path`` atomically."""
    import datetime as dt
    from pathlib import Path

    from .hashing import sha256_of
    from .hashing import adcpdyn_version

    sha = correction.attrs.get("source_case_sha256") or (
        sha256_of(source_case) if source_case and Path(source_case).is_file() else "not available (no case file)")
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = "adcp-corrected"
            f.attrs["version"] = 1
            f.attrs["adcpdyn_version"] = adcpdyn_version()
            f.attrs["written_utc"] = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
            g = f.create_group("corrected")
            g.attrs["method"] = correction.method
            g.attrs["source_case"] = str(source_case)
            g.attrs["source_case_name"] = str(correction.attrs.get("source_case_name") or "")
            g.attrs["source_case_sha256"] = str(sha)
            g.attrs["settings"] = json.dumps(correction.attrs)
            g.create_dataset("time_s", data=np.asarray(correction.time_s, dtype=float))
            g.create_dataset("vessel_velocity_m_s", data=np.asarray(correction.vessel_velocity_m_s, dtype=float))
            g.create_dataset("error_velocity_m_s", data=np.asarray(correction.error_velocity_m_s, dtype=float))
            g.create_dataset("beams_used", data=np.asarray(correction.beams_used, dtype=np.int8))
            if correction.water_velocity_m_s is not None:
                g.create_dataset("water_velocity_m_s", data=np.asarray(correction.water_velocity_m_s, dtype=float))
            if getattr(correction, "water_relative_velocity_m_s", None) is not None:
                g.create_dataset("water_relative_velocity_m_s",
                                 data=np.asarray(correction.water_relative_velocity_m_s, dtype=float))


def read_correction(path) -> dict:
    """The ``/corrected`` group of a file as a dict of arrays plus ``method``."""
    with h5py.File(path, "r") as f:
        if "corrected" not in f:
            raise ValueError(f"{path}: /corrected: group missing; expected the output of `adcpdyn correct`")
        g = f["corrected"]
        out = {k: g[k][()] for k in g}
        out["method"] = g.attrs["method"]
        out["settings"] = json.loads(g.attrs.get("settings", "{}"))
    return out
