"""Gait periodicity shared by the step detectors: walking bouts and the step period from autocorrelation.

A window is *walking* when the acceleration norm varies (energy) and repeats itself at a gait period
(normalised, unbiased autocorrelation above a threshold at some lag between the shortest step and the longest
stride). The period found may be a step or a stride: a sensor on the trunk sees every step, one on a thigh
(trouser pocket) mainly sees its own side's strides. :func:`step_period_from_acf` decides with two facts of
human gait: a stride is two steps, and a step-periodic signal is anti-correlated at half its period, while a
stride-periodic one still carries the other foot's contact there. Along a walking run, :func:`resolve_octaves`
halves a stride taken for a step where the windows next to it found the step.
"""

from __future__ import annotations

import numpy as np

from pdr.constants import REFERENCE_CADENCE_HZ
from pdr.signals.resample import runs

SUBHARMONIC_RATIO = 0.5  # the first acf peak at least this fraction of the best one is the fundamental period
OCTAVE_TOLERANCE = 1.1  # two overlapping windows' periods in a ratio of 2 within this factor: one is a stride
ANTI_PHASE_ACF = -0.5  # acf at half the period at most this: the signal flips sign there, the period is a step
ACF_CHUNK = 4096  # windows per FFT block in window_acf


def window_acf(x: np.ndarray, win: int, hop: int, max_lag: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unbiased normalised autocorrelation of sliding windows.

    Returns ``(starts, acf, std)``: window start indices, acf of shape (n_windows, max_lag + 1), window std.
    """
    n = len(x)
    if n < win:
        return np.zeros(0, int), np.zeros((0, max_lag + 1)), np.zeros(0)
    starts = np.arange(0, n - win + 1, hop)
    if starts[-1] != n - win:
        starts = np.append(starts, n - win)
    nfft = 1 << int(np.ceil(np.log2(2 * win)))
    ac = np.empty((len(starts), max_lag + 1))
    for a in range(0, len(starts), ACF_CHUNK):  # bounded temporaries: 10 h at 100 Hz took 1 GB at once
        w = x[starts[a: a + ACF_CHUNK, None] + np.arange(win)[None, :]]
        w = w - w.mean(axis=1, keepdims=True)
        spec = np.fft.rfft(w, nfft, axis=1)
        ac[a: a + ACF_CHUNK] = np.fft.irfft(spec.real ** 2 + spec.imag ** 2, nfft, axis=1)[:, : max_lag + 1]
    var = ac[:, :1]
    ac = ac / np.maximum(var, 1e-12) * (win / (win - np.arange(max_lag + 1)))[None, :]
    return starts, ac, np.sqrt(var[:, 0] / win)


def step_period_from_acf(acf: np.ndarray, rate_hz: float, min_step_s: float, max_step_s: float,
                         stride_check: bool = True) -> tuple[float, float]:
    """Step period (s) and its periodicity (acf value at the gait period) from one autocorrelation.

    The fundamental is the first autocorrelation peak between the shortest step and the longest stride that is at
    least half as high as the highest one (later peaks are its multiples); that fundamental is a stride, and the step half of it,
    when it is longer than the longest step or when the acf has a peak (not a trough) at half of it: the other foot's
    contact. A step-periodic signal is in anti-phase at half its period (Oxford hand, bag, neck: acf about -0.8, a
    trough); a thigh-worn phone shows a small peak there (Oxford pockets: prominence +0.1 to +0.4). Slow, irregular
    walking seen from the trunk can show such a peak too (mobgap daily living), so ``stride_check=False`` (a sensor
    on the trunk sees every step) keeps only the first rule.
    """
    lo = max(1, int(np.floor(min_step_s * rate_hz)))
    hi = min(len(acf) - 1, int(np.ceil(2.0 * max_step_s * rate_hz)))
    if hi <= lo:
        return float("nan"), 0.0
    seg = acf[lo: hi + 1]
    best = float(seg.max())
    peaks = np.flatnonzero((seg[1:-1] >= seg[:-2]) & (seg[1:-1] > seg[2:])) + 1
    strong = peaks[seg[peaks] >= SUBHARMONIC_RATIO * best] if len(peaks) else peaks
    if not len(strong) or acf[: lo + strong[0]].min() > 0.0:
        return float("nan"), 0.0  # no repetition, or no oscillation (a drift, e.g. the phone being handled)
    lag = lo + int(strong[0])  # the fundamental: the first strong repetition
    best = float(acf[lag])
    period = lag / rate_hz
    quarter = [acf[min(len(acf) - 1, max(1, int(round(lag * f))))] for f in (0.25, 0.5, 0.75)]
    half_prominence = quarter[1] - 0.5 * (quarter[0] + quarter[2])
    is_stride = period > max_step_s or (stride_check and period / 2 >= min_step_s and half_prominence > 0.0)
    return (period / 2 if is_stride else period), best


def resolve_octaves(period_s: np.ndarray, walking: np.ndarray, half_acf: np.ndarray) -> np.ndarray:
    """Per-window step periods with strides taken for steps halved, by continuity along runs of walking windows.

    Windows a quarter window apart share three quarters of their steps, and a walker's cadence varies from step to
    step by a few percent (step-time coefficient of variation 2-4% in healthy adults and below about 11% in impaired
    gait: Hausdorff 2005, "Gait variability: methods, modeling and meaning", J NeuroEng Rehabil 2:19), so two
    neighbouring walking windows whose periods are in a ratio of 2 within :data:`OCTAVE_TOLERANCE` (one step's 10%
    deviation; the windows' mean periods, over 5-15 steps, differ less) disagree on what a step is, not on the
    cadence. A step-periodic signal is stride-periodic as well but not the converse, so the shorter period is the
    step and the longer is halved, the correction carrying along the run; unless the longer window's own acf at half
    its period (``half_acf``) is a deep trough (at most :data:`ANTI_PHASE_ACF`): the signal is in anti-phase there,
    as a step-periodic one is, and the shorter neighbour is the one in error (phone handling next to the walking).
    ``acf(T/2) = P_even - P_odd``, the share of the periodic power at the even harmonics of ``1/T`` minus that at
    the odd ones; -0.5 asks for three quarters at the odd ones, where a sign flip over ``T/2`` is the rule (Oxford
    hand, bag and neck phones: about -0.8; the stride of a simulated trouser-pocket phone: about -0.1).
    """
    p = period_s.copy()
    ambiguous = walking & (half_acf > ANTI_PHASE_ACF)
    changed, forward = True, True
    while changed:  # sweeps alternately forward and backward, so a correction crosses a run in one sweep
        changed = False
        order = np.flatnonzero(ambiguous)
        for i in (order if forward else order[::-1]):
            for j in (i - 1, i + 1):
                if 0 <= j < len(p) and walking[j] and 2.0 / OCTAVE_TOLERANCE <= p[i] / p[j] <= 2.0 * OCTAVE_TOLERANCE:
                    p[i] /= 2.0
                    ambiguous[i] = False
                    changed = True
                    break
        forward = not forward
    return p


def rest_threshold_mps2(min_acc_std_mps2: float, step_s) -> np.ndarray:
    """The standard deviation of |a| below which walking at the step period ``step_s`` (s) is taken for rest:
    ``min_acc_std_mps2`` at a normal cadence (``f_ref`` = :data:`pdr.constants.REFERENCE_CADENCE_HZ`) and faster,
    ``(f / f_ref)^2`` of it below.

    The step-periodic part of a trunk sensor's |a| is mainly the vertical acceleration of the centre of mass, which
    rises and falls once per step: an excursion ``dh`` (peak to peak) at a step frequency ``f`` gives an amplitude
    ``dh / 2 (2 pi f)^2``. A threshold fixed in m/s2 therefore asks a slow walker for a larger excursion than a normal
    one; scaled by ``f^2`` it asks everyone for the same, ``2 sqrt(2) 0.3 / (2 pi 1.83)^2 = 6.4 mm`` for 0.3 m/s2 at
    110 steps/min: a quarter of the 2.7 cm measured at 0.7 m/s (Orendurff et al. 2004, "The effect of walking speed
    on center of mass displacement", J Rehabil Res Dev 41:829-834). Slow walkers (0.5-0.9 m/s with steps of
    0.4-0.6 m; shorter steps and slower gait in multiple sclerosis: Comber, Galvin & Coote 2017, Gait Posture
    51:25-35) step at 1.2-1.5 steps/s, where the threshold is 0.13-0.2 m/s2; at the slowest step rate of the
    detectors (1 step/s) it is 0.09 m/s2. A lower-back sensor at rest reads 0.02-0.03 m/s2 (mobgap daily-living
    recording of participant 002, 5 s windows at least 5 s from any reference contact: median 0.026), but other
    movement than walking reads more (participant 001: median 0.26), so the detectors keep the periodicity test
    and, where the cadence is not measured, the unscaled threshold.
    """
    f = 1.0 / np.asarray(step_s, float)
    return min_acc_std_mps2 * np.minimum(1.0, (f / REFERENCE_CADENCE_HZ) ** 2)


def walking_mask(x: np.ndarray, rate_hz: float, *, window_s: float, min_step_s: float, max_step_s: float,
                 min_acc_std_mps2: float, min_periodicity: float, stride_check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample walking flag and step period (s, NaN where not walking) of a signal (the acceleration norm).

    Windows of ``window_s`` with a hop of a quarter window; each window decides for its central hop. A window is
    at rest when its |a| standard deviation is below :func:`rest_threshold_mps2` at its step period. With
    ``stride_check``, :func:`resolve_octaves` then halves the strides taken for steps along each walking run.
    """
    n = len(x)
    win = int(round(window_s * rate_hz))
    hop = max(1, win // 4)
    max_lag = min(win - 1, int(np.ceil(2.0 * max_step_s * rate_hz)) + 2)
    walking = np.zeros(n, bool)
    period = np.full(n, np.nan)
    if n < win or max_lag < 2:
        return walking, period
    starts, acf, std = window_acf(x, win, hop, max_lag)
    lowest = float(rest_threshold_mps2(min_acc_std_mps2, max_step_s))
    periods, half_acf = np.full(len(starts), np.nan), np.zeros(len(starts))
    periodic = np.zeros(len(starts), bool)
    for i, (a, sd) in enumerate(zip(acf, std)):
        if sd >= lowest:
            periods[i], strength = step_period_from_acf(a, rate_hz, min_step_s, max_step_s, stride_check)
            periodic[i] = np.isfinite(periods[i]) and strength >= min_periodicity
            if periodic[i]:
                half_acf[i] = a[int(round(0.5 * periods[i] * rate_hz))]
    if stride_check:
        periods = resolve_octaves(periods, periodic, half_acf)
    for s, p, ok, sd in zip(starts, periods, periodic, std):
        if not ok or sd < rest_threshold_mps2(min_acc_std_mps2, p):
            continue
        c0 = s + (win - hop) // 2
        lo = 0 if s == starts[0] else c0
        hi = n if s == starts[-1] else c0 + hop
        walking[lo:hi] = True
        period[lo:hi] = p
    return walking, period


def bouts_from_mask(walking: np.ndarray, valid: np.ndarray, rate_hz: float, min_bout_s: float, pad_s: float) -> list[tuple[int, int]]:
    """Walking bouts ``[start, stop)``: runs of walking samples, padded, clipped to valid data, at least ``min_bout_s`` long."""
    pad = int(round(pad_s * rate_hz))
    out = []
    for a, b in runs(walking & valid):
        a, b = max(0, a - pad), min(len(walking), b + pad)
        for va, vb in runs(valid[a:b]):
            if (vb - va) / rate_hz >= min_bout_s:
                out.append((a + va, a + vb))
    merged: list[tuple[int, int]] = []
    for a, b in sorted(out):
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(b, merged[-1][1]))
        else:
            merged.append((a, b))
    return merged


def undecided_samples(rate_hz: float, window_s: float) -> int:
    """Samples at each end of a recording that no window of :func:`walking_mask` decides for (each window decides
    for its central hop; the first and the last vote for the recording's ends as well)."""
    win = int(round(window_s * rate_hz))
    return (win - max(1, win // 4)) // 2


def core_walking(walking: np.ndarray, rate_hz: float, window_s: float) -> np.ndarray:
    """The walking samples every detector window covering them agrees on: each walking run shrunk by half a window.

    A window half walking already votes for walking, and the first and last windows of :func:`walking_mask` vote
    for the whole start and end of the recording, so the edges of its runs hold the walker starting, stopping or
    handling the phone; the core holds walking only. The recording's ends count as not walking (the samples before
    the first window's central hop and after the last one's were never decided). A run shorter than a window has no core.
    """
    n = len(walking)
    undecided = undecided_samples(rate_hz, window_s)
    half = int(round(0.5 * window_s * rate_hz))
    core = np.zeros(n, bool)
    for a, b in runs(walking):
        a, b = max(a, undecided) + half, min(b, n - undecided) - half
        if b > a:
            core[a:b] = True
    return core
