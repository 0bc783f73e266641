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

Custom experiments write headers without units (``"time","Acceleration x",...``, ``GPS.csv`` with ``Latitude,
Longitude, Altitude, Direction, Speed``, ``Pressure.csv``): recognised by name, in phyphox's units. Data files may end
without a line break and with an empty row ``""`` (dropped). Acceleration without gravity (median |a| near 2 m/s²)
is refused naming its file, whatever the file is called.

Clock: the experiment time is ``t_s`` (the accelerometer's clock, other sensors interpolated onto it; see
``_phone.combine_imu``). ``start_unix_s`` = the ``system time`` of the ``START`` event of ``meta/time.csv``. An
experiment paused and resumed (several ``START`` events) becomes one recording per run, ``<name>_run1``, ...: the run's
samples are those of its experiment-time window (or, where the time restarts at a resume, the stretch between
restarts), its ``t_s`` counts from its ``START``, so a pause is never a jump inside one recording.
Recording name: the export folder's (or zip's) name. Placement ``unknown``.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.importers._common import numeric_array, read_table, safe_id, source_folder, write_recordings
from pdr.io.importers._phone import (
    Series, clean_series, combine_imu, gnss_table, require_app, require_gravity, require_overlap,
)
from pdr.io.recording import Recording

_COLUMN = re.compile(r"^(?P<label>.*?)\s*\((?P<unit>[^()]*)\)\s*$")
_AXIS = {
    "acc": re.compile(r"^(acceleration\s+)?(?P<axis>[xyz])$", re.I),
    "linacc": re.compile(r"^linear\s+acceleration\s+(?P<axis>[xyz])$", re.I),
    "gyr": re.compile(r"^(gyroscope\s+|angular\s+velocity\s+)?(?P<axis>[xyz])$", re.I),
    "mag": re.compile(r"^(magnetic\s+field\s+)?(?P<axis>[xyz])$", re.I),
}
_NAMED = {"acc": "acceleration", "linacc": "linear acceleration", "gyr": "gyroscope", "mag": "magnetic field"}
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
    df = read_table(path, what, last_break=False, sep=sep, decimal=decimal, quoting=csv.QUOTE_MINIMAL, encoding="utf-8-sig")
    df.columns = [str(c).strip() for c in df.columns]
    return df


def _label_unit(name: str) -> tuple[str, str | None]:
    """``"Acceleration x (m/s^2)"`` -> ("acceleration x", "m/s^2"); a custom experiment's ``"Acceleration x"`` has no unit."""
    m = _COLUMN.match(name)
    if m:
        return m["label"].strip().lower(), m["unit"].strip().lower()
    return name.strip().lower(), None


def _classify(df: pd.DataFrame, file_name: str) -> list[tuple[int, dict[str, dict[str, int]]]]:
    """Per time column: the sensors (acc, linacc, gyr, mag, baro, location fields) found after it, by column index.

    Columns without a unit (custom experiments) are recognised by their full name (``Acceleration x``, ``Gyroscope x``,
    ``Magnetic field x``, ``Pressure``, ``Latitude``...) and taken in phyphox's units (m/s², rad/s, µT, hPa, °, m)."""
    groups: list[tuple[int, dict[str, dict[str, int]]]] = []
    linear_file = "linear" in file_name.lower()
    for j, name in enumerate(df.columns):
        label, unit = _label_unit(str(name))
        if label == "time" and unit in ("s", None):
            groups.append((j, {}))
            continue
        if not groups:
            continue
        sensors = groups[-1][1]
        for kind, pattern in _AXIS.items():
            am = pattern.match(label)
            if am and (unit in _UNITS[kind] if unit is not None else label.startswith(_NAMED[kind] + " ")):
                kind = "linacc" if kind == "acc" and linear_file else kind
                sensors.setdefault(kind, {})[am["axis"].lower()] = j
                break
        else:
            if "pressure" in label and unit in ("hpa", None):
                sensors.setdefault("baro", {})["p"] = j
            for key, (loc_label, loc_unit) in _LOCATION.items():
                if label == loc_label and unit in (loc_unit, None):
                    sensors.setdefault("location", {})[key] = j
    return groups


