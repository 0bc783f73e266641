"""Strides from shoe-mounted IMUs (``imu_foot_left.csv`` / ``imu_foot_right.csv``, or ``imu.csv`` placed on a foot).

Configuration section ``[foot]``::

    [foot]
    method = "zupt_ins"          # or "footstep_tracker"
    double_feet = true           # DoubleFeetCalibration when both feet are present (default: footstep_tracker only)
    [foot.zero_velocity]         # ZeroVelocityDetection parameters
    [foot.zupt_ins]              # ZuptInsStride parameters (foot is set here)
    [foot.footstep_tracker]      # FootStepTrackerStride parameters
    [foot.double_feet_calibration]
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, check_keys
from pdr.foot import DoubleFeetCalibration, FootStepTrackerStride, ZeroVelocityDetection, ZuptInsStride
from pdr.foot._checks import check_pair, foot_imu_arrays, saturated_samples
from pdr.io.recording import Recording

STRIDE_COLUMNS = ["t_start_s", "t_end_s", "foot", "length_m", "length_std_m", "source"]
METHODS = {"zupt_ins": ZuptInsStride, "footstep_tracker": FootStepTrackerStride}
SECTION_KEYS = {"method", "double_feet", "zero_velocity", "zupt_ins", "footstep_tracker", "double_feet_calibration"}
GYR_SATURATION_MIN_RADPS = 4.0  # 230 deg/s: below this a flat top is a resting sensor, not a clipped one
ACC_SATURATION_MIN_MPS2 = 2.0 * 9.80665


def foot_imus(rec: Recording) -> dict[str, pd.DataFrame]:
    """The foot IMUs of a recording by foot (``"left"``, ``"right"``); empty when there is none."""
    return {placement[len("foot_"):]: imu for placement, imu in rec.imus_by_placement().items()
            if placement in ("foot_left", "foot_right")}


def _saturation(imu: pd.DataFrame, foot: str) -> np.ndarray:
    """Samples where the gyroscope or the accelerometer sits at its range (warns when any)."""
    _, acc, gyr = foot_imu_arrays(imu, f"{foot} foot IMU")
    gyr_sat = saturated_samples(gyr, min_abs=GYR_SATURATION_MIN_RADPS)
    acc_sat = saturated_samples(acc, min_abs=ACC_SATURATION_MIN_MPS2)
    if gyr_sat.any():
        warnings.warn(f"{foot} foot IMU: the gyroscope is saturated (flat at {np.abs(gyr).max():.2f} rad/s) in "
                      f"{int(gyr_sat.sum())} samples; strides across them are dropped", stacklevel=3)
    if acc_sat.any():
        warnings.warn(f"{foot} foot IMU: the accelerometer is saturated (flat at {np.abs(acc).max():.1f} m/s²) in "
                      f"{int(acc_sat.sum())} samples; strides across them are dropped", stacklevel=3)
    return gyr_sat | acc_sat


def foot_strides(rec: Recording, config: dict) -> pd.DataFrame | None:
    """Strides table (INTERFACES.md; ``source = "foot_imu"``) of the foot IMUs of ``rec``; None without a foot IMU.

    Extra columns: ``method``, ``heading_change_rad`` (the change of the stride direction since the previous stride of
    the same foot, from the foot INS; NaN for the first stride of a foot and for ``footstep_tracker``) and
    ``calibrated`` (the double-feet calibration was applied to the stride), ``t_swing_start_s, t_swing_end_s`` (when
    the foot moved).
    """
    imus = foot_imus(rec)
    if not imus:
        return None
    section: dict[str, Any] = dict((config or {}).get("foot", {}))
    check_keys(section, sorted(SECTION_KEYS), "configuration [foot]")
    method = section.get("method", "zupt_ins")
    if method not in METHODS:
        raise InputError(f"configuration [foot]: expected method one of {', '.join(METHODS)}, found {method!r}")
    if "left" in imus and "right" in imus:
        check_pair(imus["left"], imus["right"])
    tables = []
    for foot, imu in sorted(imus.items()):
        saturated = _saturation(imu, foot)
        stance = ZeroVelocityDetection.from_config(section.get("zero_velocity")).detect(imu)
        algo = METHODS[method].from_config(section.get(method), foot=foot)
        strides = algo.estimate(imu, stance=stance).strides_
        if saturated.any() and len(strides):
            t = imu["t_s"].to_numpy()
            t_sat = t[saturated]
            hit = np.array([((t_sat >= a) & (t_sat <= b)).any()
                            for a, b in zip(strides["t_start_s"], strides["t_end_s"])])
            strides = strides[~hit]
        extra = strides["heading_change_rad"] if "heading_change_rad" in strides else np.nan
        tables.append(strides[[*STRIDE_COLUMNS, "t_swing_start_s", "t_swing_end_s"]]
                      .assign(method=method, heading_change_rad=extra))
    out = pd.concat(tables, ignore_index=True)
    out = out.sort_values("t_start_s", kind="stable").reset_index(drop=True)
    out["calibrated"] = False
    # the INS alone beats its double-feet combination on the gaitmap strides (1.8 vs 2.0 cm), FootStep-Tracker does not
    if section.get("double_feet", method == "footstep_tracker") and out["foot"].nunique() == 2:
        cal = DoubleFeetCalibration.from_config(section.get("double_feet_calibration")).estimate(out)
        out = cal.strides_[out.columns]
    if len(out) == 0:
        warnings.warn("foot IMU: no stride found (the feet never rest, or fewer than two stances)", stacklevel=2)
    return out.reset_index(drop=True)
