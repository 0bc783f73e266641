"""Step detection by the Meyer-wavelet detail band of the acceleration norm (Ladetto et al. 2000, section 2)."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pywt

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.signals.attitude import gravity_direction_lowpass
from pdr.signals.resample import UniformImu, moving_average, runs, uniform_imu
from pdr.steps.gait import bouts_from_mask, core_walking, rest_threshold_mps2, undecided_samples, walking_mask
from pdr.steps.handling import HANDLING_COLUMNS, AttitudeHandlingDetection, contact_impacts, steps_continuing_the_gait

STEP_COLUMNS = ["t_s", "bout_id"]
BOUT_COLUMNS = ["bout_id", "t_start_s", "t_end_s", "step_period_s", "n_steps"]


def acc_norm_signal(u: UniformImu) -> np.ndarray:
    """Orientation-independent detection signal: |specific force| minus its mean (m/s²)."""
    x = np.linalg.norm(u.acc_mps2, axis=1)
    return x - (x[u.valid].mean() if u.valid.any() else x.mean())


def acc_vertical_signal(u: UniformImu) -> np.ndarray:
    """Orientation-independent detection signal: specific force along the (low-passed) gravity direction, mean removed."""
    up = gravity_direction_lowpass(u.acc_mps2, u.rate_hz)
    x = np.einsum("ij,ij->i", u.acc_mps2, up)
    return x - (x[u.valid].mean() if u.valid.any() else x.mean())


DETECTION_SIGNALS = {"norm": acc_norm_signal, "vertical": acc_vertical_signal}


def empty_steps() -> pd.DataFrame:
    return pd.DataFrame({"t_s": pd.Series(dtype=float), "bout_id": pd.Series(dtype=int)})


def empty_bouts() -> pd.DataFrame:
    return pd.DataFrame({c: pd.Series(dtype=int if c in ("bout_id", "n_steps") else float) for c in BOUT_COLUMNS})


def as_uniform(imu: pd.DataFrame | UniformImu) -> UniformImu:
    if isinstance(imu, UniformImu):
        return imu
    if not isinstance(imu, pd.DataFrame):
        raise InputError(f"step detection: expected an IMU table (DataFrame) or UniformImu, found {type(imu).__name__}")
    return uniform_imu(imu)


def local_maxima(y: np.ndarray) -> np.ndarray:
    """Indices of strict-left / non-strict-right local maxima (plateaus give their first sample)."""
    if len(y) < 3:
        return np.zeros(0, int)
    d = np.diff(y)
    return np.flatnonzero((d[:-1] > 0) & (d[1:] <= 0)) + 1


def parabolic_offset(y: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Sub-sample offset of maxima at ``k`` from a parabola through three samples."""
    k = np.clip(k, 1, len(y) - 2)
    a, b, c = y[k - 1], y[k], y[k + 1]
    den = a - 2 * b + c
    return np.where(np.abs(den) > 1e-12, 0.5 * (a - c) / np.where(np.abs(den) > 1e-12, den, 1.0), 0.0)


def bridge_short_gaps(valid: np.ndarray, max_samples: int) -> np.ndarray:
    """``valid`` with the invalid runs (gaps of the clock) shorter than ``max_samples`` samples set True; a run
    touching an end of the recording is kept."""
    out = np.asarray(valid, bool).copy()
    for a, b in runs(~out):
        if 0 < a and b < len(out) and b - a < max_samples:
            out[a:b] = True
    return out


PEAK_NEIGHBOURS = 3  # maxima on each side that a maximum's amplitude is compared with (1.5 strides)


