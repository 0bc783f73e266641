"""phyphox (RWTH Aachen) CSV export: a folder or the .zip the app shares.

Format: one CSV per sensor view, each with a ``"Time (s)"`` column (experiment time, s) and quoted headers
``"<quantity> (<unit>)"``; the export offers comma, tab or semicolon separators, the last with a decimal comma.
Recognised columns, by unit and name (any file, any order; several sensors may share one file and time column):

- acceleration **with g**: ``Acceleration x (m/s^2)`` ("Acceleration with g" / "Raw Data.csv") or ``X (m/s^2)`` in a file
  not named "linear". Linear acceleration (``Linear Acceleration x``, files named "Linear ...") has gravity removed
  and is refused when it is the only acceleration;
- gyroscope ``Gyroscope x (rad/s)`` or ``X (rad/s)``; magnetometer ``Magnetic field x (µT)`` or ``X (µT)``;
- ``Pressure (hPa)``;
- location: ``Latitude (°)``, ``Longitude (°)``, ``Altitude WGS84 (m)`` (else ``Height (m)`` / ``Altitude (m)``),
  ``Horizontal Accuracy (m)`` -> ``gnss.csv`` and ``[geo]`` origin = the first valid fix.

Clock: the experiment time is ``t_s`` (the accelerometer's clock, other sensors interpolated onto it; see
``_phone.combine_imu``). ``start_unix_s`` = the ``system time`` of the first ``START`` event of ``meta/time.csv``
(a paused experiment continues its experiment time, so later wall-clock times are not recoverable: warned).
Recording name: the export folder's (or zip's) name. Placement ``unknown``.
"""

from __future__ import annotations

import csv
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.io.importers._common import numeric_array, read_table, safe_id, source_folder, write_recordings
from pdr.io.importers._phone import Series, clean_series, combine_imu, gnss_table
from pdr.io.recording import Recording

_COLUMN = re.compile(r"^(?P<label>.*?)\s*\((?P<unit>[^()]*)\)\s*$")
_AXIS = {
    "acc": re.compile(r"^(acceleration\s+)?(?P<axis>[xyz])$", re.I),
    "linacc": re.compile(r"^linear\s+acceleration\s+(?P<axis>[xyz])$", re.I),
    "gyr": re.compile(r"^(gyroscope\s+)?(?P<axis>[xyz])$", re.I),
    "mag": re.compile(r"^(magnetic\s+field\s+)?(?P<axis>[xyz])$", re.I),
}
_UNITS = {"acc": ("m/s^2", "m/s²", "m/s2"), "linacc": ("m/s^2", "m/s²", "m/s2"), "gyr": ("rad/s",), "mag": ("µt", "μt", "ut")}
_LOCATION = {"latitude": ("latitude", "°"), "longitude": ("longitude", "°"), "alt_wgs84": ("altitude wgs84", "m"),
             "height": ("height", "m"), "altitude": ("altitude", "m"), "h_acc": ("horizontal accuracy", "m")}


