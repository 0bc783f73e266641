"""Per-step signal features that some step-length models need beyond the steps table of ``detect_steps``.

The steps table (CONTRACT.md) carries ``step_freq_hz`` and ``acc_var_m2ps4``, enough for the regression model.
Weinberg needs the range of the vertical acceleration over the step, Kim the mean absolute dynamic acceleration,
and Zijlstra's inverted pendulum the vertical excursion of the centre of mass. These are computed here from the
recording's main IMU (on its uniform grid, :func:`pdr.signals.uniform_imu`) and the step instants,
orientation-free: the vertical is the direction of the low-passed specific force (gravity), so a waist belt, a
phone in a pocket or a hand all work.

A step (row ``k``) is the interval from the previous foot contact of its bout to its own contact ``t_s[k]``; the
first step of a bout has no previous contact, so it takes the interval of the bout's median step duration before it.

Example
-------
>>> from pdr.io.recording import load_recording
>>> from pdr.step_length.features import with_signal_features
>>> steps = with_signal_features(steps, load_recording("rec"))  # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.signal import butter, sosfiltfilt

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.io.recording import Recording
from pdr.schema import require_table
from pdr.signals import ImuSignals, UniformImu, uniform_imu

SIGNAL_FEATURES = ("acc_range_mps2", "acc_abs_mean_mps2", "vertical_excursion_m")
DEFAULT_STEP_S = 1.0 / 1.8  # duration assumed for a lone step (typical cadence 108 steps/min)
GRAVITY_LOWPASS_HZ = 0.3  # the specific force below this is gravity (walking is at 1.4-2.5 Hz)
ACC_HIGHPASS_HZ = 0.1  # before the first integration (Zijlstra & Hof 2003, as in mobgap's SlZijlstra)
VEL_HIGHPASS_HZ = 1.0  # drift removal before the second integration (idem)
MIN_RATE_HZ = 10.0


def step_intervals(t_s: np.ndarray, bout_id: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Start and end time (s) of every step: from the previous contact of the same bout to the step's contact."""
    t_s = np.asarray(t_s, float)
    bout = np.zeros(len(t_s), int) if bout_id is None else np.asarray(bout_id)
    start = np.empty_like(t_s)
    if len(t_s) == 0:
        return start, t_s.copy()
    start[1:] = t_s[:-1]
    first = np.ones(len(t_s), bool)
    first[1:] = bout[1:] != bout[:-1]
    dur = t_s - start
    for b in np.unique(bout[first]):
        in_bout = (bout == b) & ~first
        d = float(np.median(dur[in_bout])) if in_bout.any() else DEFAULT_STEP_S
        start[(bout == b) & first] = t_s[(bout == b) & first] - d
    return start, t_s.copy()


def vertical_acceleration(u: UniformImu) -> tuple[np.ndarray, np.ndarray, float]:
    """Vertical dynamic acceleration (m/s², up positive, gravity removed) on the IMU's uniform grid
    (:func:`pdr.signals.uniform_imu`): ``(t_s, a_v, rate_hz)``. The vertical is the unit vector of the low-passed
    (``GRAVITY_LOWPASS_HZ``, zero phase) specific force.
    """
    rate = u.rate_hz
    if rate < MIN_RATE_HZ:
        raise InputError(f"imu: expected a sampling rate of at least {MIN_RATE_HZ:g} Hz for step features, found {rate:.1f} Hz")
    a = u.acc_mps2
    if len(a) > 12:
        pad = min(len(a) - 1, int(3 * rate / GRAVITY_LOWPASS_HZ))
        g = sosfiltfilt(butter(2, GRAVITY_LOWPASS_HZ, "lowpass", fs=rate, output="sos"), a, axis=0, padlen=pad)
    else:  # too short for the filter: one mean gravity vector
        g = np.broadcast_to(a.mean(axis=0), a.shape)
    up = g / np.linalg.norm(g, axis=1, keepdims=True)
    return u.t_s, np.einsum("ij,ij->i", a, up) - GRAVITY_MPS2, rate


