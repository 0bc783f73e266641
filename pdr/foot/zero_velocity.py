"""Stance / swing segmentation of a foot IMU by zero-velocity detection."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.ndimage import uniform_filter1d

from pdr.base import Algorithm
from pdr.errors import warn
from pdr.foot._checks import MIN_SAMPLES, foot_imu_arrays

STANCE_COLUMNS = ["t_start_s", "t_end_s", "t_mid_s", "i_start", "i_end", "i_mid"]


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) indices of the runs of True in ``mask``."""
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def _white_noise_norm(x: np.ndarray) -> float:
    """White-noise level of the norm of a 3-axis signal from the 10th percentile of the sample-to-sample differences
    (the smooth motion of a foot hardly changes between two samples, the sensor noise does; the low quantile keeps
    the swings' fast changes out). For Gaussian noise of std s, |x[k+1] - x[k]| has its 10th percentile at
    0.1257 * sqrt(2) * s."""
    d = np.abs(np.diff(x, axis=0))
    sigma = float(np.percentile(d, 10)) / (0.1257 * np.sqrt(2.0))
    return sigma * np.sqrt(x.shape[1])


class ZeroVelocityDetection(Algorithm):
    """Stance (foot at rest on the ground) and swing phases of a shoe-mounted IMU.

    Parameters
    ----------
    window_s : length of the moving window of the detector; converted to samples with the sampling rate
        (at least 3 samples).
    gyr_threshold_radps : rms angular rate in the window below which the foot may be at rest.
    acc_threshold_mps2 : rms deviation of the specific force from its window mean (any orientation, any
        accelerometer scale error) below which the foot may be at rest.
    noise_factor : the thresholds are raised to ``noise_factor`` times the sensor's own white noise (from the
        low quantile of sample-to-sample differences, norm over the axes) when that is larger, so a noisy sensor
        does not lose its stances.
    swing_fraction : the angular-rate threshold follows the gait: it is lowered to ``swing_fraction`` times the
        typical peak angular rate of the swings around (running median over ``swing_window`` swings of a first
        detection) where that is below ``gyr_threshold_radps``. A slow walk turns the foot more slowly, in the swing
        and in the heel rise, so a fixed threshold keeps part of the heel rise (the foot already moving) in the
        stance. 0.14 leaves the real walks the fixed threshold was set on unchanged (swing peaks 8-14 rad/s:
        gaitmap walk and stairs, x-io; 0.125 already moved a gaitmap result by 0.5 mm); 0 disables it.
    swing_window : number of swings of that running median.
    min_stance_s : shorter rest phases are dropped (the foot passes through zero angular rate in mid-swing).
    min_swing_s : shorter motion bursts inside a stance (heel-strike shocks, a wobble) are merged into it.

    Attributes
    ----------
    stance_ : bool array, one per sample: True where the foot is at rest.
    stances_ : DataFrame ``t_start_s, t_end_s, t_mid_s, i_start, i_end, i_mid`` (``i_end`` exclusive), one row per
        stance phase; the swings lie between consecutive rows.
    statistic_ : the detector statistic per sample (dimensionless; below 1 means at rest).
    window_samples_ : the window length used, in samples.

    Notes
    -----
    The SHOE generalised-likelihood test (Skog et al. 2010, "Zero-velocity detection - an algorithm evaluation",
    eq. 21), ``T = mean_W(|w|^2) / gyr_thr^2 + mean_W(|f - g u|^2) / acc_thr^2`` with ``u`` the direction of the
    window's mean specific force; stance where ``T < 1``. ``g`` is the accelerometer's own reading of gravity (the
    median |f| over the 20% quietest samples), so a scale error of the accelerometer does not hide a stance.
    The thresholds (1.2 rad/s, 2.5 m/s^2) keep one stance per stride on level walking, stairs up and stairs
    down (gaitmap example data), the x-io and the OpenShoe loop walks; the 0.1 s window is the leave-one-recording-out
    choice of ``benchmarks/bench_foot.py`` (see :class:`ZuptInsStride`). Windows are in seconds and thresholds in
    physical units, so the strides do not depend on the sampling rate (tests: 100, 102.4 and 200 Hz copies). The gyroscope threshold scales with the swings' peak
    angular rate below that (``swing_fraction``; adaptive thresholds for varying gait speed as in Wagstaff,
    Peretroukhin & Kelly 2017, "Improving foot-mounted inertial navigation through real-time motion
    classification"): on simulated walks at 0.6-0.8 m/s the fixed threshold left up to 0.2 s of heel rise in every
    stance, and the zero-velocity updates there cost the foot INS 10-15 cm per stride.

    Examples
    --------
    >>> det = ZeroVelocityDetection().detect(imu)          # doctest: +SKIP
    >>> det.stances_[["t_start_s", "t_end_s"]].head()       # doctest: +SKIP
    """

    def __init__(self, *, window_s: float = 0.1, gyr_threshold_radps: float = 1.2, acc_threshold_mps2: float = 2.5,
                 noise_factor: float = 5.0, swing_fraction: float = 0.14, swing_window: int = 5,
                 min_stance_s: float = 0.06, min_swing_s: float = 0.2) -> None:
        self.window_s = window_s
        self.gyr_threshold_radps = gyr_threshold_radps
        self.acc_threshold_mps2 = acc_threshold_mps2
        self.noise_factor = noise_factor
        self.swing_fraction = swing_fraction
        self.swing_window = swing_window
        self.min_stance_s = min_stance_s
        self.min_swing_s = min_swing_s

    def detect(self, imu: pd.DataFrame) -> ZeroVelocityDetection:
        """Segment a canonical IMU table (``t_s``, ``acc_*_mps2``, ``gyr_*_radps``) into stance and swing."""
        t, acc, gyr = foot_imu_arrays(imu)
        n = len(t)
        self.stance_ = np.zeros(n, dtype=bool)
        self.statistic_ = np.full(n, np.inf)
        self.window_samples_ = 0
        self.stances_ = pd.DataFrame({c: pd.Series(dtype=float if c.startswith("t_") else int) for c in STANCE_COLUMNS})
        if n < MIN_SAMPLES:
            warn(f"foot IMU: {n} samples are too few for zero-velocity detection (need {MIN_SAMPLES}); "
                 "no stance found")
            return self
        rate = 1.0 / float(np.median(np.diff(t)))
        w = max(3, int(round(self.window_s * rate)))
        gyr_ms = uniform_filter1d((gyr**2).sum(axis=1), w, mode="nearest")
        acc_mean = uniform_filter1d(acc, w, axis=0, mode="nearest")
        norm = np.linalg.norm(acc, axis=1)
        quiet = gyr_ms <= np.percentile(gyr_ms, 20)
        g_local = float(np.median(norm[quiet]))  # the accelerometer's own reading of gravity
        up = acc_mean / np.maximum(np.linalg.norm(acc_mean, axis=1, keepdims=True), 1e-9)
        acc_ms = uniform_filter1d(((acc - g_local * up) ** 2).sum(axis=1), w, mode="nearest")
        gyr_floor = self.noise_factor * _white_noise_norm(gyr)
        gyr_thr = max(self.gyr_threshold_radps, gyr_floor)
        acc_thr = max(self.acc_threshold_mps2, self.noise_factor * _white_noise_norm(acc))
        stat = gyr_ms / gyr_thr**2 + acc_ms / acc_thr**2
        mask = self._clean(stat < 1.0, t)
        if self.swing_fraction > 0:
            local = self._swing_scaled_threshold(mask, np.linalg.norm(gyr, axis=1), t)
            if local is not None and (local < gyr_thr).any():
                gyr_thr = np.maximum(np.minimum(gyr_thr, local), gyr_floor)
                stat = gyr_ms / gyr_thr**2 + acc_ms / acc_thr**2
                mask = self._clean(stat < 1.0, t)
        starts, ends = _runs(mask)
        self.stance_, self.statistic_, self.window_samples_ = mask, stat, w
        if len(starts) == 0:
            warn(f"foot IMU: no stance (zero-velocity) phase in {t[-1] - t[0]:.1f} s: the foot never rests "
       f"(running, or the sensor is not on a foot); no strides")
            return self
        mid = (starts + ends - 1) // 2
        self.stances_ = pd.DataFrame({
            "t_start_s": t[starts], "t_end_s": t[ends - 1], "t_mid_s": t[mid],
            "i_start": starts.astype(int), "i_end": ends.astype(int), "i_mid": mid.astype(int),
        })
        motion = float(np.mean(~mask))
        if len(starts) < 2 and motion > 0.5:
            warn(f"foot IMU: only {len(starts)} stance phase(s) while the foot moves {motion:.0%} of the "
                 "time: the foot hardly ever rests (running?); strides need two stances")
        return self

    def _clean(self, mask: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Merge short motion bursts into stances, then drop short rests."""
        mask = mask.copy()
        n = len(mask)
        starts, ends = _runs(~mask)
        for s, e in zip(starts, ends):  # short motion inside a stance
            if s > 0 and e < n and t[e - 1] - t[s] < self.min_swing_s:
                mask[s:e] = True
        starts, ends = _runs(mask)
        for s, e in zip(starts, ends):  # short rests inside a swing
            if t[e - 1] - t[s] < self.min_stance_s:
                mask[s:e] = False
        return mask

    def _swing_scaled_threshold(self, mask: np.ndarray, gyr_norm: np.ndarray, t: np.ndarray) -> np.ndarray | None:
        """Per-sample angular-rate threshold ``swing_fraction`` x the running median of the swings' peak rates (None
        with fewer than two swings between stances)."""
        starts, ends = _runs(~mask)
        inner = (starts > 0) & (ends < len(mask))
        starts, ends = starts[inner], ends[inner]
        if len(starts) < 2:
            return None
        peaks = np.array([gyr_norm[s:e].max() for s, e in zip(starts, ends)])
        half = max(int(self.swing_window), 1) // 2
        med = np.array([np.median(peaks[max(k - half, 0):k + half + 1]) for k in range(len(peaks))])
        mid_t = 0.5 * (t[starts] + t[ends - 1])
        return self.swing_fraction * np.interp(t, mid_t, med)
