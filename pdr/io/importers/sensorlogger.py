"""Sensor Logger (the app by Kelvin Choi, tszheichoi.com/sensorlogger): the zipped-CSV export, as a folder or a .zip.

Format (documented in the app's "awesome-sensor-logger" repository, UNITS.md and CROSSPLATFORM.md): one CSV per sensor,
each with ``time`` (UTC epoch, ns) and ``seconds_elapsed`` (s since the start tap), then the values by name.
``Metadata.csv`` (one row, written without a final line break): ``version, device name, recording time, platform``
and, in later versions, ``recording epoch time`` (ms), ``appVersion``, ``standardisation`` and others.

- The specific force of CONTRACT.md, by preference: ``TotalAcceleration.csv`` (Android, m/s² with gravity);
  ``Accelerometer.csv`` (m/s², gravity **removed**) + ``Gravity.csv`` (m/s², interpolated onto the accelerometer's
  clock); ``AccelerometerUncalibrated.csv`` (raw, gravity included: on iOS in g unless "Standardise Units & Frames"
  is on, on Android in m/s²). ``Accelerometer.csv`` alone is refused: gravity is missing.
- iOS reports acceleration and gravity with the opposite sign of Android (Android's right-handed convention, +z up
  when the phone lies flat) unless "Standardise Units & Frames" was on. When ``Metadata.csv`` says
  ``platform = iOS`` and no column named like ``standardise...`` is true, they are negated.
- ``Gyroscope.csv`` rad/s; ``Magnetometer.csv`` µT; ``Barometer.csv`` ``pressure`` in mbar = hPa.
- ``Location.csv`` ``latitude, longitude`` (deg), ``altitude`` (m, WGS84 ellipsoid), ``horizontalAccuracy`` (m, about
  1 sigma; <= 0 = unknown) -> ``gnss.csv`` (``h_acc_m``), and ``[geo]`` origin = the first valid fix.
- An optional sensor's file may be empty (0 bytes; ``Location.csv`` when the phone got no fix): taken as absent.

Clock: ``t_s = (time - time of the first accelerometer sample) / 1e9``; ``start_unix_s`` is that first time stamp.
Every file's ``time - seconds_elapsed`` is the epoch of the start tap; older iOS versions write the motion sensors'
``time`` on another origin than the location's (hours apart). A file whose start epoch differs from the
accelerometer's by more than ``CLOCK_AGREEMENT_S`` is put on the accelerometer's clock through its
``seconds_elapsed`` (the same start tap for all files), with a warning; the absolute time kept is the one that agrees
with ``Metadata.csv``'s ``recording epoch time`` (else the location's: satellite time).
The accelerometer's clock is the table's clock (other sensors interpolated onto it; see ``_phone.combine_imu``).
Recording name: the export folder's (or zip's) name. Placement ``unknown`` (the export does not say).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.io.importers._common import (
    find_export_root, interp_columns, numeric_array, read_table, safe_id, source_folder, write_recordings,
)
from pdr.io.importers._phone import (
    Series, clean_series, combine_imu, gnss_table, require_app, require_gravity, require_overlap,
)
from pdr.io.recording import Recording

NS_PER_S = 1e9
CLOCK_AGREEMENT_S = 1.0  # start epochs of two files further apart than this are on different clock origins
SENSOR_FILES = ("Accelerometer.csv", "TotalAcceleration.csv", "Gravity.csv", "AccelerometerUncalibrated.csv",
                "Gyroscope.csv", "Magnetometer.csv", "Barometer.csv", "Location.csv")
_Raw = tuple[np.ndarray, np.ndarray, dict[str, Any]]  # (time_ns, values, {optional column: values or None})


def _read(folder: Path, name: str, columns: tuple[str, ...], optional: tuple[str, ...] = (), *,
          may_be_empty: bool = True) -> _Raw | None:
    """``(time_ns, values, extra)`` of one sensor file, or None when it is absent or, ``may_be_empty``, empty (0 bytes:
    the sensor gave nothing; an acceleration file is never optional). ``extra`` holds the optional columns and ``seconds_elapsed`` (None where absent).

    ``time_ns`` stays int64 when the file has integer time stamps (ns since 1970 exceed float64's exact range)."""
    path = folder / name
    if not path.is_file():
        return None
    if path.stat().st_size == 0 and may_be_empty:
        warn(f"{name}: empty file (the sensor gave no data); taken as absent")
        return None
    df = read_table(path, name, last_break=False)
    df.columns = [str(c).strip() for c in df.columns]
    missing = [c for c in ("time", *columns) if c not in df.columns]
    if missing:
        raise InputError(f"{name}: expected Sensor Logger columns time, {', '.join(columns)}, found {', '.join(df.columns)}")
    if pd.api.types.is_integer_dtype(df["time"]):
        t_ns = df["time"].to_numpy(dtype=np.int64)
    else:
        t_ns = numeric_array(df[["time"]], name)[:, 0]
    extra = {c: numeric_array(df[[c]], name)[:, 0] if c in df.columns else None for c in (*optional, "seconds_elapsed")}
    return t_ns, numeric_array(df[list(columns)], name), extra


def _start_epoch_ns(raw: _Raw) -> float | None:
    """The epoch (ns) of the start tap by this file's clock: median of ``time - seconds_elapsed``."""
    elapsed = raw[2]["seconds_elapsed"]
    if elapsed is None or not len(elapsed):
        return None
    return float(np.median(raw[0].astype(float) - elapsed * NS_PER_S))


def _seconds(t_ns: np.ndarray, t0_ns: int | float) -> np.ndarray:
    if t_ns.dtype.kind == "i" and isinstance(t0_ns, (int, np.integer)):
        return (t_ns - t0_ns).astype(float) / NS_PER_S
    return (t_ns.astype(float) - float(t0_ns)) / NS_PER_S


def _metadata(folder: Path) -> dict[str, Any]:
    """``platform`` ("ios", "android" or ""), ``standardised`` (bool) and ``epoch_ns`` (or None) of ``Metadata.csv``."""
    path = folder / "Metadata.csv"
    out: dict[str, Any] = {"platform": "", "standardised": False, "epoch_ns": None}
    if not path.is_file() or path.stat().st_size == 0:
        return out
    meta = read_table(path, "Metadata.csv", last_break=False, dtype=str, keep_default_na=False)
    meta.columns = [str(c).strip().lower() for c in meta.columns]
    row = {c: str(meta[c].iloc[0]).strip() for c in meta.columns}
    out["platform"] = row.get("platform", "").lower()
    out["standardised"] = any(v.lower() in ("true", "1", "yes") for c, v in row.items()
                              if "standardis" in c or "standardiz" in c)
    epoch_ms = pd.to_numeric(row.get("recording epoch time", ""), errors="coerce")
    out["epoch_ns"] = float(epoch_ms) * 1e6 if np.isfinite(epoch_ms) else None
    return out


def _specific_force(folder: Path, what: str, meta: dict[str, Any]) -> tuple[_Raw, np.ndarray, str]:
    """``(raw, f, name)``: the accelerometer file that sets the clock, the specific force including gravity on its
    samples (m/s², the app's sign convention) and the file's name."""
    total = _read(folder, "TotalAcceleration.csv", ("x", "y", "z"), may_be_empty=False)
    if total is not None:
        return total, total[1], "TotalAcceleration.csv"
    acc = _read(folder, "Accelerometer.csv", ("x", "y", "z"), may_be_empty=False)
    grav = _read(folder, "Gravity.csv", ("x", "y", "z"), may_be_empty=False)
    if acc is not None and grav is not None:
        t_a = _seconds(acc[0], acc[0][0])
        t_g, g = clean_series(_seconds(grav[0], acc[0][0]), grav[1], "Gravity.csv")
        if len(t_g) < 2:
            raise InputError(f"Gravity.csv: expected at least 2 samples, found {len(t_g)}")
        sel = (t_a >= t_g[0]) & (t_a <= t_g[-1])
        if not sel.any():
            raise InputError("Gravity.csv: expected samples over the time of Accelerometer.csv, found none (two exports mixed?)")
        kept = (acc[0][sel], acc[1][sel], {k: (v[sel] if v is not None else None) for k, v in acc[2].items()})
        return kept, kept[1] + interp_columns(t_a[sel], t_g, g), "Accelerometer.csv + Gravity.csv"
    raw = _read(folder, "AccelerometerUncalibrated.csv", ("x", "y", "z"), may_be_empty=False)
    if raw is not None:
        in_g = meta["platform"] == "ios" and not meta["standardised"]
        return raw, raw[1] * GRAVITY_MPS2 if in_g else raw[1], "AccelerometerUncalibrated.csv"
    if acc is not None:
        raise InputError(f"{what}: expected Gravity.csv, TotalAcceleration.csv or AccelerometerUncalibrated.csv beside "
                         "Accelerometer.csv, which holds linear acceleration (gravity removed); found none of them: "
                         "enable the Gravity sensor in the app")
    present = sorted(p.name for p in folder.iterdir())
    exports = [p for p in present if (folder / p).is_dir() and any((folder / p / n).is_file() for n in SENSOR_FILES)]
    if len(exports) > 1:
        raise InputError(f"{what}: expected one Sensor Logger export, found {len(exports)} ({', '.join(exports[:4])}): "
                         "import each on its own")
    raise InputError(f"{what}: expected a Sensor Logger export with Accelerometer.csv (or TotalAcceleration.csv, "
                     f"AccelerometerUncalibrated.csv), found {', '.join(present[:8]) or 'an empty folder'}")


def _aligned_ns(raw: _Raw, name: str, ref_epoch_ns: float | None) -> np.ndarray:
    """``time`` of a file on the accelerometer's clock origin (see the module's "Clock")."""
    epoch = _start_epoch_ns(raw)
    if ref_epoch_ns is None or epoch is None or abs(epoch - ref_epoch_ns) <= CLOCK_AGREEMENT_S * NS_PER_S:
        return raw[0]
    warn(f"{name}: its time column is {(epoch - ref_epoch_ns) / NS_PER_S:+.1f} s from the accelerometer's "
         "clock origin; aligned through seconds_elapsed (both count from the start tap)")
    return ref_epoch_ns + raw[2]["seconds_elapsed"] * NS_PER_S


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    what = src.name
    with source_folder(src, f"sensorlogger {what}") as folder:
        folder = find_export_root(folder, SENSOR_FILES)
        require_app(folder, "sensorlogger", what)
        meta_csv = _metadata(folder)
        acc_raw, f, acc_name = _specific_force(folder, what, meta_csv)
        t0 = acc_raw[0][0]
        ios = meta_csv["platform"] == "ios" and not meta_csv["standardised"]
        sign = -1.0 if ios else 1.0
        require_gravity(_seconds(acc_raw[0], t0), f, acc_name, " (the app's Gravity sensor is needed beside it)")
        if ios:
            warn(f"{what}: iOS export without standardised frames; acceleration negated to Android's "
                 "convention (+z up when the phone lies flat)")
        ref_epoch = _start_epoch_ns(acc_raw)
        loc = _read(folder, "Location.csv", ("latitude", "longitude"), ("altitude", "horizontalAccuracy"))
        start_ns = float(t0)
        loc_epoch = _start_epoch_ns(loc) if loc is not None else None
        if ref_epoch is not None and loc_epoch is not None and abs(loc_epoch - ref_epoch) > CLOCK_AGREEMENT_S * NS_PER_S:
            truth = meta_csv["epoch_ns"] if meta_csv["epoch_ns"] is not None else loc_epoch
            if abs(truth - loc_epoch) < abs(truth - ref_epoch):
                start_ns = float(t0) + (loc_epoch - ref_epoch)  # the location's absolute time is the true one

        def series(name: str, cols: tuple[str, ...]) -> Series | None:
            raw = _read(folder, name, cols)
            return None if raw is None else clean_series(_seconds(_aligned_ns(raw, name, ref_epoch), t0), raw[1], name)

        acc = clean_series(_seconds(acc_raw[0], t0), sign * f, acc_name)
        imu = combine_imu(acc, series("Gyroscope.csv", ("x", "y", "z")),
                          series("Magnetometer.csv", ("x", "y", "z")), series("Barometer.csv", ("pressure",)), what)
        meta: dict[str, Any] = {"recording": {"id": safe_id(src.stem if src.is_file() else src.name), "placement": "unknown",
                                              "source": "sensorlogger", "start_unix_s": start_ns / NS_PER_S}}
        gnss = None
        if loc is not None:
            _, ll, extra = loc
            gnss, geo = gnss_table(_seconds(_aligned_ns(loc, "Location.csv", ref_epoch), t0), ll[:, 0], ll[:, 1],
                                   extra["altitude"], extra["horizontalAccuracy"], "Location.csv")
            require_overlap(gnss["t_s"].to_numpy(), imu["t_s"].to_numpy(), "Location.csv")
            if geo is None:
                warn("Location.csv: no valid fix; gnss.csv not written")
                gnss = None
            else:
                meta["geo"] = geo
        return write_recordings([Recording(meta=meta, imu=imu, gnss=gnss)], dest, force=force)
