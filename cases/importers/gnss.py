"""GNSS reference velocity from the NMEA an ADCP file carries, and the ADCP-to-GNSS clock offset.

Positions are float64. Two sources, in order of preference:

- ``nmea-text``: GGA/VTG sentences written as text in the file (checksums verified);
- ``winriver2-binary``: WinRiver II's binary GGA/VTG records, as decoded by dolfyn
  (latitude and longitude kept as float64, see :mod:`.reader`).

Velocity over ground comes from VTG when present, else from differenced GGA positions
(local tangent plane, WGS84 radii). The clock offset (GNSS UTC minus ADCP clock) is
taken coarsely from the reader's GNSS time stamps, then refined by cross-correlating
bottom-track speed with GNSS speed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ...models.geodesy import local_north_east_m
from ...models.rotations import course_difference_rad

KNOT_M_S = 1852.0 / 3600.0
DOLFYN_KNOT_DIVISOR = 1.944  # dolfyn stores VTG speed as knots / 1.944
MIN_FIXES = 5
LAG_HALF_WIDTH_S, LAG_STEP_S = 5.0, 0.01
MIN_CORRELATION = 0.5

_GGA = re.compile(rb"\$?(?:GP|GN|GL|GA|II)?GGA,([0-9.]*),([0-9.]*),([NS]?),([0-9.]*),([EW]?),([0-9]*),[^*\r\n$]*(?:\*([0-9A-Fa-f]{2}))?")
_VTG = re.compile(rb"\$?(?:GP|GN|GL|GA|II)?VTG,([0-9.]*),T?,[0-9.]*,M?,[0-9.]*,N?,([0-9.]*),K?[^*\r\n$]*(?:\*([0-9A-Fa-f]{2}))?")


@dataclass(frozen=True)
class GnssTrack:
    """GNSS samples on the GNSS clock (UTC, seconds since the Unix epoch)."""

    time_utc_s: np.ndarray  # (L,) time of each velocity sample
    velocity_ned_m_s: np.ndarray  # (L, 3); vertical is NaN (not measured)
    window_s: np.ndarray  # (L, 2) interval a velocity averages over (equal ends: instantaneous)
    source: str
    velocity_from: str
    n_fixes: int
    fix_time_utc_s: np.ndarray | None = None  # (P,) times of the GGA fixes, strictly increasing
    latitude_deg: np.ndarray | None = None  # (P,) float64
    longitude_deg: np.ndarray | None = None  # (P,) float64


def _checksum_ok(match) -> bool:
    """Verify the NMEA checksum when the sentence carries one (WinRiver 1 stores none)."""
    given = match.group(match.re.groups)
    body = match.group(0)
    if given is None or not body.startswith(b"$"):
        return True
    cs = 0
    for ch in body[1:body.rfind(b"*")]:
        cs ^= ch
    return f"{cs:02X}" == given.decode().upper()


def _degrees(value: bytes, hemi: bytes) -> float:
    v = float(value)
    deg = np.floor(v / 100.0)
    out = deg + (v - 100.0 * deg) / 60.0
    return -out if hemi in (b"S", b"W") else out


def text_fixes(raw: bytes):
    """Text GGA fixes (seconds of day, lat, lon) and the VTG after each, from file bytes."""
    events = []
    for m in _GGA.finditer(raw):
        if m.group(1) and m.group(2) and m.group(6) and int(m.group(6)) > 0 and _checksum_ok(m):
            hh, mm, ss = float(m.group(1)[:2]), float(m.group(1)[2:4]), float(m.group(1)[4:])
            events.append((m.start(), "gga", (3600 * hh + 60 * mm + ss, _degrees(m.group(2), m.group(3)),
                                              _degrees(m.group(4), m.group(5)))))
    for m in _VTG.finditer(raw):
        if m.group(1) and m.group(2) and _checksum_ok(m):
            events.append((m.start(), "vtg", (float(m.group(1)), float(m.group(2)) / 3.6)))
    events.sort(key=lambda e: e[0])
    fixes, vtg, last = [], {}, None
    for _, kind, val in events:
        if kind == "gga":
            fixes.append(val)
            last = len(fixes) - 1
        elif last is not None:
            vtg[last] = val
    return fixes, vtg


def _local_ne(lat_deg, lon_deg):
    return local_north_east_m(lat_deg, lon_deg, np.nanmean(lat_deg), np.nanmean(lon_deg))


def _unique_increasing(t, *arrays):
    keep = np.concatenate([[True], np.diff(t) > 0]) & np.isfinite(t)
    while np.any(np.diff(t[keep]) <= 0):
        tk = np.maximum.accumulate(np.where(keep, t, -np.inf))
        keep &= np.concatenate([[True], t[1:] > tk[:-1]])
    return (t[keep],) + tuple(a[keep] for a in arrays)


def _track(t, lat, lon, course_deg, speed_m_s, source) -> GnssTrack:
    t, lat, lon, course_deg, speed_m_s = _unique_increasing(t, lat, lon, course_deg, speed_m_s)
    if t.size < MIN_FIXES:
        raise ValueError(f"GNSS: expected at least {MIN_FIXES} GGA fixes with a position, got {t.size}")
    vtg_ok = np.isfinite(course_deg) & np.isfinite(speed_m_s)
    if vtg_ok.sum() >= MIN_FIXES:
        c = np.deg2rad(course_deg[vtg_ok])
        v = np.column_stack([speed_m_s[vtg_ok] * np.cos(c), speed_m_s[vtg_ok] * np.sin(c), np.full(c.size, np.nan)])
        tv = t[vtg_ok]
        return GnssTrack(tv, v, np.column_stack([tv, tv]), source, "VTG speed and true course", int(t.size), t, lat, lon)
    n, e = _local_ne(lat, lon)
    dt = np.diff(t)
    v = np.column_stack([np.diff(n) / dt, np.diff(e) / dt, np.full(dt.size, np.nan)])
    return GnssTrack(0.5 * (t[1:] + t[:-1]), v, np.column_stack([t[:-1], t[1:]]), source,
                     "differenced GGA positions (no VTG)", int(t.size), t, lat, lon)


def read_track(raw: bytes, ds, coarse_offset_s: float, t_adcp0_utc_s: float) -> GnssTrack:
    """The file's GNSS track on the UTC clock, float64.

    ``coarse_offset_s`` and ``t_adcp0_utc_s`` (first ping, ADCP clock, epoch seconds)
    place text times of day on the right date.
    """
    fixes, vtg = text_fixes(raw)
    if len(fixes) >= MIN_FIXES:
        sod = np.array([f[0] for f in fixes])
        guess = t_adcp0_utc_s + coarse_offset_s  # the first fix's UTC, roughly
        t0 = np.floor(guess / 86400.0) * 86400.0 + sod[0]
        t0 += 86400.0 * np.round((guess - t0) / 86400.0)
        t = t0 + np.concatenate([[0.0], np.cumsum(np.mod(np.diff(sod) + 43200.0, 86400.0) - 43200.0)])
        course = np.array([vtg[i][0] if i in vtg else np.nan for i in range(len(fixes))])
        speed = np.array([vtg[i][1] if i in vtg else np.nan for i in range(len(fixes))])
        return _track(t, np.array([f[1] for f in fixes]), np.array([f[2] for f in fixes]), course, speed, "nmea-text")
    if "latitude_gps" not in ds or "time_gps" not in ds.coords:
        raise ValueError("GNSS: no GGA sentences in the file")
    t = ds["time_gps"].values.astype("datetime64[ns]").astype(np.int64) / 1e9
    lat = ds["latitude_gps"].values.astype(np.float64)
    lon = ds["longitude_gps"].values.astype(np.float64)
    fix = ds["fix_gps"].values if "fix_gps" in ds else np.ones_like(lat)
    ok = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon) & (fix > 0) & (lat != 0)
    if "speed_over_grnd_gps" in ds:
        speed = ds["speed_over_grnd_gps"].values.astype(np.float64) * DOLFYN_KNOT_DIVISOR * KNOT_M_S
        course = ds["dir_over_grnd_gps"].values.astype(np.float64)
    else:
        speed = course = np.full(lat.shape, np.nan)
    order = np.argsort(t[ok], kind="stable")
    return _track(t[ok][order], lat[ok][order], lon[ok][order], course[ok][order], speed[ok][order], "winriver2-binary")


def coarse_offset(ds) -> float:
    """GNSS UTC minus ADCP clock from the reader's time stamps (median), seconds."""
    if "time_gps" not in ds.coords:
        raise ValueError("GNSS: no GNSS time stamps (time_gps) in the file")
    tg = ds["time_gps"].values.astype("datetime64[ns]").astype(np.int64) / 1e9
    if "hdwtime_gps" in ds:
        ta = ds["hdwtime_gps"].values.astype("datetime64[ns]").astype(np.int64) / 1e9
    elif ds["time_gps"].size == ds["time"].size:
        ta = ds["time"].values.astype("datetime64[ns]").astype(np.int64) / 1e9
    else:
        raise ValueError("GNSS: cannot pair GNSS time stamps with ADCP times")
    d = tg - ta
    d = d[np.isfinite(d) & (np.abs(d) < 2 * 86400)]
    if d.size == 0:
        raise ValueError("GNSS: no GNSS time stamp pairs with an ADCP time")
    return float(np.median(d))


