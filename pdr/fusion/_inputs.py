"""Checked, array-form inputs shared by the three fusion objects (graph, iSAM2, EKF).

Every public ``fuse`` goes through :func:`prepare`, so the three solvers see the same epochs, the same per-step
measurements and the same GNSS association, and bad input gives the same one-line message whichever is used.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.schema import GNSS_LOCAL_COLUMNS, TRAJECTORY_COLUMNS, require_table, wrap_rad

FUSION_STEP_COLUMNS = ("t_s", "step_length_m", "step_length_std_m")  # what the fusion reads of a steps table
FUSION_STRIDE_COLUMNS = ("t_start_s", "t_end_s", "length_m", "length_std_m")  # what it reads of a strides table
BOUT_START_HEADING_STD_RAD = 0.5  # heading change of a step whose change is unknown (a bout's first step without heading_rad)


@dataclass
class Problem:
    """The fusion problem in arrays. Epoch 0 is the start pose; epoch ``i + 1`` is the contact of step ``i``."""

    epoch_t_s: np.ndarray  # (N + 1,)
    step_length_m: np.ndarray  # (N,) from the steps table
    step_length_std_m: np.ndarray  # (N,)
    lateral_std_m: np.ndarray  # (N,) across the step
    gap: np.ndarray  # (N,) bool: the step spans a gap (missed steps, a stop): its length is barely known
    dtheta_rad: np.ndarray  # (N,) heading change of step i (epoch i -> i + 1)
    dtheta_std_rad: np.ndarray  # (N,)
    heading0_rad: float  # heading of the start pose (documented default: the first step's heading_rad)
    features: np.ndarray | None  # (N, 3) [1, step_freq_hz, acc_var_m2ps4] or None when the table lacks them
    mag_rad: np.ndarray  # (N,) absolute heading at epoch i + 1, NaN where absent
    mag_std_rad: np.ndarray  # (N,)
    gnss_n_rows: int = 0
    gnss_row: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # index into the caller's gnss rows
    gnss_t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gnss_en_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    gnss_std_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gnss_k: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # epoch before the fix
    gnss_alpha: np.ndarray = field(default_factory=lambda: np.zeros(0))  # fraction of the way to epoch k + 1
    stride_k: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), int))  # epochs at start and end
    stride_length_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stride_std_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stride_source: np.ndarray = field(default_factory=lambda: np.zeros(0, object))  # the record's ``source`` (str)

    @property
    def n_steps(self) -> int:
        return len(self.step_length_m)

    @property
    def step_duration_s(self) -> np.ndarray:
        return np.diff(self.epoch_t_s)


def _floats(df: pd.DataFrame, column: str, what: str) -> np.ndarray:
    try:
        return df[column].to_numpy(dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what}: expected numbers in column {column}, found {df[column].dtype} ({exc})") from None


def _column_or(df: pd.DataFrame, column: str, what: str, default: float) -> np.ndarray:
    return _floats(df, column, what) if column in df.columns else np.full(len(df), default)


def empty_trajectory() -> pd.DataFrame:
    return pd.DataFrame({c: np.zeros(0) for c in TRAJECTORY_COLUMNS})


def prepare(steps: pd.DataFrame, gnss: pd.DataFrame | None, strides: pd.DataFrame | None, *, t_start_s: float | None,
            default_step_length_std_m: float, default_heading_change_std_rad: float, default_h_acc_m: float,
            gnss_time_tolerance_s: float, lateral_std_m: float, max_step_duration_s: float,
            gap_speed_std_mps: float) -> Problem | None:
    """Check the tables and build the :class:`Problem`; ``None`` (with a warning) for a table of 0 steps.

    A step lasting more than ``max_step_duration_s`` (steps missed by the detector, a stop, the start after standing)
    is a *gap*: the displacement over it is known only to ``gap_speed_std_mps`` times its duration, along and across,
    so that GNSS, not the step model, says where the walker went."""
    require_table(steps, FUSION_STEP_COLUMNS, "steps")
    if "heading_change_rad" not in steps.columns and "heading_rad" not in steps.columns:
        raise InputError("steps: expected a heading_change_rad or heading_rad column, found neither")
    if len(steps) == 0:
        warn("fusion: the steps table is empty; the trajectory is empty")
        return None
    t = _floats(steps, "t_s", "steps")
    if not np.isfinite(t).all():
        raise InputError(f"steps: expected finite t_s, found {int((~np.isfinite(t)).sum())} non-finite value(s)")
    if len(t) > 1 and not (np.diff(t) > 0).all():
        bad = int(np.argmax(np.diff(t) <= 0))
        raise InputError(f"steps: expected strictly increasing t_s, found {float(t[bad + 1])!r} after {float(t[bad])!r} "
                         f"(row {bad + 1})")
    length = _floats(steps, "step_length_m", "steps")
    if not np.isfinite(length).all() or (length < 0).any():
        raise InputError(f"steps: expected finite step_length_m >= 0 (metres), found "
                         f"{int((~np.isfinite(length) | (length < 0)).sum())} bad value(s)")
    if length.max() > 3.0:
        raise InputError(f"steps: expected step_length_m in metres (a step is < 3 m), found {length.max():.3g}; "
                         "millimetres or centimetres?")
    length_std = _floats(steps, "step_length_std_m", "steps")
    length_std = np.where(np.isfinite(length_std) & (length_std > 0), length_std, default_step_length_std_m)

    heading = _column_or(steps, "heading_rad", "steps", np.nan)
    dtheta = _column_or(steps, "heading_change_rad", "steps", np.nan)
    dtheta_std = _column_or(steps, "heading_change_std_rad", "steps", np.nan)
    dtheta_std = np.where(np.isfinite(dtheta_std) & (dtheta_std > 0), dtheta_std, default_heading_change_std_rad)
    from_heading = wrap_rad(np.diff(heading, prepend=np.nan))
    missing = ~np.isfinite(dtheta)
    use_heading = missing & np.isfinite(from_heading)
    dtheta = np.where(use_heading, from_heading, dtheta)
    unknown = ~np.isfinite(dtheta)
    unknown[0] = False  # the first step defines the start heading
    dtheta_std = np.where(unknown, BOUT_START_HEADING_STD_RAD, dtheta_std)
    dtheta = np.where(np.isfinite(dtheta), dtheta, 0.0)
    dtheta[0] = 0.0
    heading0 = float(heading[0]) if np.isfinite(heading[0]) else 0.0

    if t_start_s is None:
        duration = _column_or(steps, "step_duration_s", "steps", np.nan)
        # the first step's duration, else the next one's (causal: only the first two steps), else half a second
        first = duration[0] if np.isfinite(duration[0]) and duration[0] > 0 else (
            float(t[1] - t[0]) if len(t) > 1 else 0.5)
        t_start_s = float(t[0] - first)
    elif not np.isfinite(t_start_s) or t_start_s >= t[0]:
        raise InputError(f"t_start_s: expected a finite time before the first step ({float(t[0])!r}), found {t_start_s!r}")

    features = None
    if "step_freq_hz" in steps.columns and "acc_var_m2ps4" in steps.columns:
        features = np.column_stack([np.ones(len(t)), _floats(steps, "step_freq_hz", "steps"),
                                    _floats(steps, "acc_var_m2ps4", "steps")])
    mag = _column_or(steps, "mag_heading_rad", "steps", np.nan)
    mag_std = _column_or(steps, "mag_heading_std_rad", "steps", np.nan)
    mag = np.where(np.isfinite(mag_std) & (mag_std > 0), mag, np.nan)

    epochs = np.concatenate([[t_start_s], t])
    # a step whose displacement was measured over its whole duration (a foot INS stride across a stop) is no gap
    measured = (steps["displacement_measured"].fillna(False).to_numpy(bool) if "displacement_measured" in steps.columns
                else np.zeros(len(t), bool))
    gap = (np.diff(epochs) > max_step_duration_s) & ~measured
    gap_std = gap_speed_std_mps * np.diff(epochs)
    length_std = np.where(gap, np.maximum(length_std, gap_std), length_std)
    own_lateral = _column_or(steps, "lateral_std_m", "steps", np.nan)
    lateral = np.where(np.isfinite(own_lateral) & (own_lateral > 0), own_lateral, lateral_std_m)
    lateral = np.where(gap, gap_std, lateral)
    problem = Problem(epoch_t_s=epochs, step_length_m=length, step_length_std_m=length_std, lateral_std_m=lateral, gap=gap,
                      dtheta_rad=dtheta, dtheta_std_rad=dtheta_std, heading0_rad=heading0, features=features,
                      mag_rad=mag, mag_std_rad=mag_std)
    if gnss is not None:
        _add_gnss(problem, gnss, default_h_acc_m, gnss_time_tolerance_s, gap_speed_std_mps)
    if strides is not None:
        _add_strides(problem, strides)
    return problem


def _add_gnss(problem: Problem, gnss: pd.DataFrame, default_h_acc_m: float, tolerance_s: float,
              gap_speed_std_mps: float) -> None:
    """Valid fixes -> (epoch k, fraction alpha). Documented defaults: rows with NaN position, NaN time, h_acc_m <= 0
    or ``masked`` are not used; a fix up to ``tolerance_s`` outside the walk is tied to the first / last pose, one
    further out is not used (warning); an exact duplicate row is used once (warning); two different fixes at the
    same time are an InputError. A fix inside a gap step gets ``gap_speed_std_mps`` times its time to the nearest
    epoch added (in quadrature) to its accuracy: the path inside a gap is not the straight line between its ends."""
    require_table(gnss, GNSS_LOCAL_COLUMNS, "gnss")
    problem.gnss_n_rows = len(gnss)
    if len(gnss) == 0:
        return
    t = _floats(gnss, "t_s", "gnss")
    en = np.column_stack([_floats(gnss, "e_m", "gnss"), _floats(gnss, "n_m", "gnss")])
    h_acc = _column_or(gnss, "h_acc_m", "gnss", default_h_acc_m)
    h_acc = np.where(np.isnan(h_acc), default_h_acc_m, h_acc)
    finite_t = t[np.isfinite(t)]
    if len(finite_t) > 1 and (np.diff(finite_t) < 0).any():
        bad = int(np.argmax(np.diff(finite_t) < 0))
        raise InputError(f"gnss: expected t_s in increasing order, found {float(finite_t[bad + 1])!r} after "
                         f"{float(finite_t[bad])!r}")
    valid = np.isfinite(t) & np.isfinite(en).all(axis=1) & np.isfinite(h_acc) & (h_acc > 0)
    if "masked" in gnss.columns:
        valid &= ~gnss["masked"].fillna(False).to_numpy(dtype=bool)
    if valid.any() and np.abs(en[valid]).max() > 1e6:
        raise InputError(f"gnss: expected local east/north in metres, found |e|,|n| up to {np.abs(en[valid]).max():.3g}; "
                         "degrees or unprojected coordinates?")
    idx = np.flatnonzero(valid)
    same = np.flatnonzero(np.diff(t[idx]) == 0)
    if len(same):
        a, b = idx[same], idx[same + 1]
        differ = (en[a] != en[b]).any(axis=1)
        if differ.any():
            i = int(a[np.argmax(differ)])
            raise InputError(f"gnss: expected one fix per time, found two different fixes at t_s = {float(t[i])!r}")
        warn(f"gnss: {len(b)} duplicated fix row(s) ignored")
        valid[b] = False
    tau = problem.epoch_t_s
    early = valid & (t < tau[0] - tolerance_s)
    late = valid & (t > tau[-1] + tolerance_s)
    if (early | late).any():
        warn(f"gnss: {int(early.sum())} fix(es) before the first step and {int(late.sum())} after the last one "
             f"(more than {tolerance_s} s) are not used")
        valid &= ~(early | late)
    idx = np.flatnonzero(valid)
    tc = np.clip(t[idx], tau[0], tau[-1])
    k = np.clip(np.searchsorted(tau, tc, side="right") - 1, 0, max(len(tau) - 2, 0))
    alpha = np.clip((tc - tau[k]) / (tau[k + 1] - tau[k]), 0.0, 1.0) if len(tau) > 1 else np.zeros(len(idx))
    std = h_acc[idx]
    if len(tau) > 1:
        away = np.minimum(tc - tau[k], tau[k + 1] - tc)
        std = np.where(problem.gap[k], np.hypot(std, gap_speed_std_mps * away), std)
    problem.gnss_row, problem.gnss_t_s, problem.gnss_en_m = idx, t[idx], en[idx]
    problem.gnss_std_m, problem.gnss_k, problem.gnss_alpha = std, k, alpha


def _add_strides(problem: Problem, strides: pd.DataFrame) -> None:
    """Stride records -> range constraints between the epochs nearest to their start and end (any source; the
    ``source`` column names it, ``"stride"`` where the table has none)."""
    require_table(strides, FUSION_STRIDE_COLUMNS, "strides")
    if len(strides) == 0:
        return
    t0, t1 = _floats(strides, "t_start_s", "strides"), _floats(strides, "t_end_s", "strides")
    length, std = _floats(strides, "length_m", "strides"), _floats(strides, "length_std_m", "strides")
    ok = np.isfinite(t0) & np.isfinite(t1) & np.isfinite(length) & np.isfinite(std) & (std > 0)
    if (ok & (t1 <= t0)).any():
        raise InputError("strides: expected t_end_s > t_start_s, found a stride that ends before it starts")
    if ok.any() and length[ok].max() > 5.0:
        raise InputError(f"strides: expected length_m in metres (a stride is < 5 m), found {length[ok].max():.3g}")
    tau = problem.epoch_t_s

    def nearest(x: np.ndarray) -> np.ndarray:
        j = np.clip(np.searchsorted(tau, x), 1, len(tau) - 1)
        return np.where(np.abs(tau[j - 1] - x) <= np.abs(tau[j] - x), j - 1, j)

    k0, k1 = nearest(t0[ok]), nearest(t1[ok])
    keep = k1 > k0
    problem.stride_k = np.column_stack([k0[keep], k1[keep]])
    problem.stride_length_m, problem.stride_std_m = length[ok][keep], std[ok][keep]
    source = (strides["source"].astype(object).where(strides["source"].notna(), "stride").astype(str).to_numpy(object)
              if "source" in strides.columns else np.full(len(strides), "stride", object))
    problem.stride_source = source[ok][keep]