def _dialect(path: Path, what: str) -> tuple[str, str]:
    """Separator and decimal mark of a phyphox CSV from its header and first data line."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            header, first = f.readline(), f.readline()
    except UnicodeDecodeError:
        raise InputError(f"{what}: expected a UTF-8 text CSV, found binary content") from None
    sep = "\t" if "\t" in header else (";" if ";" in header else ",")
    decimal = "," if sep != "," and "," in first else "."
    return sep, decimal


def _read(path: Path, what: str) -> pd.DataFrame:
    sep, decimal = _dialect(path, what)
    df = read_table(path, what, sep=sep, decimal=decimal, quoting=csv.QUOTE_MINIMAL, encoding="utf-8-sig")
    df.columns = [str(c).strip() for c in df.columns]
    return df


def _classify(df: pd.DataFrame, file_name: str) -> list[tuple[int, dict[str, dict[str, int]]]]:
    """Per time column: the sensors (acc, linacc, gyr, mag, baro, location fields) found after it, by column index."""
    groups: list[tuple[int, dict[str, dict[str, int]]]] = []
    linear_file = "linear" in file_name.lower()
    for j, name in enumerate(df.columns):
        m = _COLUMN.match(name)
        if not m:
            continue
        label, unit = m["label"].strip().lower(), m["unit"].strip().lower()
        if label == "time" and unit == "s":
            groups.append((j, {}))
            continue
        if not groups:
            continue
        sensors = groups[-1][1]
        for kind, pattern in _AXIS.items():
            am = pattern.match(label)
            if am and unit in _UNITS[kind]:
                kind = "linacc" if kind == "acc" and linear_file else kind
                sensors.setdefault(kind, {})[am["axis"].lower()] = j
                break
        else:
            if unit == "hpa" and "pressure" in label:
                sensors.setdefault("baro", {})["p"] = j
            for key, (loc_label, loc_unit) in _LOCATION.items():
                if label == loc_label and unit == loc_unit:
                    sensors.setdefault("location", {})[key] = j
    return groups


def _start_unix_s(folder: Path) -> float | None:
    path = folder / "meta" / "time.csv"
    if not path.is_file():
        return None
    df = _read(path, "meta/time.csv")
    cols = {c.lower(): c for c in df.columns}
    if "event" not in cols or "system time" not in cols:
        return None
    starts = df[df[cols["event"]].astype(str).str.strip().str.upper() == "START"]
    if starts.empty:
        return None
    if len(starts) > 1:
        warnings.warn("meta/time.csv: the experiment was paused; start_unix_s is the first start", stacklevel=3)
    value = pd.to_numeric(starts[cols["system time"]].iloc[0], errors="coerce")
    return float(value) if np.isfinite(value) else None


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    what = src.name
    with source_folder(src, f"phyphox {what}") as folder:
        if not any(folder.glob("*.csv")):  # a zip with one enclosing folder
            subs = [p for p in folder.iterdir() if p.is_dir() and p.name not in ("meta", "__MACOSX")]
            folder = subs[0] if len(subs) == 1 else folder
        files = sorted(p for p in folder.glob("*.csv") if p.is_file())
        if not files:
            raise InputError(f"{what}: expected a phyphox CSV export (files with a \"Time (s)\" column), found no .csv file")
        found: dict[str, tuple[np.ndarray, dict[str, int], pd.DataFrame, str]] = {}
        for path in files:
            df = _read(path, path.name)
            for time_col, sensors in _classify(df, path.name):
                for kind, cols in sensors.items():
                    found.setdefault(kind, (time_col, cols, df, path.name))
        if "acc" not in found:
            hint = " (only linear acceleration, which has gravity removed: record 'Acceleration with g')" if "linacc" in found else ""
            raise InputError(f"{what}: expected a phyphox export with acceleration including gravity, columns "
                             f"\"Acceleration x (m/s^2)\" or \"X (m/s^2)\", found none{hint}")

        def series(kind: str, axes: tuple[str, ...]) -> Series | None:
            if kind not in found:
                return None
            time_col, cols, df, name = found[kind]
            if any(a not in cols for a in axes):
                raise InputError(f"{name}: expected {kind} columns for {', '.join(axes)}, found only {', '.join(sorted(cols))}")
            a = numeric_array(df.iloc[:, [time_col] + [cols[x] for x in axes]], name)
            return clean_series(a[:, 0], a[:, 1:], name)

        imu = combine_imu(series("acc", ("x", "y", "z")), series("gyr", ("x", "y", "z")), series("mag", ("x", "y", "z")),
                          series("baro", ("p",)), what)
        meta: dict[str, Any] = {"recording": {"id": safe_id(src.stem if src.is_file() else src.name), "placement": "unknown",
                                              "source": "phyphox", "start_unix_s": _start_unix_s(folder)}}
        gnss = None
        if "location" in found:
            time_col, cols, df, name = found["location"]
            if "latitude" not in cols or "longitude" not in cols:
                raise InputError(f"{name}: expected Latitude (°) and Longitude (°) columns, found {', '.join(df.columns)}")
            alt_key = next((k for k in ("alt_wgs84", "height", "altitude") if k in cols), None)
            keys = ["latitude", "longitude"] + ([alt_key] if alt_key else []) + (["h_acc"] if "h_acc" in cols else [])
            a = numeric_array(df.iloc[:, [time_col] + [cols[k] for k in keys]], name)
            col = {k: a[:, 1 + i] for i, k in enumerate(keys)}
            gnss, geo = gnss_table(a[:, 0], col["latitude"], col["longitude"], col.get(alt_key) if alt_key else None,
                                   col.get("h_acc"), name)
            if geo is None:
                warnings.warn(f"{name}: no valid fix; gnss.csv not written", stacklevel=2)
                gnss = None
            else:
                meta["geo"] = geo
        return write_recordings([Recording(meta=meta, imu=imu, gnss=gnss)], dest, force=force)