def _window_velocity(t_adcp, v_bt, windows):
    """Bottom-track velocity averaged over each window (ADCP clock), (L, 2) horizontal; NaN where
    the windows leave the bottom track's span, all NaN with fewer than two valid pings (a window of
    a file cut where the bottom track is lost)."""
    if np.size(t_adcp) < 2:
        return np.full((len(windows), 2), np.nan)
    pos = np.column_stack([np.concatenate([[0.0], np.cumsum(0.5 * (v_bt[1:, j] + v_bt[:-1, j]) * np.diff(t_adcp))])
                           for j in range(2)])
    a, b = windows[:, 0], windows[:, 1]
    out = np.empty((a.size, 2))
    span = b - a
    inst = span <= 0
    for j in range(2):
        out[inst, j] = np.interp(a[inst], t_adcp, v_bt[:, j])
        out[~inst, j] = (np.interp(b[~inst], t_adcp, pos[:, j]) - np.interp(a[~inst], t_adcp, pos[:, j])) / span[~inst]
    inside = (a >= t_adcp[0]) & (b <= t_adcp[-1])
    out[~inside] = np.nan
    return out


def refine_offset(track: GnssTrack, t_adcp_s, v_bt_ned, coarse_s: float):
    """Clock offset maximising the correlation of BT speed and GNSS speed.

    Parameters
    ----------
    t_adcp_s : (N,) ping times on the ADCP clock, epoch seconds
    v_bt_ned : (N, 3) bottom-track vessel velocity in the Earth frame (NaN where lost)

    Returns
    -------
    (offset_s, peak_correlation, refined) ; refined is False when the peak is too weak
    and the coarse offset is kept.
    """
    ok = np.all(np.isfinite(v_bt_ned[:, :2]), axis=1)
    if ok.sum() < 10:
        return coarse_s, float("nan"), False
    t, v = t_adcp_s[ok], v_bt_ned[ok, :2]
    g = np.hypot(track.velocity_ned_m_s[:, 0], track.velocity_ned_m_s[:, 1])
    lags = np.arange(coarse_s - LAG_HALF_WIDTH_S, coarse_s + LAG_HALF_WIDTH_S + LAG_STEP_S / 2, LAG_STEP_S)
    corr = np.full(lags.size, np.nan)
    for k, lag in enumerate(lags):
        w = _window_velocity(t, v, track.window_s - lag)
        s = np.hypot(w[:, 0], w[:, 1])
        m = np.isfinite(s) & np.isfinite(g)
        if m.sum() >= 10 and np.std(s[m]) > 0 and np.std(g[m]) > 0:
            corr[k] = np.corrcoef(s[m], g[m])[0, 1]
    if not np.any(np.isfinite(corr)):
        return coarse_s, float("nan"), False
    k = int(np.nanargmax(corr))
    best = float(lags[k])
    if 0 < k < lags.size - 1 and np.all(np.isfinite(corr[k - 1:k + 2])):
        c0, c1, c2 = corr[k - 1:k + 2]
        den = c0 - 2 * c1 + c2
        if den < 0:
            best += 0.5 * LAG_STEP_S * (c0 - c2) / den
    peak = float(corr[k])
    if peak < MIN_CORRELATION:
        return coarse_s, peak, False
    return best, peak, True