def _runs(folder: Path) -> list[tuple[float, float, float | None]]:
    """``(experiment time of a START, of the following PAUSE (inf if none), system time of the START or None)`` per
    run of ``meta/time.csv``; one run from 0 when the file is absent."""
    path = folder / "meta" / "time.csv"
    if not path.is_file():
        return [(0.0, np.inf, None)]
    df = _read(path, "meta/time.csv")
    cols = {c.lower(): c for c in df.columns}
    if "event" not in cols or "experiment time" not in cols:
        raise InputError(f"meta/time.csv: expected columns event, experiment time, system time, found {', '.join(df.columns)}")
    events = df[cols["event"]].astype(str).str.strip().str.upper().to_numpy()
    exp_t = pd.to_numeric(df[cols["experiment time"]], errors="coerce").to_numpy(float)
    sys_t = (pd.to_numeric(df[cols["system time"]], errors="coerce").to_numpy(float) if "system time" in cols
             else np.full(len(df), np.nan))
    runs: list[tuple[float, float, float | None]] = []
    for k in np.flatnonzero(events == "START"):
        later = [i for i in range(k + 1, len(events)) if events[i] == "PAUSE"]
        end = exp_t[later[0]] if later and np.isfinite(exp_t[later[0]]) else np.inf
        runs.append((float(exp_t[k]) if np.isfinite(exp_t[k]) else 0.0, float(end),
                     float(sys_t[k]) if np.isfinite(sys_t[k]) else None))
    return runs or [(0.0, np.inf, None)]


