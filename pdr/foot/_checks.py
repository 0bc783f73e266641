"""Input checks shared by the foot algorithms: a canonical IMU table with gyroscope, pairs of feet."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.recording import ACC_COLUMNS, GYR_COLUMNS, check_time
from pdr.schema import require_table

MIN_SAMPLES = 20


def foot_imu_arrays(imu: pd.DataFrame, what: str = "foot IMU") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t_s, acc_mps2 (N,3), gyr_radps (N,3))`` of a canonical IMU table; InputError when it cannot be a foot IMU."""
    require_table(imu, ("t_s", *ACC_COLUMNS, *GYR_COLUMNS), f"{what} (accelerometer and gyroscope)")
    t = imu["t_s"].to_numpy(dtype=float)
    check_time(t, what, min_rows=2)
    acc = imu[list(ACC_COLUMNS)].to_numpy(dtype=float)
    gyr = imu[list(GYR_COLUMNS)].to_numpy(dtype=float)
    if not (np.isfinite(acc).all() and np.isfinite(gyr).all()):
        raise InputError(f"{what}: expected finite acceleration and angular rate, found NaN/inf samples")
    return t, acc, gyr


def check_pair(left: pd.DataFrame, right: pd.DataFrame, *, max_offset_s: float = 0.5,
               max_length_ratio: float = 1.2) -> None:
    """Left and right foot IMUs must share one clock (CONTRACT.md): InputError when they clearly do not."""
    tl, tr = left["t_s"].to_numpy(dtype=float), right["t_s"].to_numpy(dtype=float)
    if len(tl) < 2 or len(tr) < 2:
        return
    dl, dr = tl[-1] - tl[0], tr[-1] - tr[0]
    overlap = min(tl[-1], tr[-1]) - max(tl[0], tr[0])
    if overlap <= 0:
        raise InputError(
            f"left/right foot IMUs: expected one shared clock, found disjoint time spans "
            f"(left {tl[0]:.3f}-{tl[-1]:.3f} s, right {tr[0]:.3f}-{tr[-1]:.3f} s)"
        )
    if max(dl, dr) > max_length_ratio * min(dl, dr):
        raise InputError(
            f"left/right foot IMUs: expected one shared clock and about the same span, found left "
            f"{tl[0]:.3f}-{tl[-1]:.3f} s ({len(tl)} samples) and right {tr[0]:.3f}-{tr[-1]:.3f} s ({len(tr)} samples)"
        )
    if abs(tl[0] - tr[0]) > max_offset_s or abs(tl[-1] - tr[-1]) > max_offset_s:
        warn(f"left/right foot IMUs start or end more than {max_offset_s:g} s apart (left {tl[0]:.3f}-{tl[-1]:.3f} s, "
   f"right {tr[0]:.3f}-{tr[-1]:.3f} s); only the overlap {max(tl[0], tr[0]):.3f}-{min(tl[-1], tr[-1]):.3f} s "
   f"is combined by the double-feet calibration")