def neighbour_reference(amp: np.ndarray, walking: np.ndarray, m: int) -> np.ndarray:
    """The amplitude each maximum is judged against: the smaller of the medians of the ``m`` walking maxima before it
    and the ``m`` walking maxima after it (one side only at the ends of a bout).

    ``walking`` flags the maxima inside the core of the walking detector's mask (:func:`pdr.steps.gait.core_walking`);
    only those serve as references, so a maximum at the edge of a bout (the walker starting, stopping, handling the
    phone) is judged against the steps next to it, and a bout with no core is judged against its median maximum. A spurious
    maximum between two steps is small against both sides; a step where the pace changes (fast walking followed by slow
    walking, whose impacts are several times weaker) is small against one side only, and the side of its own pace keeps
    it. A bout-wide median instead drops a whole slow stretch that follows a fast one.
    """
    n = len(amp)
    pos = np.flatnonzero(walking)
    if n == 0 or not len(pos):
        return np.full(n, np.median(amp) if n else 0.0)  # a short bout: the median of its maxima
    pad = np.concatenate([np.full(m, np.nan), amp[pos], np.full(m, np.nan)])
    win = np.lib.stride_tricks.sliding_window_view(pad, m)  # win[j] = amp[pos][j - m : j]
    i = np.arange(n)
    before, after = np.searchsorted(pos, i, "left"), np.searchsorted(pos, i, "right")  # walking maxima < i, <= i
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN side at a bout end
        left = np.nanmedian(win[before], axis=1)
        right = np.nanmedian(win[after + m], axis=1)
    return np.fmin(left, right)  # fmin ignores a NaN side; one walking maximum at least, so never both