def compare(track: GnssTrack, offset_s: float, t_adcp_s, v_bt_ned, min_speed_m_s: float = 0.2) -> dict:
    """BT against GNSS after the clock offset: speed ratio and course offset (GNSS minus BT)."""
    ok = np.all(np.isfinite(v_bt_ned[:, :2]), axis=1)
    w = _window_velocity(t_adcp_s[ok], v_bt_ned[ok, :2], track.window_s - offset_s)
    g = track.velocity_ned_m_s[:, :2]
    m = np.all(np.isfinite(w), axis=1) & (np.hypot(g[:, 0], g[:, 1]) > min_speed_m_s)
    if m.sum() < 3:
        return {"n": int(m.sum())}
    sb, sg = np.hypot(w[m, 0], w[m, 1]), np.hypot(g[m, 0], g[m, 1])
    d = course_difference_rad(g[m], w[m])
    z = np.mean(np.exp(1j * d))
    sd = np.sqrt(-2 * np.log(min(abs(z), 1.0)))
    return {"n": int(m.sum()), "speed_ratio_bt_over_gnss": float(np.sum(sb) / np.sum(sg)),
            "course_offset_gnss_minus_bt_deg": float(np.rad2deg(np.angle(z))),
            "course_offset_se_deg": float(np.rad2deg(sd) / np.sqrt(m.sum())),
            "course_offset_sd_deg": float(np.rad2deg(sd)), "min_gnss_speed_m_s": min_speed_m_s}
