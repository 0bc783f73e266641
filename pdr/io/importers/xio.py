"""x-io Gait-Tracking CSV (NGIMU on one foot): ``Time (s), Gyroscope X/Y/Z (deg/s), Accelerometer X/Y/Z (g)``.

Units are read from the header: gyroscope deg/s -> rad/s (rad/s kept), accelerometer g -> m/s² (m/s² kept); optional
``Magnetometer X/Y/Z (uT)`` columns are kept. The logger repeats a time stamp (with the same values) where it missed
a sample, including the first ones: every sample whose time repeats or steps back is dropped with a warning.

The upstream README does not say which foot carries the sensor: placement ``foot_right`` is assumed (stated in
``meta.toml`` as ``placement_assumed = true``). The recording is named after the file (``short_walk``).

Reference (``summary.toml``): ``loop_closure = true`` (the walk ends where it started, final displacement 0 m),
``distance_m = 25.0`` with ``distance_approximate = true`` (the upstream README's "about 25 m").
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError
from pdr.io.importers._common import (
    imu_frame, increasing_mask, numeric_array, read_table, require_finite, safe_id, steady_clock, write_recordings,
)
from pdr.io.recording import Recording

LOOP_DISTANCE_M = 25.0  # approximate, from the upstream README
_HEADER = re.compile(r"^(?P<sensor>gyroscope|accelerometer|magnetometer)\s+(?P<axis>[xyz])\s*\((?P<unit>[^)]*)\)$", re.I)
_UNIT_SCALE = {
    "gyroscope": {"deg/s": np.pi / 180.0, "rad/s": 1.0},
    "accelerometer": {"g": GRAVITY_MPS2, "m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0},
    "magnetometer": {"ut": 1.0, "µt": 1.0},
}


def _columns(header: list[str], what: str) -> dict[str, tuple[list[int], float]]:
    found: dict[str, dict[str, tuple[int, str]]] = {}
    for j, name in enumerate(header):
        m = _HEADER.match(name.strip())
        if m:
            found.setdefault(m["sensor"].lower(), {})[m["axis"].lower()] = (j, m["unit"].strip().lower())
    out = {}
    for sensor, axes in found.items():
        if set(axes) != {"x", "y", "z"}:
            raise InputError(f"{what}: expected {sensor} X, Y and Z columns, found only {', '.join(sorted(axes)).upper()}")
        units = {u for _, u in axes.values()}
        scale = _UNIT_SCALE[sensor].get(units.pop()) if len(units) == 1 else None
        if scale is None:
            raise InputError(f"{what}: expected {sensor} units among {', '.join(_UNIT_SCALE[sensor])}, "
                             f"found {', '.join(sorted({u for _, u in axes.values()}))}")
        out[sensor] = ([axes[a][0] for a in "xyz"], scale)
    return out


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    what = src.name
    if src.is_dir():
        raise InputError(f"{src}: expected an x-io Gait-Tracking CSV file, found a folder")
    df = read_table(src, what)
    header = [str(c).strip() for c in df.columns]
    if not header or header[0].lower() != "time (s)":
        raise InputError(f"{what}: expected the first column 'Time (s)', found {header[0] if header else 'no header'!r}")
    cols = _columns(header, what)
    if "accelerometer" not in cols:
        raise InputError(f"{what}: expected columns Accelerometer X/Y/Z (g), found {', '.join(header)}")
    a = numeric_array(df, what)
    require_finite(a, what, "all columns")
    keep = increasing_mask(a[:, 0], what)
    a = a[keep]
    if len(a) < 2:
        raise InputError(f"{what}: expected at least 2 samples with increasing time, found {len(a)}")
    t_s = a[:, 0] - a[0, 0]
    signals = {s: a[:, idx] * scale for s, (idx, scale) in cols.items()}
    order = list(signals)
    t_s, stacked = steady_clock(t_s, np.hstack([signals[s] for s in order]), what)
    signals = {s: stacked[:, 3 * k:3 * k + 3] for k, s in enumerate(order)}
    imu = imu_frame(t_s, signals["accelerometer"], signals.get("gyroscope"), signals.get("magnetometer"))
    meta = {"recording": {"id": safe_id(src.stem), "placement": "foot_right", "placement_assumed": True, "source": "xio"}}
    reference = {"summary": {"loop_closure": True, "final_displacement_m": 0.0, "distance_m": LOOP_DISTANCE_M,
                             "distance_approximate": True}}
    return write_recordings([Recording(meta=meta, imu=imu, reference=reference)], dest, force=force)