class WaveletStepDetection(Algorithm):
    """Steps as the maxima of one Meyer-wavelet detail of the acceleration norm, inside walking bouts.

    Parameters
    ----------
    level : decomposition level of the kept detail (Ladetto et al.: 4).
    min_step_freq_hz, max_step_freq_hz : the cadence range of human walking and running (steps per second). The
        floor of 1 step/s keeps the longest step shorter than a normal stride (about 1.1 s), so a thigh sensor's
        stride period is never taken for a step (with 0.5 steps/s and an 8 s window, Oxford back pocket lost 12%).
    bout_window_s : window of the walking-bout detector (about two strides at the slowest cadence, and more).
    min_acc_std_mps2 : below this standard deviation of |a| a window (and a step) at a normal cadence is at rest;
        at a slower cadence the threshold falls with the square of the step frequency, asking every walker for the
        same vertical excursion of the centre of mass (:func:`pdr.steps.gait.rest_threshold_mps2`). A waist sensor
        sees 0.3-0.4 m/s2 at 0.5 m/s and 1.3 steps/s (simulated impaired walkers), which a fixed 0.3 took for rest
        in every other window; a fixed 0.15 finds them but admits daily-living movement that is not walking
        (mobgap: whole-recording IC F1 0.71 -> 0.69).
    min_periodicity : a walking window's autocorrelation at the gait period is at least this.
    min_bout_steps : shorter walking runs are not walking (a turn on the spot, handling the phone).
    min_peak_ratio : a maximum smaller than this fraction of its neighbours' maxima is not a step (see
        :func:`neighbour_reference`: judged against the weaker of the two sides, so a change of pace keeps its steps).
    signal : ``"norm"`` (|a|) or ``"vertical"`` (a along the low-passed gravity direction); both orientation-free.
    bout_pad_s : walking bouts are widened by this (a window half walking already votes for walking).
    stride_check : whether a gait period may be a stride (thigh, arm); False for a sensor on the trunk (waist,
        lower back, chest, head), which sees every step. See :func:`pdr.steps.gait.step_period_from_acf` and, along a
        walking run, :func:`pdr.steps.gait.resolve_octaves`.
    track_cadence : resample each bout at a uniform gait phase (the kept octave follows a changing cadence)
        instead of at one rate per bout.
    leave_out_handling : maxima inside the phone's handling (:class:`pdr.steps.handling.AttitudeHandlingDetection`:
        taken out, put away, turned over) at an edge of a bout, with no gait-periodic window between it and the
        bout's end, are not steps: there the acceleration is the hand's, not the gait's (:meth:`_leave_out_handling`).
        The one among them a step period beyond the bout's first (last) kept step that carries a foot's impact is a
        step (:func:`pdr.steps.handling.steps_continuing_the_gait`: set off during the move).
        Off by default (a strapped sensor is not handled); ``pdr steps`` and ``pdr run`` turn it on for a phone's
        placements (:data:`pdr.pipelines.steps.PHONE_PLACEMENTS`).

    Attributes
    ----------
    steps_ : DataFrame ``t_s, bout_id`` (the instant of foot contact; bouts split where the stop rule fires).
    bouts_ : DataFrame ``bout_id, t_start_s, t_end_s, step_period_s, n_steps``.
    handling_ : DataFrame ``t_start_s, t_end_s, turn_deg``: the handling intervals found (empty when not looked for).
    left_out_ : DataFrame ``t_start_s, t_end_s, n_maxima``: the handling intervals whose maxima were left out.
    detail_ : the reconstructed detail band on the uniform grid (0 outside bouts), m/s².
    t_s_ : the uniform grid.

    Notes
    -----
    Ladetto et al. (2000), section 2: the signal is decomposed with the Meyer wavelet and the detail at level 4
    "reproduces the step frequency very well, with one maximum only at each occurrence"; maxima are picked within a
    fixed interval, and "if a maximum peak is not followed, after a certain time, by another one, the person is still
    considered at the previous location". The detail at level ``j`` of a signal sampled at ``fs`` holds the octave
    ``fs / 2^(j+1) .. fs / 2^j``. Instead of a fixed rate, each bout is resampled at ``fs = f_step 2^(j + 1/2)``
    (uniform in gait phase, ``f_step`` following the cadence of the sliding autocorrelation windows, see
    :mod:`pdr.steps.gait`) so that the step frequency sits at the geometric centre of the kept octave: the stride
    frequency (``f_step / 2``, dominant for a thigh sensor) and the second harmonic (``2 f_step``, the double heel/sole peak) both fall outside it. The stationary wavelet transform
    is used so that the result does not depend on where the recording starts. A maximum is then moved to the
    largest acceleration norm within a quarter step (the impact of the foot contact), and dropped when |a| barely
    varies over the step around it (its standard deviation below ``min_acc_std_mps2``, the bout detector's rest test).

    Example
    -------
    >>> det = WaveletStepDetection().detect(rec.imu)   # doctest: +SKIP
    >>> det.steps_.t_s.to_numpy()                       # doctest: +SKIP
    """

    def __init__(self, *, level: int = 4, min_step_freq_hz: float = 1.0, max_step_freq_hz: float = 3.5,
                 bout_window_s: float = 5.0, min_acc_std_mps2: float = 0.3, min_periodicity: float = 0.25,
                 min_bout_steps: int = 4, min_peak_ratio: float = 0.25, signal: str = "norm", bout_pad_s: float = 2.5,
                 stride_check: bool = True, track_cadence: bool = True, leave_out_handling: bool = False):
        self.level = level
        self.leave_out_handling = leave_out_handling
        self.track_cadence = track_cadence
        self.stride_check = stride_check
        self.signal = signal
        self.bout_pad_s = bout_pad_s
        self.min_step_freq_hz = min_step_freq_hz
        self.max_step_freq_hz = max_step_freq_hz
        self.bout_window_s = bout_window_s
        self.min_acc_std_mps2 = min_acc_std_mps2
        self.min_periodicity = min_periodicity
        self.min_bout_steps = min_bout_steps
        self.min_peak_ratio = min_peak_ratio

    def _check(self, rate_hz: float) -> None:
        if not (0 < self.min_step_freq_hz < self.max_step_freq_hz):
            raise InputError(f"steps: expected 0 < min_step_freq_hz < max_step_freq_hz, found {self.min_step_freq_hz}, {self.max_step_freq_hz}")
        if self.signal not in DETECTION_SIGNALS:
            raise InputError(f"steps: expected signal one of {', '.join(DETECTION_SIGNALS)}, found {self.signal!r}")
        if int(self.level) != self.level or not 1 <= self.level <= 8:
            raise InputError(f"steps: expected an integer level in 1..8, found {self.level}")

    def detect(self, imu: pd.DataFrame | UniformImu) -> "WaveletStepDetection":
        u = as_uniform(imu)
        self._check(u.rate_hz)
        self.t_s_ = u.t_s
        self.detail_ = np.zeros(len(u))
        self.steps_, self.bouts_ = empty_steps(), empty_bouts()
        self.handling_ = pd.DataFrame({c: pd.Series(dtype=float) for c in HANDLING_COLUMNS})
        self.left_out_ = pd.DataFrame({"t_start_s": pd.Series(dtype=float), "t_end_s": pd.Series(dtype=float),
                                       "n_maxima": pd.Series(dtype=int)})
        min_step_s, max_step_s = 1.0 / self.max_step_freq_hz, 1.0 / self.min_step_freq_hz
        if u.rate_hz < 2.0 * self.max_step_freq_hz:
            warn(f"steps: sampling rate {u.rate_hz:.1f} Hz is below twice the highest cadence "
                 f"({self.max_step_freq_hz} Hz); no steps detected")
            return self
        x = DETECTION_SIGNALS[self.signal](u)
        walking, period = walking_mask(x, u.rate_hz, window_s=self.bout_window_s, min_step_s=min_step_s,
                                       max_step_s=max_step_s, min_acc_std_mps2=self.min_acc_std_mps2,
                                       min_periodicity=self.min_periodicity, stride_check=self.stride_check)
        # a gap shorter than the longest step does not end a walking bout: the walker walks on through it (the stop
        # rule's own limit), and splitting there cut the step on each side of it with the bout's edge (a 0.5 s dropout
        # of a phone walk lost 2 visible steps); the steps are still taken only where there are samples
        bouts = bouts_from_mask(walking, bridge_short_gaps(u.valid, int(max_step_s * u.rate_hz)), u.rate_hz,
                                min_bout_s=self.min_bout_steps * min_step_s,
                                pad_s=self.bout_pad_s)
        core = core_walking(walking, u.rate_hz, self.bout_window_s)
        handled = AttitudeHandlingDetection().detect(u) if self.leave_out_handling else None
        if handled is not None:
            self.handling_ = handled.intervals_
            decided = walking.copy()  # walking where a window decided it: not the recording's ends
            edge = undecided_samples(u.rate_hz, self.bout_window_s)
            decided[:edge] = decided[len(decided) - edge:] = False
            # a gyroscope times the handling to the move itself: a walking window centred within half a window of
            # it holds the move, so it does not show walking beside it
            reach = int(round(0.5 * self.bout_window_s * u.rate_hz)) if handled.gyroscope_used_ else 0
        sums = (np.concatenate([[0.0], np.cumsum(x)]), np.concatenate([[0.0], np.cumsum(x * x)]))
        times, bout_ids, rows, left_out = [], [], [], []
        impacts = None
        bout_id = 0
        for a, b in bouts:
            p = period[a:b]
            p = p[np.isfinite(p)]
            if not len(p):
                continue
            step_s = float(np.median(p))
            local = period[a:b] if self.track_cadence else np.full(b - a, step_s)
            local = moving_average(np.where(np.isfinite(local), local, step_s), int(round(self.bout_window_s * u.rate_hz)))
            t_peaks = self._bout_steps(u, x, a, b, local, core[a:b], sums)
            if handled is not None:
                t_all = t_peaks
                t_peaks, dropped = self._leave_out_handling(u, handled.handling_, decided, a, b, t_peaks, reach)
                if dropped:  # a step taken while the phone still turns
                    impacts = contact_impacts(u) if impacts is None else impacts
                    kept = steps_continuing_the_gait(u, impacts, t_all, t_peaks, step_s)
                    back = np.setdiff1d(kept, t_peaks)
                    dropped = [(lo, hi, n - int(((back >= lo) & (back <= hi)).sum())) for lo, hi, n in dropped]
                    dropped = [d for d in dropped if d[2] > 0]
                    t_peaks = kept
                left_out += dropped
            for seg in self._split_stops(t_peaks, step_s, max_step_s):
                if len(seg) < self.min_bout_steps:
                    continue
                times.append(seg)
                bout_ids.append(np.full(len(seg), bout_id))
                rows.append((bout_id, float(seg[0]), float(seg[-1]), step_s, len(seg)))
                bout_id += 1
        if left_out:
            self.left_out_ = pd.DataFrame(left_out, columns=list(self.left_out_.columns))
        if times:
            self.steps_ = pd.DataFrame({"t_s": np.concatenate(times), "bout_id": np.concatenate(bout_ids).astype(int)})
            self.bouts_ = pd.DataFrame(rows, columns=BOUT_COLUMNS)
        return self

    def _bout_steps(self, u: UniformImu, x: np.ndarray, a: int, b: int, period_s: np.ndarray, walking: np.ndarray,
                    sums: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """Maxima of the level-``level`` detail, the bout resampled so the detail octave is centred on the cadence.

        ``period_s`` is the step period at each sample of the bout; the bout is resampled at a uniform *gait phase*
        (``2^(level + 1/2)`` samples per step), so the kept octave follows the cadence when the walker speeds up.
        """
        t = u.t_s[a:b]
        per_sample = 2.0 ** (self.level + 0.5)
        phase = np.concatenate([[0.0], np.cumsum(np.diff(t) / period_s[1:])])  # in steps
        n_out = int(np.floor(phase[-1] * per_sample)) + 1
        block = 2 ** self.level
        n_pad = max(block, int(np.ceil(n_out / block)) * block)
        filt_len = pywt.Wavelet("dmey").dec_len * block
        margin = (filt_len // block + 1) * block
        tt = np.interp(np.arange(n_out) / per_sample, phase, t)
        xs = np.interp(tt, t, x[a:b])
        xs = xs - xs.mean()
        total = n_pad + 2 * margin
        padded = np.pad(xs, (margin, total - margin - n_out), mode="reflect" if n_out > 1 else "constant")[:total]
        coeffs = pywt.swt(padded, "dmey", level=self.level, trim_approx=True, norm=True)
        kept = [np.zeros_like(c) for c in coeffs]
        kept[1] = coeffs[1]  # [cA_n, cD_n, cD_n-1, ...]: cD at the deepest level
        detail = pywt.iswt(kept, "dmey", norm=True)[margin: margin + n_out]
        self.detail_[a:b] = np.interp(t, tt, detail)
        k = local_maxima(detail)
        k = k[detail[k] > 0]
        if not len(k):
            return np.zeros(0)
        inside = np.interp(tt[k], t, walking.astype(float)) > 0.5
        k = k[detail[k] >= self.min_peak_ratio * neighbour_reference(detail[k], inside, PEAK_NEIGHBOURS)]
        tk = np.interp(k + parabolic_offset(detail, k), np.arange(n_out), tt)
        return self._refine_to_impact(u, x, tk, np.interp(tk, t, period_s), sums, walking, t[0])

    def _refine_to_impact(self, u: UniformImu, x: np.ndarray, tk: np.ndarray, step_s: np.ndarray,
                          sums: tuple[np.ndarray, np.ndarray], core: np.ndarray, core_t0_s: float) -> np.ndarray:
        """Move each maximum to the largest |a| within a quarter step (the contact impact); drop it when |a| barely
        varies around it (over the step, or over the stride inside the core of walking: ``core`` flags the samples
        from ``core_t0_s`` on)."""
        half = np.maximum(1, np.round(0.25 * step_s * u.rate_hz).astype(int))
        centre = np.clip(np.round((tk - u.t_s[0]) * u.rate_hz).astype(int), 0, len(x) - 1)
        offs = np.arange(-half.max(), half.max() + 1)
        idx = np.clip(centre[:, None] + offs[None, :], 0, len(x) - 1)
        score = np.where((np.abs(offs)[None, :] <= half[:, None]) & u.valid[idx], x[idx], -np.inf)
        best = idx[np.arange(len(idx)), np.argmax(score, axis=1)]
        # inside a gap of the clock (or at its edge, where the largest sample may only be the last one seen) the
        # contact is not seen: no step there
        seen = np.isfinite(score).any(axis=1) & u.valid[np.maximum(best - 1, 0)] & u.valid[np.minimum(best + 1, len(x) - 1)]
        if not seen.any():
            return np.zeros(0)
        tk, step_s, best = tk[seen], step_s[seen], best[seen]
        tb = u.t_s[best] + parabolic_offset(x, best) / u.rate_hz
        order = np.argsort(tb)
        tb, step_s = tb[order], step_s[order]
        keep = np.concatenate([[True], np.diff(tb) >= 0.5 * step_s[1:]])
        tb, step_s = tb[keep], step_s[keep]
        # the rest test of the bout detector, per step: |a| must vary around the contact. At the edges of walking
        # (starting, stopping, quiet standing next to a bout) over the step itself; inside the core of walking over
        # the stride around it (both feet's contacts), so that a slow, light step (0.6 m/s: |a| std 0.2-0.4 m/s2 from
        # step to step) is not taken for rest, while a pause of a few steps inside a bout still is. In the core the
        # step period is the walker's cadence and the threshold scales with it (:func:`rest_threshold_mps2`); at the
        # edges the period is borrowed from the walking next to them (handling, turning and shuffling of daily
        # living pass the scaled threshold there: mobgap whole-recording IC F1 0.71 -> 0.69), so the threshold of a
        # normal cadence holds.
        in_core = core[np.clip(np.round((tb - core_t0_s) * u.rate_hz).astype(int), 0, len(core) - 1)]
        span = np.where(in_core, 1.0, 0.5) * step_s
        i0 = np.clip(np.round((tb - span - u.t_s[0]) * u.rate_hz).astype(int), 0, len(x) - 1)
        i1 = np.clip(np.round((tb + span - u.t_s[0]) * u.rate_hz).astype(int) + 1, 1, len(x))
        c1, c2 = sums
        cnt = np.maximum(i1 - i0, 1)
        var = (c2[i1] - c2[i0]) / cnt - ((c1[i1] - c1[i0]) / cnt) ** 2
        gate = np.where(in_core, rest_threshold_mps2(self.min_acc_std_mps2, step_s), self.min_acc_std_mps2)
        return tb[var >= gate ** 2]

    @staticmethod
    def _leave_out_handling(u: UniformImu, handling: np.ndarray, walking: np.ndarray, a: int, b: int,
                            t: np.ndarray, reach: int = 0) -> tuple[np.ndarray, list[tuple[float, float, int]]]:
        """``t`` without the maxima inside the handling intervals at an edge of the bout ``[a, b)``: no walking
        (``walking``: windows found gait-periodic, their centres more than ``reach`` samples from the interval)
        between the interval and the bout's start, or between it and the bout's end. There the walker starts or
        stops, and the acceleration is the hand's. Handling with walking on both sides (the phone taken out while
        walking on) keeps its steps. Also returns the intervals that lost maxima: ``(t_start_s, t_end_s, n_maxima)``."""
        k = np.clip(np.round((t - u.t_s[0]) * u.rate_hz).astype(int), 0, len(u) - 1)
        keep = np.ones(len(t), bool)
        dropped = []
        for lo, hi in runs(handling[a:b]):
            lo, hi = a + lo, a + hi
            inside = (k >= lo) & (k < hi)
            if inside.any() and not (walking[a:max(a, lo - reach)].any() and walking[hi + reach:b].any()):
                keep &= ~inside
                dropped.append((float(u.t_s[lo]), float(u.t_s[hi - 1]), int(inside.sum())))
        return t[keep], dropped

    @staticmethod
    def _split_stops(t: np.ndarray, step_s: float, max_step_s: float) -> list[np.ndarray]:
        """The stop rule: a maximum not followed by another within the longest step interval ends the bout."""
        if not len(t):
            return []
        limit = max(max_step_s, 2.0 * step_s)
        cuts = np.flatnonzero(np.diff(t) > limit) + 1
        return np.split(t, cuts)
