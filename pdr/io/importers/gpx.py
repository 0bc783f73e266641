"""GPX track -> ``gnss.csv`` of an existing recording: ``pdr import gpx TRACK.gpx REC``.

Every ``trkpt`` (or ``rtept`` when there is no track) with ``lat``, ``lon`` and a ``time`` becomes a row ``t_s, lat_deg,
lon_deg`` (+ ``alt_m`` from ``ele``). GPX carries no horizontal accuracy, so there is no ``h_acc_m`` column.

Clock: ``t_s = time - start_unix_s`` when the recording's ``meta.toml`` has ``[recording] start_unix_s`` (the Unix time of
``t_s = 0``, written by the importers of sources that know it); otherwise the track's first point is taken as
``t_s = 0``, with a warning (align the clocks yourself if the track started earlier or later than the IMU).
Times without a zone are taken as UTC (warned). ``[geo]`` is set to the first point when the recording has none.

Safety: the file is parsed with ``xml.etree`` after refusing any DOCTYPE or ENTITY declaration (no entity expansion,
no external entities). The recording is replaced atomically (a complete copy with the new files, then a rename);
an existing ``gnss.csv`` is replaced only with ``--force``.
"""

from __future__ import annotations

import re
import shutil
import xml.etree.ElementTree as ET
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.atomic import atomic_dir, write_csv, write_text
from pdr.io.importers._common import increasing_mask, require_file
from pdr.io.recording import exact_time_column, load_recording, validate_gnss
from pdr.io.tomlio import dumps_toml

MAX_GPX_BYTES = 200 * 1024**2
_FORBIDDEN = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.I)


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _parse_time(text: str, what: str) -> tuple[float, bool]:
    """Unix seconds of an ISO 8601 time, and whether it carried a zone."""
    s = text.strip()
    if s.endswith(("Z", "z")):
        s = s[:-1] + "+00:00"
    try:
        dt = datetime.fromisoformat(s)
    except ValueError:
        raise InputError(f"{what}: expected ISO 8601 times like 2024-06-01T10:00:00Z, found {text.strip()[:40]!r}") from None
    has_zone = dt.tzinfo is not None
    if not has_zone:
        dt = dt.replace(tzinfo=timezone.utc)
    return dt.timestamp(), has_zone


def read_gpx(path: Path) -> pd.DataFrame:
    """Track points as ``unix_s, lat_deg, lon_deg, alt_m`` (alt NaN where there is no ``ele``), in file order."""
    what = path.name
    require_file(path, what)
    if path.stat().st_size > MAX_GPX_BYTES:
        raise InputError(f"{what}: expected a GPX file of at most {MAX_GPX_BYTES} bytes, found {path.stat().st_size}")
    data = path.read_bytes()
    if _FORBIDDEN.search(data):
        raise InputError(f"{what}: expected plain GPX XML, found a DOCTYPE or ENTITY declaration (refused for safety)")
    try:
        root = ET.fromstring(data)
    except (ET.ParseError, LookupError, ValueError) as exc:  # LookupError: an unknown encoding in the XML declaration
        raise InputError(f"{what}: expected well-formed GPX XML, found {exc}") from None
    if _local(root.tag) != "gpx":
        raise InputError(f"{what}: expected a <gpx> document, found <{_local(root.tag)}>")
    points = [e for e in root.iter() if _local(e.tag) == "trkpt"] or [e for e in root.iter() if _local(e.tag) == "rtept"]
    if not points:
        raise InputError(f"{what}: expected track points (<trkpt>) or route points (<rtept>), found none")
    rows, no_time, no_zone = [], 0, False
    for p in points:
        try:
            lat, lon = float(p.attrib["lat"]), float(p.attrib["lon"])
        except (KeyError, ValueError):
            raise InputError(f"{what}: expected numeric lat and lon attributes on every point, found {p.attrib}") from None
        if not (abs(lat) <= 90 and abs(lon) <= 180):
            raise InputError(f"{what}: expected lat in [-90, 90] and lon in [-180, 180], found {lat}, {lon}")
        children = {_local(c.tag): (c.text or "") for c in p}
        if not children.get("time", "").strip():
            no_time += 1
            continue
        unix_s, zoned = _parse_time(children["time"], what)
        no_zone |= not zoned
        ele = children.get("ele", "").strip()
        try:
            alt = float(ele) if ele else np.nan
        except ValueError:
            raise InputError(f"{what}: expected a number in <ele>, found {ele[:30]!r}") from None
        rows.append((unix_s, lat, lon, alt))
    if not rows:
        raise InputError(f"{what}: expected points with a <time>, found {len(points)} point(s) without one")
    if no_time:
        warn(f"{what}: skipped {no_time} point(s) without <time>")
    if no_zone:
        warn(f"{what}: times without a zone taken as UTC")
    return pd.DataFrame(rows, columns=["unix_s", "lat_deg", "lon_deg", "alt_m"])


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    track = read_gpx(src)
    rec = load_recording(dest)  # DEST must be a valid recording
    if (dest / "gnss.csv").exists() and not force:
        raise InputError(f"{dest}/gnss.csv: expected a recording without GNSS, found one (use --force to replace it)")
    start = rec.meta["recording"].get("start_unix_s")
    if isinstance(start, (int, float)) and np.isfinite(start):
        t0 = float(start)
    else:
        t0 = float(track["unix_s"].iloc[0])
        warn(f"{dest}: meta.toml has no [recording] start_unix_s; the GPX's first point is taken as t_s = 0")
    t_s = np.round(track["unix_s"].to_numpy() - t0, 6)  # GPX times have at most microsecond resolution
    keep = increasing_mask(t_s, src.name)
    gnss = pd.DataFrame({"t_s": t_s, "lat_deg": track["lat_deg"], "lon_deg": track["lon_deg"]})[keep]
    if track["alt_m"].notna().any():
        gnss["alt_m"] = track["alt_m"][keep]
    gnss = validate_gnss(gnss.reset_index(drop=True), f"{src.name} -> gnss.csv")
    imu_t = rec.imu["t_s"].to_numpy()
    if gnss["t_s"].iloc[-1] < imu_t[0] or gnss["t_s"].iloc[0] > imu_t[-1]:
        warn(f"{src.name}: the track ({gnss['t_s'].iloc[0]:.1f} to {gnss['t_s'].iloc[-1]:.1f} s) does not overlap "
             f"the IMU ({imu_t[0]:.1f} to {imu_t[-1]:.1f} s); check the clocks")
    meta = dict(rec.meta)
    if "geo" not in meta:
        meta["geo"] = {"origin_lat_deg": float(gnss["lat_deg"].iloc[0]), "origin_lon_deg": float(gnss["lon_deg"].iloc[0])}
    with atomic_dir(dest, force=True) as tmp:
        shutil.copytree(dest, tmp, symlinks=True, dirs_exist_ok=True)
        write_csv(tmp / "gnss.csv", exact_time_column(gnss))
        write_text(tmp / "meta.toml", dumps_toml(meta))
    return [dest]