def vertical_excursion_m(acc_vertical_mps2: np.ndarray, rate_hz: float, t0_s: float,
                         step_start_s: np.ndarray, step_end_s: np.ndarray) -> np.ndarray:
    """Vertical excursion (m) of the sensor over each step: peak-to-peak of the double-integrated vertical acceleration.

    Zijlstra & Hof (2003): high-pass the vertical acceleration (0.1 Hz), integrate to velocity, high-pass
    again (1 Hz) to remove drift, integrate to position; the excursion of a step is max - min over it.
    Filters are zero-phase (offline). ``acc_vertical_mps2`` is uniformly sampled from ``t0_s`` at ``rate_hz``.
    Steps outside the signal get NaN.
    """
    a = np.asarray(acc_vertical_mps2, float)
    n = len(a)
    out = np.full(len(step_start_s), np.nan)
    if n < 2:
        return out
    pad = min(n - 1, int(3 * rate_hz / ACC_HIGHPASS_HZ))
    a = sosfiltfilt(butter(4, ACC_HIGHPASS_HZ, "highpass", fs=rate_hz, output="sos"), a, padlen=pad)
    v = np.cumsum(a) / rate_hz
    v = sosfiltfilt(butter(4, VEL_HIGHPASS_HZ, "highpass", fs=rate_hz, output="sos"), v, padlen=pad)
    z = np.cumsum(v) / rate_hz
    i0 = np.round((np.asarray(step_start_s, float) - t0_s) * rate_hz).astype(int)
    i1 = np.round((np.asarray(step_end_s, float) - t0_s) * rate_hz).astype(int)
    for k, (s, e) in enumerate(zip(i0, i1)):
        if s >= 0 and e < n and e > s:
            seg = z[s:e + 1]
            out[k] = seg.max() - seg.min()
    return out


def step_signal_features(imu: pd.DataFrame | UniformImu, t_s: np.ndarray,
                         bout_id: np.ndarray | None = None) -> pd.DataFrame:
    """``acc_range_mps2`` (max - min vertical acceleration), ``acc_abs_mean_mps2`` (mean |vertical dynamic
    acceleration|) and ``vertical_excursion_m`` for the steps ending at ``t_s`` (one row each, NaN where the step
    lies outside the IMU record). ``imu``: an IMU table or its uniform resampling."""
    t_s = np.asarray(t_s, float)
    if len(t_s) and not np.isfinite(t_s).all():
        raise InputError("steps: expected finite t_s, found NaN or inf")
    if len(t_s) > 1 and (np.diff(t_s) <= 0).any():
        raise InputError("steps: expected t_s strictly increasing (sorted steps), found unsorted or repeated times")
    empty = pd.DataFrame({c: np.full(len(t_s), np.nan) for c in SIGNAL_FEATURES})
    if len(t_s) == 0:
        return empty
    grid, av, rate = vertical_acceleration(imu if isinstance(imu, UniformImu) else uniform_imu(imu))
    start, end = step_intervals(t_s, bout_id)
    exc = vertical_excursion_m(av, rate, grid[0], start, end)
    i0 = np.searchsorted(grid, start, side="left")
    i1 = np.searchsorted(grid, end, side="right")
    rng = np.full(len(t_s), np.nan)
    absmean = np.full(len(t_s), np.nan)
    ok = (start >= grid[0]) & (end <= grid[-1]) & (i1 - i0 >= 2)
    if ok.any():
        c_abs = np.concatenate([[0.0], np.cumsum(np.abs(av))])
        absmean[ok] = (c_abs[i1[ok]] - c_abs[i0[ok]]) / (i1[ok] - i0[ok])
        rng[ok] = [float(np.ptp(av[s:e])) for s, e in zip(i0[ok], i1[ok])]
    if (~ok).any():
        warn(f"step features: {int((~ok).sum())} step(s) lie outside the IMU record; their features are NaN")
    return pd.DataFrame({"acc_range_mps2": rng, "acc_abs_mean_mps2": absmean, "vertical_excursion_m": exc})


def with_signal_features(steps: pd.DataFrame, rec: Recording | pd.DataFrame,
                         signals: ImuSignals | None = None) -> pd.DataFrame:
    """A copy of ``steps`` with the columns of :data:`SIGNAL_FEATURES` added from ``rec`` (a Recording or an IMU
    table); ``signals``: its main IMU's shared signals (default: computed here)."""
    require_table(steps, ("t_s",), "steps")
    imu = rec.imu if isinstance(rec, Recording) else rec
    bout = steps["bout_id"].to_numpy() if "bout_id" in steps.columns else None
    feats = step_signal_features(imu if signals is None else signals.uniform, steps["t_s"].to_numpy(float), bout)
    out = steps.copy()
    for col in SIGNAL_FEATURES:
        out[col] = feats[col].to_numpy()
    return out
