"""Import real instrument files into cases: TRDI PD0 and Nortek AD2CP, through dolfyn.

``import_file`` picks the reader by extension, else by the file's first bytes, and
returns the case with the audit attributes of every conversion; ``write_imported``
writes both atomically (``/provenance`` plus attributes on the case's groups).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from .reader import ImportFailure
from .window import Window

__all__ = ["ImportFailure", "Window", "detect_vendor", "import_dataset", "import_file", "resalted", "write_imported"]

TRDI_SUFFIXES = (".pd0", ".000", ".ens", ".enr", ".enx", ".sta", ".lta")
NORTEK_SUFFIXES = (".ad2cp",)
TRDI_MAGIC, NORTEK_MAGIC = b"\x7f\x7f", b"\xa5"


def detect_vendor(path) -> str:
    """``trdi`` or ``nortek`` from the extension (a numbered .NNN is TRDI), else from the first bytes."""
    path = Path(path)
    if not path.is_file():
        raise ImportFailure(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix in TRDI_SUFFIXES or (len(suffix) == 4 and suffix[1:].isdigit()):
        return "trdi"
    if suffix in NORTEK_SUFFIXES:
        return "nortek"
    with open(path, "rb") as fh:
        head = fh.read(2)
    if head == TRDI_MAGIC:
        return "trdi"
    if head[:1] == NORTEK_MAGIC:
        return "nortek"
    raise ImportFailure(f"{path}: file type: expected a TRDI PD0 ({', '.join(TRDI_SUFFIXES)}; first bytes 7f7f) or a "
                        f"Nortek AD2CP (.ad2cp; first byte a5), got extension {suffix or '(none)'!r} and first bytes "
                        f"{head.hex() or '(empty)'}")


def import_file(path, window: Window | None = None):
    """Read one instrument file into ``(case, attrs)``; attrs maps HDF5 group -> audit attributes.

    Raises
    ------
    ImportFailure
        A one-line message naming what the file lacks or why it cannot be read.
    """
    from .nortek import import_nortek
    from .reader import quiet_reader
    from .trdi import import_trdi

    path = Path(path)
    window = window or Window()
    vendor = detect_vendor(path)
    with quiet_reader() as chatter:
        case, attrs = (import_trdi if vendor == "trdi" else import_nortek)(path, window)
    if chatter.messages:
        attrs.setdefault("/provenance", {})["reader_messages"] = chatter.summary()
    return case, attrs


def resalted(case, attrs: dict, salinity_psu: float) -> tuple:
    """``(case, attrs)`` with the water's salinity in place of the instrument's setting
    (:func:`~adcpdyn.cases.sound_speed.with_salinity`), the change in ``/provenance``."""
    from ..sound_speed import with_salinity

    new, note = with_salinity(case, salinity_psu)
    prov = {**attrs["/provenance"], "sound_speed_changed": note}
    if "bt_vs_gnss_speed_ratio_bt_over_gnss" in prov:  # the bottom track's speeds scale with the sound speed
        prov["bt_vs_gnss_speed_ratio_bt_over_gnss"] *= new.instrument.sound_speed_m_s / case.instrument.sound_speed_m_s
    return new, {**attrs, "/provenance": prov}


def import_dataset(ds, window: Window | None = None, name: str | None = None):
    """A dolfyn :class:`xarray.Dataset` of a TRDI file (``mhkit.dolfyn.read``) into ``(case, attrs)``.

    Parameters
    ----------
    ds : xarray.Dataset
        What dolfyn read from a TRDI PD0 file (Nortek datasets are refused, as their files are).
    window : Window, optional
    name : str, optional
        The case's name (default ``dataset``).

    Raises
    ------
    ImportFailure
        Not a dolfyn TRDI dataset, or what it lacks (one line).
    """
    from .reader import quiet_reader
    from .trdi import import_trdi_dataset

    if not (hasattr(ds, "attrs") and hasattr(ds, "data_vars")):
        raise ImportFailure(f"source: expected an instrument file path or a dolfyn xarray.Dataset, got {type(ds).__name__}")
    make = str(ds.attrs.get("inst_make", "")).upper()
    if make and make not in ("TRDI", "RDI"):
        raise ImportFailure(f"source: inst_make: expected a TRDI dataset (Nortek bottom track is not imported, see "
                            f"`adcpdyn import`), got {ds.attrs.get('inst_make')!r}")
    with quiet_reader() as chatter:
        case, attrs = import_trdi_dataset(ds, window or Window(), str(name or "dataset"))
    if chatter.messages:
        attrs.setdefault("/provenance", {})["reader_messages"] = chatter.summary()
    return case, attrs


def _attr_value(v):
    if isinstance(v, (dict, list, tuple)):
        return json.dumps(v)
    if isinstance(v, bool):
        return np.int64(v)
    if isinstance(v, float):
        return np.float64(v)
    return v


def write_imported(case, attrs: dict, out, source=None) -> None:
    """Write the case and its audit attributes atomically; never over the source file."""
    from ..atomic import atomic_path, refuse_overwrite_input
    from ..io import write_case
    from ..validation import validate_case

    refuse_overwrite_input(out, source)
    # checked under the names the user gave (the temporary file's is nobody's)
    validate_case(case, source=f"{os.fspath(out)} (from {Path(source).name})" if source is not None else os.fspath(out))
    with atomic_path(out) as tmp:
        write_case(case, tmp)
        with h5py.File(tmp, "a") as f:
            for group, values in attrs.items():
                g = f.require_group(group)
                for k, v in values.items():
                    g.attrs[k] = _attr_value(v)
