"""gaitmap IMU CSVs (MaD-Lab, FAU; the layout of gaitmap's ``example_data``): two foot-mounted IMUs, with the
motion-capture stride reference when it lies beside the file.

Source: a folder (every ``*.csv`` in gaitmap's IMU layout in it is a recording) or one such file. The layout: two
header rows (sensor ``left_sensor`` / ``right_sensor`` x axis ``acc_x..gyr_z``), acc in m/s², gyr in deg/s, the first
column either a **sample index** (consecutive integers: the rate comes from ``--rate-hz``; without it
``DEFAULT_RATE_HZ`` is used with a warning) or time in seconds (used as is; a different ``--rate-hz`` is ignored with a
warning). The recording id is the file name without ``.csv``, except the three example files, which keep their
descriptive ids: ``imu_sample.csv`` -> ``walk_2x20m``, ``imu_sample_healthy_stair_up.csv`` / ``..._down.csv`` ->
``stairs_up`` / ``stairs_down`` (``activity`` in the reference).

Each recording: ``imu.csv`` = the left foot (placement ``foot_left``) and ``imu_foot_right.csv``; acc m/s² as given, gyr
deg/s -> rad/s; gaitmap's foot "sensor frame" (z up at rest, x roughly along the foot) is kept.

Reference of ``imu_<name>.csv``, from ``stride_events_<name>.csv`` (IMU sample indices) and ``position_<name>.csv`` (heel
marker per stride, metres, relative to the stride start) beside it:

- ``strides.csv``: ``t_start_s, t_end_s`` (min_vel to the next min_vel, i.e. mid-stance to mid-stance), ``foot``,
  ``length_m`` (horizontal norm of the stride's last position row), plus ``ic_s``, ``tc_s``;
- ``steps.csv``: ``t_s, foot`` of every initial contact (each stride's ``ic`` and ``pre_ic``, without duplicates);
- ``summary.toml``: ``n_strides``, ``n_steps``, ``stride_length_sum_left_m`` / ``_right_m``, ``distance_m`` (the mean of
  the two feet's stride-length sums: the walked distance covered by the reference strides), ``activity``.
Without stride events, ``stride_borders_<name>.csv`` (``s_id, foot, start, end``) gives ``strides.csv`` with
``t_start_s, t_end_s, foot`` and unknown (NaN) ``length_m``. A recording without either has only its ``activity``,
when the example file names it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.importers._common import (
    imu_frame, numeric_array, read_table, require_finite, safe_id, write_recordings,
)
from pdr.io.recording import Recording

DEFAULT_RATE_HZ = 204.8
RECORDINGS = {  # the example files -> (recording name, activity label)
    "imu_sample.csv": ("walk_2x20m", "level_walk"),
    "imu_sample_healthy_stair_up.csv": ("stairs_up", "stairs_up"),
    "imu_sample_healthy_stair_down.csv": ("stairs_down", "stairs_down"),
}
SENSORS = {"left_sensor": "left", "right_sensor": "right"}
AXES = ("acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z")
EVENT_COLUMNS = ("s_id", "foot", "start", "end", "ic", "tc", "min_vel", "pre_ic")


def _two_header_table(path: Path, what: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """First column and, per foot, the (N, 6) array acc_x..gyr_z of a two-header-row gaitmap IMU file."""
    df = read_table(path, what, header=[0, 1], index_col=0)
    # a damaged first data row can make pandas give plain (not two-level) column labels: nothing is found then
    found = {(str(c[0]), str(c[1])) for c in df.columns if isinstance(c, tuple) and len(c) == 2}
    missing = [f"{s}/{a}" for s in SENSORS for a in AXES if (s, a) not in found]
    if missing:
        raise InputError(f"{what}: expected two header rows (sensor: left_sensor/right_sensor; axis: acc_x..gyr_z), "
                         f"found no {', '.join(missing[:4])}{'...' if len(missing) > 4 else ''}")
    first = numeric_array(df.index.to_frame(index=False), what)[:, 0]
    require_finite(first, what, "the first column")
    feet = {}
    for sensor, foot in SENSORS.items():
        a = numeric_array(df[[(sensor, ax) for ax in AXES]], what)
        require_finite(a, what, f"{sensor} columns")
        feet[foot] = a
    return first, feet


def _feet_imus(t_s: np.ndarray, feet: dict[str, np.ndarray]) -> dict[str, pd.DataFrame]:
    return {foot: imu_frame(t_s, a[:, :3], np.radians(a[:, 3:6])) for foot, a in feet.items()}


def _borders_reference(path: Path, rate_hz: float, activity: dict[str, Any]) -> dict[str, Any]:
    b = read_table(path, path.name)
    need = ("foot", "start", "end")
    if any(c not in b.columns for c in need):
        raise InputError(f"{path.name}: expected columns {', '.join(need)}, found {', '.join(map(str, b.columns))}")
    idx = numeric_array(b[["start", "end"]], path.name)
    require_finite(idx, path.name, "start, end")
    foot = b["foot"].astype(str).str.strip().str.lower()
    if not foot.isin(("left", "right")).all():
        raise InputError(f"{path.name}: expected foot 'left' or 'right', found {sorted(set(foot) - {'left', 'right'})}")
    strides = pd.DataFrame({"t_start_s": idx[:, 0] / rate_hz, "t_end_s": idx[:, 1] / rate_hz, "foot": foot.to_numpy(),
                            "length_m": np.nan}).sort_values(["t_start_s", "foot"], kind="stable").reset_index(drop=True)
    return {"strides": strides, "summary": {**activity, "n_strides": int(len(strides))}}


def _walk_reference(folder: Path, suffix: str, rate_hz: float, activity: dict[str, Any]) -> dict[str, Any]:
    events_path, pos_path = folder / f"stride_events_{suffix}.csv", folder / f"position_{suffix}.csv"
    if not events_path.is_file():
        borders = folder / f"stride_borders_{suffix}.csv"
        return _borders_reference(borders, rate_hz, activity) if borders.is_file() else {"summary": activity} \
            if activity else {}
    ev = read_table(events_path, events_path.name)
    missing = [c for c in EVENT_COLUMNS if c not in ev.columns]
    if missing:
        raise InputError(f"{events_path.name}: expected columns {', '.join(EVENT_COLUMNS)}, found {', '.join(map(str, ev.columns))}")
    num_cols = [c for c in EVENT_COLUMNS if c != "foot"]
    idx = numeric_array(ev[num_cols], events_path.name)
    require_finite(idx, events_path.name, ", ".join(num_cols))
    ev = pd.DataFrame(idx, columns=num_cols).assign(foot=ev["foot"].astype(str).str.strip().str.lower())
    if not ev["foot"].isin(("left", "right")).all():
        raise InputError(f"{events_path.name}: expected foot 'left' or 'right', found "
                         f"{sorted(set(ev['foot']) - {'left', 'right'})}")
    lengths = np.full(len(ev), np.nan)
    if pos_path.is_file():
        pos = read_table(pos_path, pos_path.name)
        pos = pos.rename(columns={pos.columns[0]: "sensor"})
        need = ("sensor", "s_id", "sample", "pos_x", "pos_y")
        if any(c not in pos.columns for c in need):
            raise InputError(f"{pos_path.name}: expected columns {', '.join(need)}, found {', '.join(map(str, pos.columns))}")
        xy = numeric_array(pos[["s_id", "sample", "pos_x", "pos_y"]], pos_path.name)
        pos = pd.DataFrame(xy, columns=["s_id", "sample", "pos_x", "pos_y"]).assign(
            foot=pos["sensor"].astype(str).map(SENSORS))
        last = pos.sort_values(["foot", "s_id", "sample"], kind="stable").groupby(["foot", "s_id"]).tail(1)
        norm = dict(zip(zip(last["foot"], last["s_id"]), np.hypot(last["pos_x"], last["pos_y"])))
        lengths = np.array([norm.get((f, s), np.nan) for f, s in zip(ev["foot"], ev["s_id"])])
    else:
        warn(f"{folder.name}: no {pos_path.name}; stride lengths are unknown (NaN)")
    strides = pd.DataFrame({
        "t_start_s": ev["start"] / rate_hz, "t_end_s": ev["end"] / rate_hz, "foot": ev["foot"], "length_m": lengths,
        "ic_s": ev["ic"] / rate_hz, "tc_s": ev["tc"] / rate_hz, "s_id": ev["s_id"].astype(int),
    }).sort_values(["t_start_s", "foot"], kind="stable").reset_index(drop=True)
    ics = pd.concat([ev[["ic", "foot"]], ev[["pre_ic", "foot"]].rename(columns={"pre_ic": "ic"})], ignore_index=True)
    ics = ics.drop_duplicates().sort_values(["ic", "foot"], kind="stable")
    steps = pd.DataFrame({"t_s": ics["ic"].to_numpy() / rate_hz, "foot": ics["foot"].to_numpy()})
    sums = {foot: float(np.nansum(strides.loc[strides["foot"] == foot, "length_m"])) for foot in ("left", "right")}
    summary = {
        **activity,
        "n_strides": int(len(strides)),
        "n_steps": int(len(steps)),
        "stride_length_sum_left_m": sums["left"],
        "stride_length_sum_right_m": sums["right"],
        "distance_m": (sums["left"] + sums["right"]) / 2.0,
        "distance_source": "mean over the two feet of the mocap stride-length sums (heel marker, mid-stance to mid-stance)",
    }
    return {"steps": steps, "strides": strides, "summary": summary}


def _recording(path: Path, rate_hz: float | None) -> Recording:
    name, label = RECORDINGS.get(path.name, (safe_id(path.stem), None))
    activity = {"activity": label} if label else {}
    first, feet = _two_header_table(path, path.name)
    if (np.diff(first) <= 0).any():
        raise InputError(f"{path.name}: expected an increasing sample index or time in the first column, found it out "
                         "of order")
    if np.allclose(np.diff(first), 1.0) and np.allclose(first, np.round(first)):  # a sample index
        if rate_hz is None:
            warn(f"{path.name}: carries only a sample index and --rate-hz was not given; "
                 f"using {DEFAULT_RATE_HZ} Hz (the rate of the gaitmap example data)")
            rate_hz = DEFAULT_RATE_HZ
        t_s = (first - first[0]) / rate_hz
    else:
        t_s = first
        file_rate = 1.0 / float(np.median(np.diff(t_s))) if len(t_s) > 1 else float("nan")
        if rate_hz is not None and abs(file_rate - rate_hz) > 0.01 * rate_hz:
            warn(f"{path.name}: its time column gives {file_rate:.1f} Hz; --rate-hz {rate_hz:g} is ignored")
        rate_hz = file_rate
    suffix = path.stem[len("imu_"):] if path.stem.startswith("imu_") else path.stem
    reference = _walk_reference(path.parent, suffix, rate_hz, activity)
    imus = _feet_imus(t_s, feet)
    meta = {"recording": {"id": name, "placement": "foot_left", "source": "gaitmap"}}
    return Recording(meta=meta, imu=imus["left"], extra_imus={"foot_right": imus["right"]}, reference=reference)


def _is_imu_layout(path: Path) -> bool:
    """The first two lines hold gaitmap's sensor and axis header rows."""
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            head = f.readline() + f.readline()
    except OSError:
        return False
    return "left_sensor" in head and "right_sensor" in head and "acc_x" in head


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    if src.is_file():
        files = [src]
    else:
        files = [p for p in sorted(src.glob("*.csv")) if _is_imu_layout(p)]
        if not files:
            raise InputError(f"{src}: expected a folder with gaitmap IMU CSVs (two header rows left_sensor/right_sensor "
                             "x acc_x..gyr_z), found none")
    return write_recordings([_recording(p, rate_hz) for p in files], dest, force=force)
