"""Writers for the outputs of ``pdr run`` (CONTRACT.md "Outputs of pdr run").

Every writer goes through :mod:`pdr.io.atomic` (temporary name, then rename) and is deterministic: fixed float
formats, sorted JSON keys, no time stamps. Tables are the flat, unit-named tables of the pipeline:

- a trajectory: ``t_s, e_m, n_m, heading_rad, e_std_m, n_std_m`` (first row = the start pose, then one row per step);
- steps: ``step_id, t_s, step_length_m, step_length_std_m, step_freq_hz, heading_rad, source``;
- strides: ``t_start_s, t_end_s, foot, length_m, length_std_m, source``;
- bouts: ``bout_id, t_start_s, t_end_s, n_steps, distance_m, speed_mps, cadence_spm, step_length_m, step_length_cv,
  vertical_lift_m, speed_variation_mps, power_gravity_w, power_inertia_w, power_external_w, mechanics_source``.

Frames: east-north-up local frame of the recording's ``[geo]`` origin, heading counter-clockwise from east.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from pdr import __version__
from pdr.geo import en_to_latlon
from pdr.io.atomic import write_csv, write_text
from pdr.io.tomlio import dumps_json
from pdr.schema import BOUT_COLUMNS, STEPS_COLUMNS, STRIDE_COLUMNS, TRAJECTORY_COLUMNS, require_table

CSV_FLOAT_FORMAT = "%.15g"  # prints the rounded values exactly (15 significant digits round-trip a decimal)
# fixed decimals by unit suffix: microseconds, 0.1 mm, microradians, 1e-4 Hz, 1e-9 deg (0.1 mm)
DECIMALS_BY_SUFFIX = {"_s": 6, "_m": 4, "_rad": 6, "_hz": 4, "_deg": 9}
GPX_NS = "http://www.topografix.com/GPX/1/1"


def fixed_decimals(df: pd.DataFrame) -> pd.DataFrame:
    """Float columns rounded to the decimals of their unit suffix (``DECIMALS_BY_SUFFIX``), negative zero removed, so
    that the CSV shows ``0.0000`` rather than ``7.4e-21`` and is byte-identical for identical results."""
    out = df.copy()
    for col in out.columns:
        if not pd.api.types.is_float_dtype(out[col]):
            continue
        for suffix, decimals in DECIMALS_BY_SUFFIX.items():
            if str(col).endswith(suffix):
                out[col] = np.round(out[col].to_numpy(float), decimals) + 0.0
                break
    return out


def _write_table(path: Path, df: pd.DataFrame) -> None:
    write_csv(path, fixed_decimals(df), float_format=CSV_FLOAT_FORMAT)


def trajectory_table(traj: pd.DataFrame, origin: tuple[float, float] | None) -> pd.DataFrame:
    """The ``trajectory.csv`` table: the contract columns first, plus ``lat_deg, lon_deg`` when ``origin`` is known."""
    require_table(traj, TRAJECTORY_COLUMNS, "trajectory")
    table = traj[list(TRAJECTORY_COLUMNS)].astype(float).reset_index(drop=True)
    if origin is not None:
        lat, lon = en_to_latlon(table["e_m"].to_numpy(), table["n_m"].to_numpy(), origin)
        table["lat_deg"], table["lon_deg"] = lat, lon
    return table


def steps_table(steps: pd.DataFrame) -> pd.DataFrame:
    """The ``steps.csv`` table: contract columns in contract order, then ``bout_id`` when present."""
    require_table(steps, STEPS_COLUMNS, "steps")
    extra = [c for c in ("bout_id",) if c in steps.columns]
    return steps[list(STEPS_COLUMNS) + extra].reset_index(drop=True)


def write_trajectory_csv(path: Path, traj: pd.DataFrame, origin: tuple[float, float] | None = None) -> None:
    _write_table(path, trajectory_table(traj, origin))


def write_steps_csv(path: Path, steps: pd.DataFrame) -> None:
    _write_table(path, steps_table(steps))


def write_strides_csv(path: Path, strides: pd.DataFrame) -> None:
    require_table(strides, STRIDE_COLUMNS, "strides")
    _write_table(path, strides[list(STRIDE_COLUMNS)].reset_index(drop=True))


def write_bouts_csv(path: Path, bouts: pd.DataFrame) -> None:
    """``bouts.csv`` (:data:`pdr.gait.mechanics.BOUT_COLUMNS`); speeds to 0.1 mm/s, cadence and powers to 0.01."""
    require_table(bouts, BOUT_COLUMNS, "bouts")
    table = bouts[list(BOUT_COLUMNS)].reset_index(drop=True)
    for col, decimals in (("speed_mps", 4), ("speed_variation_mps", 4), ("cadence_spm", 2), ("step_length_cv", 4),
                          ("power_gravity_w", 2), ("power_inertia_w", 2), ("power_external_w", 2)):
        table[col] = np.round(table[col].to_numpy(float), decimals) + 0.0
    _write_table(path, table)


def write_json(path: Path, obj: Any, float_digits: int | None = 9) -> None:
    """A JSON object with sorted keys, 2-space indent, floats at ``float_digits`` significant digits (None: exactly;
    :func:`pdr.io.tomlio.jsonable`)."""
    write_text(path, dumps_json(obj, float_digits))


def yaw_to_quaternion_xyzw(yaw_rad: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(qx, qy, qz, qw)`` of rotations by ``yaw_rad`` about the up (z) axis."""
    yaw = np.asarray(yaw_rad, float)
    return Rotation.from_euler("z", yaw.reshape(-1, 1)).as_quat().reshape(yaw.shape + (4,))


