"""Handling the phone (taken out, put away, turned in the hand): its attitude against the vertical turns."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.signals.attitude import gravity_direction_lowpass
from pdr.signals.resample import UniformImu, moving_average, runs

HANDLING_COLUMNS = ["t_start_s", "t_end_s", "turn_deg"]


def live_gyroscope(u: UniformImu) -> np.ndarray | None:
    """The angular rate of ``u`` (rad/s), or None without a gyroscope or with a dead one: every axis reading one
    constant value on every valid sample (an export that writes zeros for a sensor it did not read; a real
    gyroscope's noise and the walker's own turning never leave all three axes constant). A dead gyroscope is
    warned about and treated as absent, so the handling is timed from the accelerometer instead of never found
    (no tilt rate would ever reach a move's)."""
    if u.gyr_radps is None:
        return None
    gyr = u.gyr_radps[u.valid] if u.valid.any() else u.gyr_radps
    if len(gyr) and np.all(np.ptp(gyr, axis=0) == 0.0):
        warn(f"handling: the gyroscope reads a constant {gyr[0].tolist()} rad/s on every sample (dead or not "
             f"recorded): ignored, the phone's handling is found from the accelerometer alone")
        return None
    return u.gyr_radps


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
    min_tilt_rate_radps, settled_tilt_rate_radps : with a gyroscope, the accelerometer's interval is only a
        candidate (its turn at least half of ``min_turn_deg``: a move as long as two windows keeps about half its
        turn in the windowed measure), and the gyroscope times it. The phone's tilt rate is its angular rate about
        a horizontal axis (the component perpendicular to gravity: the walk's turns, about the vertical, do not
        count). The move is the samples of the candidate where the tilt rate is at least ``min_tilt_rate_radps``
        (none: a slow tilt of the sensor, not a move of the hand), widened to where the tilt rate falls below
        ``settled_tilt_rate_radps``, at most a quarter window beyond the candidate (a phone in a pocket swings with
        the thigh while the walker walks); it is handling when the mean
        specific force over the window before it and the one over the window after it (windows that no longer
        straddle the move) turn by ``min_turn_deg`` or more. Both rates are the trunk's, which carries the phone:
        the thorax's sagittal tilt spans 4.0° (SD 1.8°) against the ground, twice a stride, and its obliquity 3.3°
        (SD 1.4°), once (Chung et al. 2010, *J. NeuroEng. Rehabil.* 7:9, 20 adults); a sine of 4.0° at 1.8 steps/s
        turns at most 0.4 rad/s (the phone has settled when it turns no faster than a walker's trunk), one of 7.6°
        (two SD up) 0.75 rad/s (a move is faster than nearly every walker's trunk). Taking a phone out of a pocket
        turns it by 90-180° in 0.5-1 s (1.6-6 rad/s on average).

    Attributes
    ----------
    intervals_ : DataFrame ``t_start_s, t_end_s, turn_deg`` (the peak turn of each interval; with a gyroscope the
        turn from the window before the move to the one after it).
    handling_ : per-sample flag on ``t_s_``.
    turn_deg_ : the turn at each sample (degrees).
    gyroscope_used_ : whether a live gyroscope timed the intervals (:func:`live_gyroscope`).
    t_s_ : the uniform grid.

    Notes
    -----
    Needs only the accelerometer, so it works on every phone export; a gyroscope, where there is one, times the
    intervals to the sample (instead of to a quarter window) and measures their turn outside the move. A turn alone
    is not proof of handling (an armband can turn by 30° over a few strides of steady walking): the step detector leaves out only
    the handling outside the core of a walking bout (:func:`pdr.steps.gait.core_walking`), where the acceleration is
    not gait-periodic.

    Example
    -------
    >>> det = AttitudeHandlingDetection().detect(uniform_imu(rec.imu))   # doctest: +SKIP
    >>> det.intervals_                                                    # doctest: +SKIP
    """

    def __init__(self, *, stride_window_s: float = 2.0, min_turn_deg: float = 30.0, peak_fraction: float = 0.75,
                 min_tilt_rate_radps: float = 0.75, settled_tilt_rate_radps: float = 0.4):
        self.stride_window_s = stride_window_s
        self.min_turn_deg = min_turn_deg
        self.peak_fraction = peak_fraction
        self.min_tilt_rate_radps = min_tilt_rate_radps
        self.settled_tilt_rate_radps = settled_tilt_rate_radps

    def detect(self, u: UniformImu) -> "AttitudeHandlingDetection":
        if not (self.stride_window_s > 0 and 0 < self.min_turn_deg < 180 and 0 < self.peak_fraction <= 1
                and 0 < self.settled_tilt_rate_radps <= self.min_tilt_rate_radps):
            raise InputError(f"handling: expected stride_window_s > 0, 0 < min_turn_deg < 180, 0 < peak_fraction <= 1, "
                             f"0 < settled_tilt_rate_radps <= min_tilt_rate_radps, found {self.stride_window_s}, "
                             f"{self.min_turn_deg}, {self.peak_fraction}, {self.settled_tilt_rate_radps}, "
                             f"{self.min_tilt_rate_radps}")
        n = len(u)
        self.t_s_ = u.t_s
        up = gravity_direction_lowpass(u.acc_mps2, u.rate_hz, self.stride_window_s)
        half = int(round(0.5 * self.stride_window_s * u.rate_hz))
        i = np.arange(n)
        before, after = up[np.clip(i - half, 0, n - 1)], up[np.clip(i + half, 0, n - 1)]
        self.turn_deg_ = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", before, after), -1.0, 1.0)))
        gyr = live_gyroscope(u)
        self.gyroscope_used_ = gyr is not None
        tilt_rate = None if gyr is None else np.linalg.norm(np.cross(gyr, up), axis=1)
        candidate_deg = self.min_turn_deg if tilt_rate is None else 0.5 * self.min_turn_deg
        self.handling_ = np.zeros(n, bool)
        seen = np.zeros(n, bool)
        rows = []
        for a, b in runs((self.turn_deg_ >= candidate_deg) & u.valid):
            peak = a + int(np.argmax(self.turn_deg_[a:b]))
            if seen[peak]:
                continue  # inside the interval of an earlier, higher peak
            high = self.turn_deg_ >= self.peak_fraction * self.turn_deg_[peak]
            lo, hi = next((x, y) for x, y in runs(high) if x <= peak < y)
            seen[lo:hi] = True
            turn_deg = float(self.turn_deg_[peak])
            if tilt_rate is not None:
                timed = self._gyro_timed(u, tilt_rate, lo, hi)
                if timed is None:
                    continue
                lo, hi, turn_deg = timed
            if turn_deg < self.min_turn_deg:
                continue
            self.handling_[lo:hi] = True
            rows.append((float(u.t_s[lo]), float(u.t_s[hi - 1]), turn_deg))
        self.intervals_ = pd.DataFrame(rows, columns=HANDLING_COLUMNS)
        return self

    def _gyro_timed(self, u: UniformImu, tilt_rate: np.ndarray, lo: int, hi: int) -> tuple[int, int, float] | None:
        """The move inside the candidate ``[lo, hi)`` timed by the tilt rate, and the turn of the mean specific force
        from the window before it to the one after it (see ``min_tilt_rate_radps``); None without a fast tilt."""
        n = len(u)
        fast = lo + np.flatnonzero((tilt_rate[lo:hi] >= self.min_tilt_rate_radps) & u.valid[lo:hi])
        if not len(fast):
            return None
        reach = int(round(0.25 * self.stride_window_s * u.rate_hz))
        settled = (tilt_rate < self.settled_tilt_rate_radps) | ~u.valid
        first, last = max(0, lo - reach), min(n, hi + reach)
        before = np.flatnonzero(settled[first:fast[0]])
        after = np.flatnonzero(settled[fast[-1]:last])
        start = first + int(before[-1]) + 1 if len(before) else first
        stop = int(fast[-1]) + int(after[0]) if len(after) else last
        window = int(round(self.stride_window_s * u.rate_hz))
        if start == 0 or stop == n:
            return start, stop, float(self.turn_deg_[lo + int(np.argmax(self.turn_deg_[lo:hi]))])
        g0 = u.acc_mps2[max(0, start - window):start].mean(axis=0)
        g1 = u.acc_mps2[stop:stop + window].mean(axis=0)
        cos = g0 @ g1 / max(np.linalg.norm(g0) * np.linalg.norm(g1), 1e-12)
        return start, stop, float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


IMPACT_HIGHPASS_S = 0.1  # the foot's contact transient at the trunk rises in 10-30 ms; a hand's reach lasts 0.5-1 s
MIN_IMPACT_RATIO = 0.5  # a step taken during a move: its impact at least this fraction of the bout's steps'


def contact_impacts(u: UniformImu) -> np.ndarray:
    """The norm of the specific force minus its mean over :data:`IMPACT_HIGHPASS_S` (m/s²). To first order in a/g
    the norm is g plus the acceleration's vertical component, whatever the phone's attitude while it turns (a
    horizontal acceleration a_h enters only as a_h²/2g), so no attitude is needed and an accelerometer alone will do.
    What is left after the high-pass is the foot contacts' transients, sharp upward peaks (the heel-strike transient
    at the trunk rises within a few tens of ms: Whittle 1999, *Gait Posture* 10:264), not the hand's reach (a smooth,
    minimum-jerk movement of 0.5-1 s: Flash & Hogan 1985). On the simulated tuning walks (setting off, seeds 100-129,
    with a gyroscope) it keeps the same steps as the earth-vertical force of a VQF attitude did (mean count error 3.36%
    against 3.43%), without an attitude filter."""
    norm = np.linalg.norm(u.acc_mps2, axis=1)
    return norm - moving_average(norm, max(1, int(round(IMPACT_HIGHPASS_S * u.rate_hz))))


def steps_continuing_the_gait(u: UniformImu, impacts: np.ndarray, maxima_s: np.ndarray, kept_s: np.ndarray,
                              step_s: float, ref_steps: int = 6) -> np.ndarray:
    """``kept_s`` (a bout's steps, the handling's maxima left out) with back the left-out maxima (``maxima_s`` not in
    ``kept_s``) that continue the bout by one step at its start or end: the walker set off (or began to stop) while
    the phone still turned in the hand.

    The candidate is the maximum nearest one step period ``step_s`` before the bout's first kept step (after its
    last), within a quarter step (the step-time variability of a few percent, Hausdorff 2005; the first step of
    gait initiation is a little quicker or slower than the steady ones); it is a step when the peak of
    :func:`contact_impacts` within a quarter step of it is at least :data:`MIN_IMPACT_RATIO` times the median of
    the bout's first (last) ``ref_steps`` kept steps' peaks. The first step of gait initiation is shorter and slower
    than the steady ones (60-80% of their length; the heel-strike transient grows with speed), but it lands; the
    hand's maxima have no impact unless the hand jerks. The ratio was chosen on the simulated tuning walks (seeds
    100-129, setting off): the steps taken during the move have 0.61-1.39 of the bout's impact, the hand's maxima a
    step away from the bout 0.08-0.34 or 1.3-3.0 (an upper bound of 1.25 or 1.5 changed the mean error by 0.04-0.17
    points and was left out). Only one step per edge: the walker's gait begins within a step or two of the move's
    end, and a second step back would be two step periods from walking that was seen."""
    if len(kept_s) < 2:
        return kept_s
    quarter = max(1, int(round(0.25 * step_s * u.rate_hz)))

    def impact(t_s: float) -> float:
        k = int(round((t_s - u.t_s[0]) * u.rate_hz))
        return float(impacts[max(0, k - quarter): k + quarter + 1].max())

    extra = []
    for edge, ref, side in ((kept_s[0], kept_s[:ref_steps], -1.0), (kept_s[-1], kept_s[-ref_steps:], 1.0)):
        gap = side * (maxima_s - edge)
        cand = maxima_s[(gap > 0) & (np.abs(gap - step_s) <= 0.25 * step_s)]
        if not len(cand):
            continue
        best = cand[np.argmin(np.abs(side * (cand - edge) - step_s))]
        level = np.median([impact(t) for t in ref])
        if level > 0 and impact(best) >= MIN_IMPACT_RATIO * level:
            extra.append(best)
    return np.sort(np.concatenate([kept_s, extra])) if extra else kept_s
