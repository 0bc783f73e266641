"""Handling the phone (taken out, put away, turned in the hand): its attitude against the vertical turns."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError
from pdr.signals.attitude import gravity_direction_lowpass
from pdr.signals.resample import UniformImu, runs

HANDLING_COLUMNS = ["t_start_s", "t_end_s", "turn_deg"]


class AttitudeHandlingDetection(Algorithm):
    """Intervals in which the phone is handled: the gravity direction in its frame, averaged over a stride, turns.

    Parameters
    ----------
    stride_window_s : the specific force is averaged over this, the longest stride (two steps at the lowest
        cadence, 1 step/s), so the gait's oscillation cancels and gravity in the sensor frame remains.
    min_turn_deg : a turn of at least this between the mean gravity direction over the window before an instant and
        the one over the window after it is handling. Walking barely turns that mean: the hip's flexion-extension
        spans about 40° over a stride (Winter 2009, *Biomechanics and motor control of human movement*) and only a few
        degrees of it survive the average; a turn at a corner is about the vertical, which gravity does not see.
        Taking a phone out of a trouser pocket (upright) to read it (screen 20-60° from level) turns it by 30-70°.
    peak_fraction : a handling interval is where the turn is at least this fraction of its peak. A quick turn
        makes a triangle a window wide on each side of it; a longer movement rounds its top. 3/4 of the peak lies a
        quarter window (about one step) beyond the movement.

    Attributes
    ----------
    intervals_ : DataFrame ``t_start_s, t_end_s, turn_deg`` (the peak turn of each interval).
    handling_ : per-sample flag on ``t_s_``.
    turn_deg_ : the turn at each sample (degrees).
    t_s_ : the uniform grid.

    Notes
    -----
    Needs only the accelerometer (no gyroscope), so it works on every phone export. A turn alone is not proof of
    handling (an armband can turn by 30° over a few strides of steady walking): the step detector leaves out only
    the handling outside the core of a walking bout (:func:`pdr.steps.gait.core_walking`), where the acceleration is
    not gait-periodic.

    Example
    -------
    >>> det = AttitudeHandlingDetection().detect(uniform_imu(rec.imu))   # doctest: +SKIP
    >>> det.intervals_                                                    # doctest: +SKIP
    """

    def __init__(self, *, stride_window_s: float = 2.0, min_turn_deg: float = 30.0, peak_fraction: float = 0.75):
        self.stride_window_s = stride_window_s
        self.min_turn_deg = min_turn_deg
        self.peak_fraction = peak_fraction

    def detect(self, u: UniformImu) -> "AttitudeHandlingDetection":
        if not (self.stride_window_s > 0 and 0 < self.min_turn_deg < 180 and 0 < self.peak_fraction <= 1):
            raise InputError(f"handling: expected stride_window_s > 0, 0 < min_turn_deg < 180, 0 < peak_fraction <= 1, "
                             f"found {self.stride_window_s}, {self.min_turn_deg}, {self.peak_fraction}")
        n = len(u)
        self.t_s_ = u.t_s
        up = gravity_direction_lowpass(u.acc_mps2, u.rate_hz, self.stride_window_s)
        half = int(round(0.5 * self.stride_window_s * u.rate_hz))
        i = np.arange(n)
        before, after = up[np.clip(i - half, 0, n - 1)], up[np.clip(i + half, 0, n - 1)]
        self.turn_deg_ = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", before, after), -1.0, 1.0)))
        self.handling_ = np.zeros(n, bool)
        rows = []
        for a, b in runs((self.turn_deg_ >= self.min_turn_deg) & u.valid):
            peak = a + int(np.argmax(self.turn_deg_[a:b]))
            if self.handling_[peak]:
                continue  # inside the interval of an earlier, higher peak
            high = self.turn_deg_ >= self.peak_fraction * self.turn_deg_[peak]
            lo, hi = next((x, y) for x, y in runs(high) if x <= peak < y)
            self.handling_[lo:hi] = True
            rows.append((float(u.t_s[lo]), float(u.t_s[hi - 1]), float(self.turn_deg_[peak])))
        self.intervals_ = pd.DataFrame(rows, columns=HANDLING_COLUMNS)
        return self
