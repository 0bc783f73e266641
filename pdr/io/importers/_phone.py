"""Shared by the smartphone-app importers (Sensor Logger, phyphox): one IMU table from sensors on separate clocks,
the GNSS table with its geo origin, and the checks that name the user's file (the app that wrote it, gravity
present, GNSS on the same clock)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.io.importers._common import imu_frame, increasing_mask, interp_columns, require_finite, steady_clock
from pdr.io.recording import ACC_G_MEDIAN_RANGE, ACC_MPS2_MEDIAN_RANGE

Series = tuple[np.ndarray, np.ndarray]  # (t_s increasing, values (N, k))
MIN_OVERLAP_S = 0.5
MIN_STEADY_FRACTION = 0.7  # gravity dominates a 1 s mean (walking moves the phone's tilt by tens of degrees at most)
MAX_GNSS_OUTSIDE_S = 60.0  # a first fix may come a while after the start tap; hours away is another clock
APPS = {"sensorlogger": "Sensor Logger", "phyphox": "phyphox"}


def csv_app(path: Path) -> str | None:
    """The app whose header a CSV file carries: ``sensorlogger`` (a ``seconds_elapsed`` column; ``Metadata.csv``'s
    ``version, device name, ...``), ``phyphox`` (a first column ``Time (s)``, or ``"time"`` quoted as phyphox quotes
    its headers, in custom experiments), else None."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            line = f.readline(4096)
    except OSError:
        return None
    raw = [c.strip().lower() for c in re.split(r"[,;\t]", line)]
    cells = [c.strip('"').strip() for c in raw]
    if "seconds_elapsed" in cells or cells[:2] == ["version", "device name"]:
        return "sensorlogger"
    if cells[0] == "time (s)" or raw[0] == '"time"':
        return "phyphox"
    return None


def require_app(folder: Path, app: str, what: str) -> None:
    """Refuse an export folder whose CSV files another app wrote, or that mixes both apps' files (two exports)."""
    by_app = {a: sorted(p.name for p in folder.glob("*.csv") if p.is_file() and csv_app(p) == a) for a in APPS}
    other = next(a for a in APPS if a != app)
    if not by_app[other]:
        return
    theirs = ", ".join(by_app[other][:3])
    if by_app[app]:
        raise InputError(f"{what}: expected one export per folder, found {APPS[app]} files ({', '.join(by_app[app][:3])}) "
                         f"mixed with {APPS[other]} files ({theirs})")
    raise InputError(f"{what}: expected a {APPS[app]} export, found a {APPS[other]} export ({theirs}): import it with "
                     f"pdr import {other}")


def clean_series(t: np.ndarray, values: np.ndarray, what: str) -> Series:
    """Finite values required (an empty cell means a damaged or truncated file), then strictly increasing time:
    repeated or back-stepping samples are dropped with a warning."""
    values = np.asarray(values, float)
    values = values.reshape(len(t), values.shape[1] if values.ndim == 2 else -1)
    require_finite(np.column_stack([t, values]), what, "time and values")
    keep = increasing_mask(t, what)
    return t[keep], values[keep]


def steady_fraction(t_s: np.ndarray, acc: np.ndarray, window_s: float = 1.0) -> float:
    """Median over ``window_s`` windows of |mean vector| / mean |a|: near 1 when a steady vector (gravity) dominates,
    near 0 for acceleration without gravity (the body's accelerations average out over a step or two)."""
    if len(t_s) < 2:
        return 1.0
    edges = np.arange(t_s[0], t_s[-1] + window_s, window_s)
    idx = np.searchsorted(t_s, edges)
    norm = np.linalg.norm(acc, axis=1)
    ratios = [np.linalg.norm(acc[a:b].mean(axis=0)) / norm[a:b].mean() for a, b in zip(idx[:-1], idx[1:])
              if b - a >= 3 and norm[a:b].mean() > 0]
    return float(np.median(ratios)) if ratios else 1.0


def require_gravity(t_s: np.ndarray, acc_mps2: np.ndarray, what: str, hint: str = "") -> None:
    """Refuse, naming the user's file, acceleration without gravity (median |a| near 2 m/s² instead of 9.8: the
    phone's "linear acceleration") and acceleration in g labelled m/s². Data in g and linear acceleration both have
    median |a| near 1 m/s² at times; gravity is the steady part (``steady_fraction`` >= ``MIN_STEADY_FRACTION``)."""
    med = float(np.median(np.linalg.norm(acc_mps2, axis=1))) if len(acc_mps2) else float("nan")
    if med < ACC_MPS2_MEDIAN_RANGE[0] and steady_fraction(t_s, acc_mps2) < MIN_STEADY_FRACTION:
        raise InputError(f"{what}: expected acceleration including gravity (median |a| near {GRAVITY_MPS2} m/s²), found "
                         f"median |a| = {med:.2f} m/s² with no steady gravity: linear acceleration (gravity removed){hint}")
    if ACC_G_MEDIAN_RANGE[0] <= med <= ACC_G_MEDIAN_RANGE[1]:
        raise InputError(f"{what}: expected acceleration in m/s² (median |a| near {GRAVITY_MPS2}), found median |a| = "
                         f"{med:.3f}: the data look like g")


