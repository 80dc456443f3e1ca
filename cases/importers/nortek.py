"""Nortek AD2CP (Signature) -> case, through dolfyn.

A case needs per-beam bottom-track radial velocities. Signature bottom-track records
are not imported: their beam order and sign conventions are not verified against a
file here, so a file with or without them gets a one-line refusal naming the reason.
"""

from __future__ import annotations

from .reader import ImportFailure, read_dolfyn


def import_nortek(path, window) -> tuple:
    """Refuse with a clear one-line message (see module docstring)."""
    ds, version = read_dolfyn(path)
    bt = [k for k in ds.data_vars if "bt" in k.lower()]
    if not bt:
        raise ImportFailure(f"{path}: bottom track: none in this file ({version} found no Nortek bottom-track record; "
                            "only water profiles, AHRS and altimeter data); a case needs per-beam bottom-track "
                            "radial velocities (/pings/bt_radial_m_s)")
    raise ImportFailure(f"{path}: bottom track ({', '.join(bt)}): Nortek AD2CP bottom-track beam order and sign "
                        "conventions are not verified against a file, so they are not imported")
