"""Shared by the smartphone-app importers (Sensor Logger, phyphox): one IMU table from sensors on separate clocks,
and the GNSS table with its geo origin."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.io.importers._common import imu_frame, increasing_mask, interp_columns, require_finite, steady_clock
from pdr.io.recording import ACC_G_MEDIAN_RANGE, ACC_MPS2_MEDIAN_RANGE
from pdr.constants import GRAVITY_MPS2

Series = tuple[np.ndarray, np.ndarray]  # (t_s increasing, values (N, k))
MIN_OVERLAP_S = 0.5


def clean_series(t: np.ndarray, values: np.ndarray, what: str) -> Series:
    """Finite values required (an empty cell means a damaged or truncated file), then strictly increasing time:
    repeated or back-stepping samples are dropped with a warning."""
    values = np.asarray(values, float).reshape(len(t), -1)
    require_finite(np.column_stack([t, values]), what, "time and values")
    keep = increasing_mask(t, what)
    return t[keep], values[keep]


def require_gravity(acc_mps2: np.ndarray, what: str, hint: str = "") -> None:
    """Refuse, naming the user's file, acceleration without gravity (median |a| near 2 m/s² instead of 9.8: the
    phone's "linear acceleration") and acceleration in g labelled m/s²."""
    med = float(np.median(np.linalg.norm(acc_mps2, axis=1))) if len(acc_mps2) else float("nan")
    if ACC_G_MEDIAN_RANGE[0] <= med <= ACC_G_MEDIAN_RANGE[1]:
        raise InputError(f"{what}: expected acceleration in m/s² (median |a| near {GRAVITY_MPS2}), found median |a| = "
                         f"{med:.3f}: the data look like g")
    if med < ACC_MPS2_MEDIAN_RANGE[0]:
        raise InputError(f"{what}: expected acceleration including gravity (median |a| near {GRAVITY_MPS2} m/s²), found "
                         f"median |a| = {med:.2f} m/s²: linear acceleration (gravity removed){hint}")


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


def gnss_table(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, alt: np.ndarray | None, h_acc: np.ndarray | None,
               what: str) -> tuple[pd.DataFrame, dict[str, Any] | None]:
    """``gnss.csv`` rows (invalid fixes kept as NaN positions) and the ``[geo]`` origin = the first valid fix."""
    ok = np.isfinite(t)
    t, lat, lon = t[ok], lat[ok].astype(float), lon[ok].astype(float)
    alt = alt[ok] if alt is not None else None
    h_acc = h_acc[ok] if h_acc is not None else None
    invalid = ~np.isfinite(lat) | ~np.isfinite(lon) | ((lat == 0.0) & (lon == 0.0)) | (np.abs(lat) > 90) | (np.abs(lon) > 180)
    if invalid.any():
        warnings.warn(f"{what}: {int(invalid.sum())} fix(es) without a valid position kept as NaN", stacklevel=3)
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