def combine_imu(acc: Series, gyr: Series | None, mag: Series | None, baro: Series | None, what: str) -> pd.DataFrame:
    """The accelerometer's clock (resampled to a uniform grid only if it jitters wildly) is the table's clock; the
    other sensors are interpolated linearly onto it. The table covers the time where the accelerometer, gyroscope
    and magnetometer all have data; the slow barometer is held at its first/last value beyond its own span."""
    t, a = acc
    if len(t) < 2:
        raise InputError(f"{what}: expected at least 2 accelerometer samples, found {len(t)}")
    t, a = steady_clock(t, a, f"{what} accelerometer")
    lo, hi = t[0], t[-1]
    for name, s in (("gyroscope", gyr), ("magnetometer", mag)):
        if s is not None:
            if len(s[0]) < 2:
                raise InputError(f"{what}: expected at least 2 {name} samples, found {len(s[0])}")
            lo, hi = max(lo, s[0][0]), min(hi, s[0][-1])
    if hi - lo < MIN_OVERLAP_S:
        raise InputError(f"{what}: expected the accelerometer and the other motion sensors to overlap for at least "
                         f"{MIN_OVERLAP_S} s, found {max(hi - lo, 0.0):.3f} s")
    sel = (t >= lo) & (t <= hi)
    t, a = t[sel], a[sel]
    g = interp_columns(t, *gyr) if gyr is not None else None
    m = interp_columns(t, *mag) if mag is not None else None
    p = None
    if baro is not None and len(baro[0]) >= 1:
        p = np.interp(t, baro[0], baro[1][:, 0])
    return imu_frame(t, a, g, m, p)


def require_overlap(gnss_t_s: np.ndarray, imu_t_s: np.ndarray, what: str) -> None:
    """Fixes none of which falls within the motion recording (give or take ``MAX_GNSS_OUTSIDE_S``) are on another
    clock: refused rather than kept unused."""
    if len(gnss_t_s) and len(imu_t_s):
        near = (gnss_t_s >= imu_t_s[0] - MAX_GNSS_OUTSIDE_S) & (gnss_t_s <= imu_t_s[-1] + MAX_GNSS_OUTSIDE_S)
        if not near.any():
            gap = min(abs(gnss_t_s[0] - imu_t_s[-1]), abs(imu_t_s[0] - gnss_t_s[-1]))
            raise InputError(f"{what}: expected fixes during the motion recording ({imu_t_s[0]:.1f} to {imu_t_s[-1]:.1f} s), "
                             f"found all of them {gap:.1f} s away (a clock on another origin, or two exports mixed)")


def gnss_table(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, alt: np.ndarray | None, h_acc: np.ndarray | None,
               what: str) -> tuple[pd.DataFrame, dict[str, Any] | None]:
    """``gnss.csv`` rows (invalid fixes kept as NaN positions) and the ``[geo]`` origin = the first valid fix."""
    ok = np.isfinite(t)
    t, lat, lon = t[ok], lat[ok].astype(float), lon[ok].astype(float)
    alt = alt[ok] if alt is not None else None
    h_acc = h_acc[ok] if h_acc is not None else None
    invalid = ~np.isfinite(lat) | ~np.isfinite(lon) | ((lat == 0.0) & (lon == 0.0)) | (np.abs(lat) > 90) | (np.abs(lon) > 180)
    if invalid.any():
        warn(f"{what}: {int(invalid.sum())} fix(es) without a valid position kept as NaN")
        lat[invalid] = lon[invalid] = np.nan
    cols: dict[str, np.ndarray] = {"t_s": t, "lat_deg": lat, "lon_deg": lon}
    if alt is not None:
        cols["alt_m"] = np.where(invalid, np.nan, alt)
    if h_acc is not None:
        cols["h_acc_m"] = np.where(h_acc > 0, h_acc, np.nan)  # apps report <= 0 for "unknown"
    keep = increasing_mask(t, what)
    df = pd.DataFrame(cols)[keep].reset_index(drop=True)
    valid = df["lat_deg"].notna().to_numpy()
    geo = None
    if valid.any():
        first = int(np.flatnonzero(valid)[0])
        geo = {"origin_lat_deg": float(df["lat_deg"].iloc[first]), "origin_lon_deg": float(df["lon_deg"].iloc[first])}
    return df, geo
