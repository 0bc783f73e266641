"""HuMoLiRe (Ghaoui et al., IEEE Sensors J. 2023): a hand-held phone walk with surveyed landmarks.

Source: a sequence folder (``data/imus/<user>/<sequence>/``) with ``accelerometer-calibrated.txt`` (m/s², gravity
included), ``gyroscope-calibrated.txt`` (rad/s), ``keypoints.json`` (start + landmarks, metres, map frame) and
``references.txt`` (the time each landmark was passed). Recording name = the folder name (``square_2x``).

Clock: both sensors log irregularly (median 2 ms, mean ~418 Hz) on separate clocks; both are resampled onto one
uniform ``RESAMPLE_RATE_HZ`` grid on the shared ``elapsed-time-sensor`` clock (s since the recording started, the
monotonic one; ``elapsed-time-system``, on which the landmark clicks are logged, differs from it by 2-5 ms). Each
output sample is the mean over one output period (a box anti-alias filter, see ``resample_mean``). ``t_s`` keeps the
source clock, so reference times need no shift; ``start_unix_s`` is ``StartTime`` of ``record.properties``.

Reference (map frame: east = x, north = y, metres):

- ``landmarks.csv``: ``t_s, e_m, n_m`` of the landmarks in the order passed (8 for ``square_2x``);
- ``trajectory.csv``: the starting position at the first IMU sample, then the landmarks: the only known positions
  (the start is not a landmark: nobody clicked there);
- ``summary.toml``: ``distance_m`` (polyline start -> landmarks: 120.8 m for ``square_2x``), ``n_landmarks``,
  ``loop_closure`` (the last landmark is the start point).

Subject ``height_m`` comes from ``participant.txt`` (searched up to three folders above; the user is the sequence's
parent folder name) when it is there.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.io.importers._common import (
    imu_frame, numeric_array, read_table, require_dir, require_file, require_finite, resample_mean, safe_id, uniform_grid,
    write_recordings,
)
from pdr.io.recording import Recording

RESAMPLE_RATE_HZ = 200.0
TIME_COLUMN = "elapsed-time-sensor"
FILES = ("accelerometer-calibrated.txt", "gyroscope-calibrated.txt", "keypoints.json", "references.txt")
LOOP_CLOSURE_TOLERANCE_M = 0.05


def _header_row(path: Path, marker: str, what: str) -> int:
    require_file(path, what)
    try:
        with open(path, encoding="utf-8") as f:
            for i, line in enumerate(f):
                if line.strip().startswith(marker):
                    return i
                if i > 50:
                    break
    except UnicodeDecodeError:
        raise InputError(f"{what}: expected a text file, found binary content") from None
    raise InputError(f"{what}: expected a header line starting with {marker!r} in the first lines, found none")


def _sensor(path: Path, what: str) -> tuple[np.ndarray, np.ndarray]:
    row = _header_row(path, "elapsed-time-system", what)
    df = read_table(path, what, sep=r"\s+", skiprows=row)
    expected = ["elapsed-time-system", "elapsed-time-sensor", "x", "y", "z"]
    if list(df.columns) != expected:
        raise InputError(f"{what}: expected columns {' '.join(expected)}, found {' '.join(map(str, df.columns))}")
    a = numeric_array(df, what)
    require_finite(a, what, "all columns")
    t = a[:, 1]
    if (np.diff(t) <= 0).any():
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise InputError(f"{what}: expected a strictly increasing {TIME_COLUMN}, found {t[i]} after {t[i - 1]} in data row {i + 1}")
    if len(t) < 10:
        raise InputError(f"{what}: expected a recording of at least 10 samples, found {len(t)}")
    return t, a[:, 2:5]


def _keypoints(path: Path, what: str) -> tuple[tuple[float, float], np.ndarray]:
    require_file(path, what)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        start = (float(doc["starting_position"]["x"]), float(doc["starting_position"]["y"]))
        count = int(doc["count"])
        points = np.array([[float(doc[str(k)]["x"]), float(doc[str(k)]["y"])] for k in range(count)]).reshape(-1, 2)
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise InputError(f"{what}: expected JSON with starting_position {{x, y}}, count and landmarks \"0\".. {{x, y}}, "
                         f"found a problem at {exc!s:.60}") from None
    if not np.isfinite(points).all() or not all(map(math.isfinite, start)):
        raise InputError(f"{what}: expected finite landmark coordinates, found NaN or inf")
    return start, points


def _references(path: Path, what: str) -> np.ndarray:
    row = _header_row(path, "elapsed-time-system", what)
    try:
        df = pd.read_csv(path, sep=r"\s+", skiprows=row + 1, header=None)
    except pd.errors.EmptyDataError:
        return np.zeros(0)
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{what}: expected rows of landmark times, found unreadable content ({str(exc)[:80]})") from None
    t = numeric_array(df.iloc[:, :1], what)[:, 0]
    require_finite(t, what, "the landmark times")
    return t


def _subject(src: Path) -> dict[str, float]:
    for folder in list(src.parents)[:3]:
        path = folder / "participant.txt"
        if path.is_file():
            try:
                table = pd.read_csv(path, sep=r"\s+")
                row = table[table["number"].astype(str) == src.parent.name]
                height_cm = float(row["height"].iloc[0])
            except (KeyError, IndexError, ValueError, pd.errors.ParserError, UnicodeDecodeError):
                return {}
            return {"height_m": round(height_cm / 100.0, 4)} if 50 < height_cm < 250 else {}
    return {}


def _start_unix_s(src: Path) -> float | None:
    path = src / "record.properties"
    if not path.is_file():
        return None
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        key, _, value = line.partition("=")
        if key.strip() == "StartTime":
            try:
                return float(value)
            except ValueError:
                return None
    return None


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    require_dir(src, "humolire")
    missing = [n for n in FILES if not (src / n).is_file()]
    if missing:
        raise InputError(f"{src}: expected a HuMoLiRe sequence folder with {', '.join(FILES)}, found no {', '.join(missing)}")
    t_acc, acc = _sensor(src / FILES[0], f"{src.name}/{FILES[0]}")
    t_gyr, gyr = _sensor(src / FILES[1], f"{src.name}/{FILES[1]}")
    h = 1.0 / RESAMPLE_RATE_HZ
    t_first, t_last = max(t_acc[0], t_gyr[0]) + h / 2, min(t_acc[-1], t_gyr[-1]) - h / 2
    if t_last - t_first < 1.0:
        raise InputError(f"{src.name}: expected accelerometer and gyroscope to overlap for at least 1 s, found "
                         f"{max(t_last - t_first, 0.0):.3f} s")
    grid = uniform_grid(math.ceil(t_first * RESAMPLE_RATE_HZ) / RESAMPLE_RATE_HZ, t_last, RESAMPLE_RATE_HZ)
    imu = imu_frame(grid, resample_mean(grid, t_acc, acc, RESAMPLE_RATE_HZ), resample_mean(grid, t_gyr, gyr, RESAMPLE_RATE_HZ))

    start, points = _keypoints(src / FILES[2], f"{src.name}/{FILES[2]}")
    t_marks = _references(src / FILES[3], f"{src.name}/{FILES[3]}")
    if len(t_marks) != len(points):
        raise InputError(f"{src.name}/references.txt: expected one time per landmark of keypoints.json ({len(points)}), "
                         f"found {len(t_marks)}")
    if (np.diff(t_marks) <= 0).any():
        raise InputError(f"{src.name}/references.txt: expected increasing landmark times, found them out of order")
    landmarks = pd.DataFrame({"t_s": t_marks, "e_m": points[:, 0], "n_m": points[:, 1]})
    path_xy = np.vstack([start, points])
    trajectory = pd.DataFrame({"t_s": np.concatenate([[grid[0]], t_marks]), "e_m": path_xy[:, 0], "n_m": path_xy[:, 1]})
    summary: dict[str, Any] = {
        "distance_m": float(np.sum(np.linalg.norm(np.diff(path_xy, axis=0), axis=1))),
        "n_landmarks": int(len(points)),
        "loop_closure": bool(len(points) and np.linalg.norm(points[-1] - np.asarray(start)) < LOOP_CLOSURE_TOLERANCE_M),
        "distance_source": "polyline from the starting position through the landmarks (keypoints.json)",
    }
    meta: dict[str, Any] = {"recording": {"id": safe_id(src.name), "placement": "hand", "source": "humolire",
                                          "start_unix_s": _start_unix_s(src),
                                          "resampled_hz": RESAMPLE_RATE_HZ}}
    subject = _subject(src)
    if subject:
        meta["subject"] = subject
    rec = Recording(meta=meta, imu=imu,
                    reference={"landmarks": landmarks, "trajectory": trajectory, "summary": summary})
    return write_recordings([rec], dest, force=force)
