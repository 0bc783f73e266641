"""Mobilise-D TVS lab data as shipped by mobgap: a lower-back IMU with INDIP / stereophotogrammetry reference.

Source: a participant folder with ``data.mat`` and ``infoForAlgo.mat`` (see ``datasets/mobgap_lowerback_tvs_lab/README.md``),
read with ``scipy.io.loadmat(squeeze_me=True, struct_as_record=False)``. One recording per test and trial, named
``<test>_<trial>`` (``Test5_Trial1``); further time measures get a ``<TimeMeasure>_`` prefix.

Units: acc g -> m/s² (x 9.80665), gyr deg/s -> rad/s, mag µT, baro hPa; the unix ``Timestamp`` becomes ``t_s`` from the
first sample (``start_unix_s`` keeps the first time stamp). Placement ``waist`` (L5, belt). Subject from
``infoForAlgo``: ``height_m``, ``mass_kg``, ``sensor_height_m`` (SensorHeight), ``foot_length_m`` (FootSize).

Reference: the INDIP ``ContinuousWalkingPeriod`` bouts, or Stereophoto when INDIP has none (``summary.reference_system``
says which); no ``reference/`` at all when neither has a bout (warned).

- ``steps.csv``: ``t_s, foot`` of every initial contact with a known time (INDIP leaves a few as NaN: they count in
  ``summary.n_steps`` but have no row; ``n_steps_timed`` counts the rows);
- ``strides.csv``: ``t_start_s, t_end_s, foot, length_m`` from ``Stride_InitialContacts`` (INDIP: samples at 100 Hz,
  Stereophoto: seconds) and ``Stride_Length``; the foot is that of the initial contact that starts the stride;
- ``bouts.csv`` (an addition to CONTRACT.md's reference tables): ``t_start_s, t_end_s, length_m, n_initial_contacts,
  avg_stride_length_m, walking_speed_mps, step_length_sum_m`` per bout;
- ``summary.toml``: ``distance_m`` (sum of the bouts' ``Length``), ``step_length_sum_m`` (sum over bouts of
  ``AverageStrideLength x (initial contacts - 1) / 2``, as the dataset README; INDIP's ``Length`` is up to 27 % shorter on bouts with turns,
  so a step-based estimate should be compared with this one), ``n_steps``, ``n_strides``, ``n_bouts``,
  ``turn_angles_deg`` (signed), ``turn_start_s``, ``turn_end_s``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.io.importers._common import imu_frame, require_dir, require_file, write_recordings
from pdr.io.recording import Recording

REFERENCE_SYSTEMS = ("INDIP", "Stereophoto")  # in order of preference
STRIDE_ICS_IN_SAMPLES = {"INDIP": True, "Stereophoto": False}
SUBJECT_FIELDS = {"Height": ("height_m", 0.01), "Weight": ("mass_kg", 1.0), "SensorHeight": ("sensor_height_m", 0.01),
                  "FootSize": ("foot_length_m", 0.01)}


def _loadmat(path: Path, what: str) -> dict[str, Any]:
    import scipy.io

    require_file(path, what)
    try:
        return scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except Exception as exc:  # scipy raises ValueError, TypeError, MatReadError... on damaged files
        raise InputError(f"{what}: expected a MATLAB .mat file, found unreadable content ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0][:100] if str(exc) else ''})") from None


def _fields(obj: Any) -> list[str]:
    return list(getattr(obj, "_fieldnames", None) or [])


def _get(obj: Any, name: str, what: str) -> Any:
    if name not in _fields(obj):
        raise InputError(f"{what}: expected a field {name!r}, found {', '.join(_fields(obj)) or 'no fields'}")
    return getattr(obj, name)


def _floats(obj: Any, name: str) -> np.ndarray:
    value = getattr(obj, name, None)
    if value is None:
        return np.zeros(0)
    try:
        return np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    except (TypeError, ValueError):
        return np.zeros(0)


def _scalar(obj: Any, name: str) -> float:
    v = _floats(obj, name)
    return float(v[0]) if v.size == 1 else math.nan


def _bouts(system: Any) -> list[Any]:
    cwp = getattr(system, "ContinuousWalkingPeriod", None)
    if cwp is None:
        return []
    if _fields(cwp):
        return [cwp]
    return [b for b in np.atleast_1d(cwp).ravel() if _fields(b)]


def _signal(lb: Any, name: str, n: int, cols: int, what: str) -> np.ndarray | None:
    if name not in _fields(lb):
        return None
    try:
        arr = np.asarray(getattr(lb, name), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected numbers in {name}, found {type(getattr(lb, name)).__name__}") from None
    if arr.size == 0:
        return None
    arr = arr.reshape(len(arr), -1) if arr.ndim > 1 else arr.reshape(-1, 1)
    if arr.shape != (n, cols):
        raise InputError(f"{what}: expected {name} of shape ({n}, {cols}) like Timestamp, found {arr.shape}")
    return arr


def _reference(standards: Any, what: str) -> dict[str, Any]:
    chosen = None
    for name in REFERENCE_SYSTEMS:
        system = getattr(standards, name, None) if standards is not None else None
        if system is not None and _bouts(system):
            chosen = name
            break
    if chosen is None:
        warn(f"{what}: no walking bout in any reference system ({', '.join(REFERENCE_SYSTEMS)}); no reference/ written")
        return {}
    system = getattr(standards, chosen)
    fs = _scalar(system, "Fs")
    fs = fs if math.isfinite(fs) and fs > 0 else 100.0
    steps, strides, bouts = [], [], []
    turns: list[tuple[float, float, float]] = []
    for b in _bouts(system):
        ic_t = _floats(b, "InitialContact_Event")
        lr = np.atleast_1d(np.asarray(getattr(b, "InitialContact_LeftRight", []), dtype=object)).ravel()
        feet = np.array([str(x).strip().lower() for x in lr]) if lr.size == ic_t.size else np.full(ic_t.size, "unknown")
        ok = np.isfinite(ic_t)
        steps.append(pd.DataFrame({"t_s": ic_t[ok], "foot": feet[ok]}))
        pairs = _floats(b, "Stride_InitialContacts")
        lengths = _floats(b, "Stride_Length")
        if pairs.size and pairs.size == 2 * lengths.size:
            pairs = pairs.reshape(-1, 2) / (fs if STRIDE_ICS_IN_SAMPLES[chosen] else 1.0)
            for (t0, t1), length in zip(pairs, lengths):
                if not (np.isfinite(t0) and np.isfinite(t1) and np.isfinite(length)) or t1 <= t0:
                    continue
                foot = "unknown"
                if ic_t[ok].size:
                    k = int(np.argmin(np.abs(ic_t[ok] - t0)))
                    if abs(ic_t[ok][k] - t0) <= 1.5 / fs:
                        foot = feet[ok][k]
                strides.append((t0, t1, foot, length))
        n_ic = int(ic_t.size)  # contacts whose time INDIP could not resolve (NaN) still count as steps
        avg_stride = _scalar(b, "AverageStrideLength")
        bouts.append({"t_start_s": _scalar(b, "Start"), "t_end_s": _scalar(b, "End"), "length_m": _scalar(b, "Length"),
                      "n_initial_contacts": n_ic, "avg_stride_length_m": avg_stride,
                      "walking_speed_mps": _scalar(b, "WalkingSpeed"),
                      "step_length_sum_m": avg_stride * max(n_ic - 1, 0) / 2.0})
        angles, t_start, t_end = _floats(b, "Turn_Angle"), _floats(b, "Turn_Start"), _floats(b, "Turn_End")
        for j, angle in enumerate(angles):
            turns.append((t_start[j] if j < t_start.size else math.nan, t_end[j] if j < t_end.size else math.nan, angle))
    steps_df = pd.concat(steps, ignore_index=True).sort_values("t_s", kind="stable").reset_index(drop=True)
    strides_df = pd.DataFrame(strides, columns=["t_start_s", "t_end_s", "foot", "length_m"])
    bouts_df = pd.DataFrame(bouts)
    if bouts_df["length_m"].isna().any():
        warn(f"{what}: {int(bouts_df['length_m'].isna().sum())} {chosen} bout(s) without a Length; "
             "distance_m sums the others")
    summary = {
        "reference_system": chosen,
        "distance_m": float(np.nansum(bouts_df["length_m"])),
        "step_length_sum_m": float(np.nansum(bouts_df["step_length_sum_m"])),
        "n_steps": int(bouts_df["n_initial_contacts"].sum()),
        "n_steps_timed": int(len(steps_df)),
        "n_strides": int(len(strides_df)),
        "n_bouts": int(len(bouts_df)),
        "turn_angles_deg": [float(a) for _, _, a in turns],
        "turn_start_s": [float(s) for s, _, _ in turns],
        "turn_end_s": [float(e) for _, e, _ in turns],
    }
    return {"steps": steps_df, "strides": strides_df, "bouts": bouts_df, "summary": summary}


def _subject(info: Any) -> dict[str, float]:
    subject = {}
    for field, (key, scale) in SUBJECT_FIELDS.items():
        v = _scalar(info, field) if info is not None else math.nan
        if math.isfinite(v) and v > 0:
            subject[key] = round(v * scale, 6)
    return subject


def _trial(tm_name: str, test: str, trial: str, tr: Any, subject: dict[str, float], what: str) -> Recording:
    lb = _get(_get(tr, "SU", what), "LowerBack", what)
    try:
        stamp = np.asarray(_get(lb, "Timestamp", what), dtype=float).ravel()
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected numbers in Timestamp") from None
    n = stamp.size
    if n < 2:
        raise InputError(f"{what}: expected a recording of at least 2 samples, found {n}")
    acc = _signal(lb, "Acc", n, 3, what)
    if acc is None:
        raise InputError(f"{what}: expected an Acc signal, found none")
    gyr = _signal(lb, "Gyr", n, 3, what)
    mag = _signal(lb, "Mag", n, 3, what)
    bar = _signal(lb, "Bar", n, 1, what)
    imu = imu_frame(stamp - stamp[0], acc * GRAVITY_MPS2, None if gyr is None else np.radians(gyr), mag,
                    None if bar is None else bar[:, 0])
    rec_id = f"{test}_{trial}" if tm_name == "TimeMeasure1" else f"{tm_name}_{test}_{trial}"
    meta: dict[str, Any] = {"recording": {"id": rec_id, "placement": "waist", "source": "mobgap",
                                          "start_unix_s": float(stamp[0])}}
    if subject:
        meta["subject"] = subject
    return Recording(meta=meta, imu=imu, reference=_reference(getattr(tr, "Standards", None), what))


def import_source(src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False) -> list[Path]:
    require_dir(src, "mobgap")
    data = _loadmat(src / "data.mat", f"{src.name}/data.mat")
    info_mat = _loadmat(src / "infoForAlgo.mat", f"{src.name}/infoForAlgo.mat")
    if "data" not in data:
        raise InputError(f"{src.name}/data.mat: expected a variable 'data', found {', '.join(k for k in data if not k.startswith('__'))}")
    root = data["data"]
    time_measures = [f for f in _fields(root) if f.startswith("TimeMeasure")]
    if not time_measures:
        raise InputError(f"{src.name}/data.mat: expected data.TimeMeasure1..., found {', '.join(_fields(root)) or 'no fields'}")
    info_root = info_mat.get("infoForAlgo")
    recs = []
    for tm_name in time_measures:
        subject = _subject(getattr(info_root, tm_name, None) if info_root is not None else None)
        tm = getattr(root, tm_name)
        for test in _fields(tm):
            for trial in _fields(getattr(tm, test)):
                what = f"{src.name}/data.mat {tm_name}.{test}.{trial}"
                recs.append(_trial(tm_name, test, trial, getattr(getattr(tm, test), trial), subject, what))
    if not recs:
        raise InputError(f"{src.name}/data.mat: expected at least one test and trial, found none")
    return write_recordings(recs, dest, force=force)
