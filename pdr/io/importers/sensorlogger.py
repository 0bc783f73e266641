"""Sensor Logger (the app by Kelvin Choi, tszheichoi.com/sensorlogger): the zipped-CSV export, as a folder or a .zip.

Format (documented in the app's "awesome-sensor-logger" repository, UNITS.md and CROSSPLATFORM.md): one CSV per sensor,
each with ``time`` (UTC epoch, ns) and ``seconds_elapsed`` (s since the start tap), then the values by name.

- ``Accelerometer.csv`` ``x, y, z``: m/s², gravity **removed** (user acceleration) on both platforms;
  ``Gravity.csv`` ``x, y, z``: m/s²; ``TotalAcceleration.csv`` (Android only): m/s² with gravity.
  The specific force of CONTRACT.md is ``TotalAcceleration`` when present, else ``Accelerometer + Gravity``
  (gravity interpolated onto the accelerometer's clock). ``Accelerometer.csv`` alone is refused: gravity is missing.
- iOS reports acceleration and gravity with the opposite sign of Android (Android's right-handed convention, +z up
  when the phone lies flat) unless "Standardise Units & Frames" was on. When ``Metadata.csv`` says
  ``platform = iOS`` and no column named like ``standardise...`` is true, both are negated.
- ``Gyroscope.csv`` rad/s; ``Magnetometer.csv`` µT; ``Barometer.csv`` ``pressure`` in mbar = hPa.
- ``Location.csv`` ``latitude, longitude`` (deg), ``altitude`` (m, WGS84 ellipsoid), ``horizontalAccuracy`` (m, about
  1 sigma; <= 0 = unknown) -> ``gnss.csv`` (``h_acc_m``), and ``[geo]`` origin = the first valid fix.

Clock: ``t_s = (time - time of the first accelerometer sample) / 1e9``; ``start_unix_s`` is that first time stamp.
The accelerometer's clock is the table's clock (other sensors interpolated onto it; see ``_phone.combine_imu``).
Recording name: the export folder's (or zip's) name. Placement ``unknown`` (the export does not say).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.io.importers._common import (
    find_export_root, interp_columns, numeric_array, read_table, safe_id, source_folder, write_recordings,
)
from pdr.io.importers._phone import Series, clean_series, combine_imu, gnss_table
from pdr.io.recording import Recording

NS_PER_S = 1e9
SENSOR_FILES = ("Accelerometer.csv", "TotalAcceleration.csv", "Gravity.csv", "Gyroscope.csv", "Magnetometer.csv",
                "Barometer.csv", "Location.csv")


def _read(folder: Path, name: str, columns: tuple[str, ...], optional: tuple[str, ...] = ()):
    """``(time_ns, values, {optional column: values or None})`` of one sensor file, or None when it is absent.

    ``time_ns`` stays int64 when the file has integer time stamps (ns since 1970 exceed float64's exact range)."""
    path = folder / name
    if not path.is_file():
        return None
    df = read_table(path, name)
    df.columns = [str(c).strip() for c in df.columns]
    missing = [c for c in ("time", *columns) if c not in df.columns]
    if missing:
        raise InputError(f"{name}: expected columns time, {', '.join(columns)}, found {', '.join(df.columns)}")
    if pd.api.types.is_integer_dtype(df["time"]):
        t_ns = df["time"].to_numpy(dtype=np.int64)
    else:
        t_ns = numeric_array(df[["time"]], name)[:, 0]
    extra = {c: numeric_array(df[[c]], name)[:, 0] if c in df.columns else None for c in optional}
    return t_ns, numeric_array(df[list(columns)], name), extra


def _seconds(t_ns: np.ndarray, t0_ns: int | float) -> np.ndarray:
    if t_ns.dtype.kind == "i" and isinstance(t0_ns, (int, np.integer)):
        return (t_ns - t0_ns).astype(float) / NS_PER_S
    return (t_ns.astype(float) - float(t0_ns)) / NS_PER_S


def _ios_sign(folder: Path) -> float:
    path = folder / "Metadata.csv"
    if not path.is_file():
        return 1.0
    meta = read_table(path, "Metadata.csv")
    meta.columns = [str(c).strip().lower() for c in meta.columns]
    platform = str(meta["platform"].iloc[0]).strip().lower() if "platform" in meta.columns else ""
    standardised = any(str(meta[c].iloc[0]).strip().lower() in ("true", "1", "yes")
                       for c in meta.columns if "standardis" in c or "standardiz" in c)
    return -1.0 if platform == "ios" and not standardised else 1.0


def _specific_force(folder: Path, what: str) -> tuple[Any, np.ndarray, np.ndarray]:
    """``(t0_ns, t_s, f)``: specific force including gravity (m/s², app's sign convention) and its clock."""
    total = _read(folder, "TotalAcceleration.csv", ("x", "y", "z"))
    if total is not None:
        t0 = total[0][0]
        return (t0, *clean_series(_seconds(total[0], t0), total[1], "TotalAcceleration.csv"))
    acc = _read(folder, "Accelerometer.csv", ("x", "y", "z"))
    grav = _read(folder, "Gravity.csv", ("x", "y", "z"))
    if acc is None:
        raise InputError(f"{what}: expected a Sensor Logger export with Accelerometer.csv (or TotalAcceleration.csv), found "
                         f"{', '.join(sorted(p.name for p in folder.iterdir())[:8]) or 'an empty folder'}")
    if grav is None:
        raise InputError(f"{what}: expected Gravity.csv (or TotalAcceleration.csv) beside Accelerometer.csv, which has "
                         "gravity removed; found neither: enable the Gravity sensor in the app")
    t0 = acc[0][0]
    t_a, a = clean_series(_seconds(acc[0], t0), acc[1], "Accelerometer.csv")
    t_g, g = clean_series(_seconds(grav[0], t0), grav[1], "Gravity.csv")
    if len(t_g) < 2:
        raise InputError(f"Gravity.csv: expected at least 2 samples, found {len(t_g)}")
    sel = (t_a >= t_g[0]) & (t_a <= t_g[-1])
    return t0, t_a[sel], a[sel] + interp_columns(t_a[sel], t_g, g)


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    what = src.name
    with source_folder(src, f"sensorlogger {what}") as folder:
        folder = find_export_root(folder, SENSOR_FILES)
        t0, t_acc, f = _specific_force(folder, what)
        sign = _ios_sign(folder)
        if sign < 0:
            warnings.warn(f"{what}: iOS export without standardised frames; acceleration negated to Android's "
                          "convention (+z up when the phone lies flat)", stacklevel=2)

        def series(name: str, cols: tuple[str, ...]) -> Series | None:
            raw = _read(folder, name, cols)
            return None if raw is None else clean_series(_seconds(raw[0], t0), raw[1], name)

        imu = combine_imu((t_acc, sign * f), series("Gyroscope.csv", ("x", "y", "z")),
                          series("Magnetometer.csv", ("x", "y", "z")), series("Barometer.csv", ("pressure",)), what)
        meta: dict[str, Any] = {"recording": {"id": safe_id(src.stem if src.is_file() else src.name), "placement": "unknown",
                                              "source": "sensorlogger", "start_unix_s": float(t0) / NS_PER_S}}
        gnss = None
        loc = _read(folder, "Location.csv", ("latitude", "longitude"), ("altitude", "horizontalAccuracy"))
        if loc is not None:
            t_ns, ll, extra = loc
            gnss, geo = gnss_table(_seconds(t_ns, t0), ll[:, 0], ll[:, 1], extra["altitude"], extra["horizontalAccuracy"],
                                   "Location.csv")
            if geo is None:
                warnings.warn("Location.csv: no valid fix; gnss.csv not written", stacklevel=2)
                gnss = None
            else:
                meta["geo"] = geo
        return write_recordings([Recording(meta=meta, imu=imu, gnss=gnss)], dest, force=force)
