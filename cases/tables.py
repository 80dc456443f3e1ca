"""The scenario TOML's tables into dataclasses: degrees to radians, unknown keys refused in one
line, tables merged (a run over its file's defaults). Shared by scenarios and surveys."""

from __future__ import annotations

import copy
from dataclasses import fields

import numpy as np


def angles_in_radians(d: dict, owner: str) -> dict:
    """Turn ``*_deg`` keys into ``*_rad`` (values or lists)."""
    out = {}
    for k, v in d.items():
        if k.endswith("_deg"):
            out[k[:-4] + "_rad"] = np.deg2rad(np.asarray(v, dtype=float)).tolist()
        else:
            out[k] = v
    return out


def build(cls, d: dict, owner: str, **extra):
    d = dict(d)
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"{owner}: unknown key(s) {unknown}; expected some of {sorted(known)}")
    for k, v in d.items():
        if isinstance(v, list):
            d[k] = tuple(tuple(x) if isinstance(x, list) else x for x in v)
    return cls(**d, **extra)


def deep_merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out