def tum_text(traj: pd.DataFrame) -> str:
    """TUM RGB-D trajectory text: one ``t x y z qx qy qz qw`` line per pose (x = east, y = north, z = 0).

    This is the format ``evo`` reads (``evo_traj tum trajectory.tum``); the leading ``#`` line is a comment.
    """
    require_table(traj, TRAJECTORY_COLUMNS, "trajectory")
    q = yaw_to_quaternion_xyzw(traj["heading_rad"].to_numpy())
    lines = ["# t x y z qx qy qz qw  (pdr: x east, y north, metres; yaw counter-clockwise from east)"]
    for t, e, n, (qx, qy, qz, qw) in zip(traj["t_s"].to_numpy(), traj["e_m"].to_numpy(), traj["n_m"].to_numpy(), q):
        lines.append(f"{t:.6f} {e:.6f} {n:.6f} 0.000000 {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}")
    return "\n".join(lines) + "\n"


def write_tum(path: Path, traj: pd.DataFrame) -> None:
    write_text(path, tum_text(traj))


def geojson_object(traj: pd.DataFrame, origin: tuple[float, float] | None, *, name: str = "") -> dict[str, Any]:
    """A GeoJSON FeatureCollection with the path as one LineString.

    With a geo origin, coordinates are ``[lon, lat]`` in degrees (RFC 7946); without one they are ``[east, north]`` in
    metres of the local frame, and the feature's ``frame`` property says so. ``t_s`` gives the time of each vertex.
    """
    table = trajectory_table(traj, origin)
    if origin is not None:
        coords = [[round(float(lo), 9), round(float(la), 9)] for lo, la in zip(table["lon_deg"], table["lat_deg"])]
        frame = "WGS84 lon/lat (deg)"
    else:
        coords = [[round(float(e), 4), round(float(n), 4)] for e, n in zip(table["e_m"], table["n_m"])]
        frame = "local east/north (m), no geo origin"
    props: dict[str, Any] = {"name": name, "frame": frame, "t_s": [round(float(t), 6) for t in table["t_s"]]}
    if origin is not None:
        props["origin_lat_deg"], props["origin_lon_deg"] = origin
    return {"type": "FeatureCollection",
            "features": [{"type": "Feature", "properties": props, "geometry": {"type": "LineString", "coordinates": coords}}]}


def write_geojson(path: Path, traj: pd.DataFrame, origin: tuple[float, float] | None, *, name: str = "") -> None:
    write_text(path, json.dumps(geojson_object(traj, origin, name=name), sort_keys=True, allow_nan=False) + "\n")


def gpx_text(traj: pd.DataFrame, origin: tuple[float, float], *, name: str = "", start_unix_s: float | None = None) -> str:
    """A GPX 1.1 document with one track of the path (``trkpt lat lon``), each point with its UTC ``time`` (ISO 8601,
    microseconds) when the recording's clock is known (``start_unix_s``: the Unix time of ``t_s = 0``, ``meta.toml``
    ``[recording]``); without it the recording has no absolute clock, so no ``time``."""
    table = trajectory_table(traj, origin)
    ET.register_namespace("", GPX_NS)
    root = ET.Element(f"{{{GPX_NS}}}gpx", {"version": "1.1", "creator": f"pdr {__version__}"})
    trk = ET.SubElement(root, f"{{{GPX_NS}}}trk")
    ET.SubElement(trk, f"{{{GPX_NS}}}name").text = name
    seg = ET.SubElement(trk, f"{{{GPX_NS}}}trkseg")
    for lat, lon, t in zip(table["lat_deg"], table["lon_deg"], table["t_s"]):
        point = ET.SubElement(seg, f"{{{GPX_NS}}}trkpt", {"lat": f"{lat:.9f}", "lon": f"{lon:.9f}"})
        if start_unix_s is not None:
            utc = datetime.fromtimestamp(round(float(start_unix_s) + float(t), 6), tz=timezone.utc)
            ET.SubElement(point, f"{{{GPX_NS}}}time").text = utc.isoformat(timespec="microseconds").replace("+00:00", "Z")
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_gpx(path: Path, traj: pd.DataFrame, origin: tuple[float, float], *, name: str = "",
              start_unix_s: float | None = None) -> None:
    write_text(path, gpx_text(traj, origin, name=name, start_unix_s=start_unix_s))
