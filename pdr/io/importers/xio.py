"""x-io Gait-Tracking CSV (NGIMU on one foot): ``Time (s), Gyroscope X/Y/Z (deg/s), Accelerometer X/Y/Z (g)``.

Units are read from the header: gyroscope deg/s -> rad/s (rad/s kept), accelerometer g -> m/s² (m/s² kept); optional
``Magnetometer X/Y/Z (uT)`` columns are kept. The logger repeats a time stamp (with the same values) where it missed
a sample, including the first ones: every sample whose time repeats or steps back is dropped with a warning.

The file does not say which foot carries the sensor: ``--foot`` names it; without it placement ``foot_right`` is
assumed (stated in ``meta.toml`` as ``placement_assumed = true``). The recording is named after the file.

The CSV carries no ground truth, so no reference is written, except what the user declares: ``--closed-loop`` (the
walk ends where it started) writes ``reference/summary.toml`` ``loop_closure = true, final_displacement_m = 0``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError
from pdr.io.importers.openshoe import closed_loop_reference
from pdr.io.importers._common import (
    imu_frame, increasing_mask, numeric_array, read_table, require_finite, safe_id, steady_clock, write_recordings,
)
from pdr.io.recording import Recording

OPTIONS = ("foot", "closed_loop")
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


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False, foot: str | None = None,
                  closed_loop: bool = False) -> list[Path]:
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
    if foot is not None and foot not in ("left", "right"):
        raise InputError(f"import xio: expected --foot left or right, found {foot!r}")
    recording = {"id": safe_id(src.stem), "placement": f"foot_{foot or 'right'}", "source": "xio"}
    if foot is None:
        recording["placement_assumed"] = True
    return write_recordings([Recording(meta={"recording": recording}, imu=imu, reference=closed_loop_reference(closed_loop))],
                            dest, force=force)
