"""gaitmap example data (MaD-Lab, FAU): two foot-mounted IMUs with motion-capture stride reference.

Source: a folder with the gaitmap example CSVs (see ``datasets/gaitmap_foot_imu_mocap/README.md``), or one of its IMU files.

- ``imu_sample.csv`` -> recording ``walk_2x20m``. Two header rows (sensor, axis), then a **sample index** only:
  the rate comes from ``--rate-hz`` (204.8 Hz for this file; when not given, ``DEFAULT_RATE_HZ`` is used with a warning).
- ``imu_sample_healthy_stair_up.csv`` / ``..._stair_down.csv`` -> ``stairs_up`` / ``stairs_down``. Their first column is
  time in seconds, which is used as is (``--rate-hz`` is not needed; a different one is ignored with a warning).

Each recording: ``imu.csv`` = the left foot (placement ``foot_left``) and ``imu_foot_right.csv``; acc m/s² as given, gyr
deg/s -> rad/s; gaitmap's foot "sensor frame" (z up at rest, x roughly along the foot) is kept.

Reference of the walk, from ``stride_events_sample.csv`` (IMU sample indices) and ``position_sample.csv`` (heel marker
per stride, metres, relative to the stride start):

- ``strides.csv``: ``t_start_s, t_end_s`` (min_vel to the next min_vel, i.e. mid-stance to mid-stance), ``foot``,
  ``length_m`` (horizontal norm of the stride's last position row), plus ``ic_s``, ``tc_s``;
- ``steps.csv``: ``t_s, foot`` of every initial contact (each stride's ``ic`` and ``pre_ic``, without duplicates);
- ``summary.toml``: ``n_strides``, ``n_steps``, ``stride_length_sum_left_m`` / ``_right_m``, ``distance_m`` (the mean of
  the two feet's stride-length sums: the walked distance covered by the reference strides), ``activity``.
The stair recordings have only ``summary.toml`` with ``activity = "stairs_up"`` / ``"stairs_down"``.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.io.importers._common import (
    imu_frame, numeric_array, read_table, require_finite, write_recordings,
)
from pdr.io.recording import Recording

DEFAULT_RATE_HZ = 204.8
WALK_FILE = "imu_sample.csv"
RECORDINGS = {  # file -> (recording name, activity label)
    WALK_FILE: ("walk_2x20m", "level_walk"),
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


def _walk_reference(folder: Path, rate_hz: float) -> dict[str, Any]:
    events_path, pos_path = folder / "stride_events_sample.csv", folder / "position_sample.csv"
    if not events_path.is_file():
        warnings.warn(f"{folder.name}: no stride_events_sample.csv; walk_2x20m has no stride reference", stacklevel=3)
        return {"summary": {"activity": "level_walk"}}
    ev = read_table(events_path, "stride_events_sample.csv")
    missing = [c for c in EVENT_COLUMNS if c not in ev.columns]
    if missing:
        raise InputError(f"stride_events_sample.csv: expected columns {', '.join(EVENT_COLUMNS)}, found {', '.join(map(str, ev.columns))}")
    num_cols = [c for c in EVENT_COLUMNS if c != "foot"]
    idx = numeric_array(ev[num_cols], "stride_events_sample.csv")
    require_finite(idx, "stride_events_sample.csv", ", ".join(num_cols))
    ev = pd.DataFrame(idx, columns=num_cols).assign(foot=ev["foot"].astype(str).str.strip().str.lower())
    if not ev["foot"].isin(("left", "right")).all():
        raise InputError("stride_events_sample.csv: expected foot 'left' or 'right', found "
                         f"{sorted(set(ev['foot']) - {'left', 'right'})}")
    lengths = np.full(len(ev), np.nan)
    if pos_path.is_file():
        pos = read_table(pos_path, "position_sample.csv")
        pos = pos.rename(columns={pos.columns[0]: "sensor"})
        need = ("sensor", "s_id", "sample", "pos_x", "pos_y")
        if any(c not in pos.columns for c in need):
            raise InputError(f"position_sample.csv: expected columns {', '.join(need)}, found {', '.join(map(str, pos.columns))}")
        xy = numeric_array(pos[["s_id", "sample", "pos_x", "pos_y"]], "position_sample.csv")
        pos = pd.DataFrame(xy, columns=["s_id", "sample", "pos_x", "pos_y"]).assign(
            foot=pos["sensor"].astype(str).map(SENSORS))
        last = pos.sort_values(["foot", "s_id", "sample"], kind="stable").groupby(["foot", "s_id"]).tail(1)
        norm = dict(zip(zip(last["foot"], last["s_id"]), np.hypot(last["pos_x"], last["pos_y"])))
        lengths = np.array([norm.get((f, s), np.nan) for f, s in zip(ev["foot"], ev["s_id"])])
    else:
        warnings.warn(f"{folder.name}: no position_sample.csv; stride lengths are unknown (NaN)", stacklevel=3)
    strides = pd.DataFrame({
        "t_start_s": ev["start"] / rate_hz, "t_end_s": ev["end"] / rate_hz, "foot": ev["foot"], "length_m": lengths,
        "ic_s": ev["ic"] / rate_hz, "tc_s": ev["tc"] / rate_hz, "s_id": ev["s_id"].astype(int),
    }).sort_values(["t_start_s", "foot"], kind="stable").reset_index(drop=True)
    ics = pd.concat([ev[["ic", "foot"]], ev[["pre_ic", "foot"]].rename(columns={"pre_ic": "ic"})], ignore_index=True)
    ics = ics.drop_duplicates().sort_values(["ic", "foot"], kind="stable")
    steps = pd.DataFrame({"t_s": ics["ic"].to_numpy() / rate_hz, "foot": ics["foot"].to_numpy()})
    sums = {foot: float(np.nansum(strides.loc[strides["foot"] == foot, "length_m"])) for foot in ("left", "right")}
    summary = {
        "activity": "level_walk",
        "n_strides": int(len(strides)),
        "n_steps": int(len(steps)),
        "stride_length_sum_left_m": sums["left"],
        "stride_length_sum_right_m": sums["right"],
        "distance_m": (sums["left"] + sums["right"]) / 2.0,
        "distance_source": "mean over the two feet of the mocap stride-length sums (heel marker, mid-stance to mid-stance)",
    }
    return {"steps": steps, "strides": strides, "summary": summary}


def _recording(path: Path, rate_hz: float | None) -> Recording:
    name, activity = RECORDINGS[path.name]
    first, feet = _two_header_table(path, path.name)
    if path.name == WALK_FILE:
        if rate_hz is None:
            warnings.warn(f"{path.name}: carries only a sample index and --rate-hz was not given; "
                          f"using {DEFAULT_RATE_HZ} Hz (the rate of the gaitmap example data)", stacklevel=3)
            rate_hz = DEFAULT_RATE_HZ
        if (np.diff(first) <= 0).any():
            raise InputError(f"{path.name}: expected an increasing sample index in the first column, found it out of order")
        t_s = (first - first[0]) / rate_hz
        reference = _walk_reference(path.parent, rate_hz)
    else:
        t_s = first
        file_rate = 1.0 / float(np.median(np.diff(t_s))) if len(t_s) > 1 else float("nan")
        if rate_hz is not None and abs(file_rate - rate_hz) > 0.01 * rate_hz:
            warnings.warn(f"{path.name}: its time column gives {file_rate:.1f} Hz; --rate-hz {rate_hz:g} is ignored", stacklevel=3)
        reference = {"summary": {"activity": activity}}
    imus = _feet_imus(t_s, feet)
    meta = {"recording": {"id": name, "placement": "foot_left", "source": "gaitmap"}}
    return Recording(meta=meta, imu=imus["left"], extra_imus={"foot_right": imus["right"]}, reference=reference)


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    if src.is_file():
        if src.name not in RECORDINGS:
            raise InputError(f"{src}: expected a gaitmap example folder or one of {', '.join(RECORDINGS)}, found {src.name}")
        files = [src]
    else:
        files = [src / n for n in RECORDINGS if (src / n).is_file()]
        if not files:
            raise InputError(f"{src}: expected a folder with gaitmap example CSVs ({', '.join(RECORDINGS)}), found none of them")
    return write_recordings([_recording(p, rate_hz) for p in files], dest, force=force)