def _run_rows(t: np.ndarray, runs: list[tuple[float, float, float | None]], k: int) -> np.ndarray:
    """The rows of run ``k`` (all rows when there is one run): where the time restarts (steps back at a resume) the
    ``k``-th stretch between restarts, otherwise the samples inside the run's experiment-time window."""
    if len(runs) == 1:
        return np.ones(len(t), bool)
    restarts = np.flatnonzero(np.diff(t) < -0.5) + 1  # a resume that restarts the clock (small stutters are repaired)
    if len(restarts) == len(runs) - 1:
        bounds = np.concatenate([[0], restarts, [len(t)]])
        rows = np.zeros(len(t), bool)
        rows[bounds[k]:bounds[k + 1]] = True
        return rows
    lo, hi = runs[k][0], runs[k][1]
    return (t >= lo - 1e-9) & (t <= hi + 1e-9)


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    what = src.name
    with source_folder(src, f"phyphox {what}") as folder:
        if not any(folder.glob("*.csv")):  # a zip with one enclosing folder
            subs = sorted(p for p in folder.iterdir() if p.is_dir() and p.name not in ("meta", "__MACOSX"))
            exports = [p.name for p in subs if any(p.glob("*.csv"))]
            if len(exports) > 1:
                raise InputError(f"{what}: expected one phyphox export, found {len(exports)} ({', '.join(exports[:4])}): "
                                 "import each on its own")
            folder = subs[0] if len(subs) == 1 else folder
        files = sorted(p for p in folder.glob("*.csv") if p.is_file())
        if not files:
            raise InputError(f"{what}: expected a phyphox CSV export (files with a \"Time (s)\" column), found no .csv file")
        require_app(folder, "phyphox", what)
        found: dict[str, tuple[np.ndarray, dict[str, int], pd.DataFrame, str]] = {}
        for path in files:
            if path.stat().st_size == 0:
                warn(f"{path.name}: empty file; taken as absent")
                continue
            df = _read(path, path.name)
            groups = _classify(df, path.name)
            if not groups:
                raise InputError(f"{path.name}: expected phyphox columns, \"Time (s)\" (or \"time\") then quantities such "
                                 f"as \"Acceleration x (m/s^2)\", found {', '.join(map(str, df.columns))}")
            for time_col, sensors in groups:
                for kind, cols in sensors.items():
                    found.setdefault(kind, (time_col, cols, df, path.name))
        if "acc" not in found:
            hint = " (only linear acceleration, which has gravity removed: record 'Acceleration with g')" if "linacc" in found else ""
            raise InputError(f"{what}: expected a phyphox export with acceleration including gravity, columns "
                             f"\"Acceleration x (m/s^2)\" or \"X (m/s^2)\", found none in {', '.join(p.name for p in files[:6])}{hint}")
        raw: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
        for kind, axes in (("acc", ("x", "y", "z")), ("gyr", ("x", "y", "z")), ("mag", ("x", "y", "z")), ("baro", ("p",))):
            if kind in found:
                time_col, cols, df, name = found[kind]
                if any(a not in cols for a in axes):
                    raise InputError(f"{name}: expected {kind} columns for {', '.join(axes)}, found only {', '.join(sorted(cols))}")
                a = numeric_array(df.iloc[:, [time_col] + [cols[x] for x in axes]], name)
                raw[kind] = (a[:, 0], a[:, 1:], name)
        require_gravity(raw["acc"][0], raw["acc"][1], raw["acc"][2], " (record 'Acceleration with g' in phyphox)")
        location = _location(found)
        runs = _runs(folder)
        base = safe_id(src.stem if src.is_file() else src.name)
        if len(runs) > 1:
            warn(f"{what}: the experiment was paused {len(runs) - 1} time(s) (meta/time.csv); one recording per "
                 "run, named ..._run1, _run2, ...")
        recordings = []
        for k, (t_start, _, sys_start) in enumerate(runs):
            def series(kind: str) -> Series | None:
                if kind not in raw:
                    return None
                t, v, name = raw[kind]
                rows = _run_rows(t, runs, k)
                return clean_series(t[rows] - (t_start if len(runs) > 1 else 0.0), v[rows], name)

            acc = series("acc")
            if len(runs) > 1 and len(acc[0]) < 2:
                warn(f"{what}: run {k + 1} has no acceleration samples; skipped")
                continue
            imu = combine_imu(acc, series("gyr"), series("mag"), series("baro"), what)
            rec_id = f"{base}_run{k + 1}" if len(runs) > 1 else base
            meta: dict[str, Any] = {"recording": {"id": rec_id, "placement": "unknown", "source": "phyphox",
                                                  "start_unix_s": sys_start}}
            gnss = None
            if location is not None:
                t_loc, cols, name = location
                rows = _run_rows(t_loc, runs, k)
                gnss, geo = gnss_table(t_loc[rows] - (t_start if len(runs) > 1 else 0.0), cols["latitude"][rows],
                                       cols["longitude"][rows], cols["alt"][rows] if cols["alt"] is not None else None,
                                       cols["h_acc"][rows] if cols["h_acc"] is not None else None, name)
                require_overlap(gnss["t_s"].to_numpy(), imu["t_s"].to_numpy(), name)
                if geo is None:
                    warn(f"{name}: no valid fix; gnss.csv not written")
                    gnss = None
                else:
                    meta["geo"] = geo
            recordings.append(Recording(meta=meta, imu=imu, gnss=gnss))
        if not recordings:
            raise InputError(f"{what}: expected acceleration samples in at least one run of meta/time.csv, found none")
        return write_recordings(recordings, dest, force=force)


def _location(found: dict) -> tuple[np.ndarray, dict[str, np.ndarray | None], str] | None:
    """``(time, {latitude, longitude, alt, h_acc}, file name)`` of the location columns, or None."""
    if "location" not in found:
        return None
    time_col, cols, df, name = found["location"]
    if "latitude" not in cols or "longitude" not in cols:
        raise InputError(f"{name}: expected Latitude (°) and Longitude (°) columns, found {', '.join(df.columns)}")
    alt_key = next((k for k in ("alt_wgs84", "height", "altitude") if k in cols), None)
    keys = ["latitude", "longitude"] + ([alt_key] if alt_key else []) + (["h_acc"] if "h_acc" in cols else [])
    a = numeric_array(df.iloc[:, [time_col] + [cols[k] for k in keys]], name)
    col = {k: a[:, 1 + i] for i, k in enumerate(keys)}
    return a[:, 0], {"latitude": col["latitude"], "longitude": col["longitude"],
                     "alt": col[alt_key] if alt_key else None, "h_acc": col.get("h_acc")}, name
