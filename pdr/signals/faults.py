"""Sensor faults inside a valid recording, detected from the data: gaps, stuck or saturated sensors, duplicated
samples, a sampling rate that changes, a disturbed magnetic field, GNSS fixes that jump or that report an accuracy
too poor to use.

A recording with these faults is still valid (CONTRACT.md: ``t_s`` strictly increasing, finite values); ``pdr run``
keeps going, widens the uncertainty where they are and lists them in ``summary.json`` ``warnings``. What stays an
*error* (``pdr validate``, importers): repeated or back-stepping time stamps (importers repair a few, with a warning,
and refuse more), NaN / inf values, wrong units. A clock that jumps *forward* is a gap here (the data cannot tell a
clock jump from a dropout); one that jumps back is unsorted time, an error.

Example
-------
>>> import numpy as np, pandas as pd
>>> t = np.r_[np.arange(0, 10, 0.01), np.arange(12, 20, 0.01)]
>>> rng = np.random.default_rng(0)
>>> imu = pd.DataFrame({"t_s": t, **{f"acc_{a}_mps2": rng.normal(0, 0.3, len(t)) for a in "xy"},
...                     "acc_z_mps2": 9.8 + rng.normal(0, 0.3, len(t))})
>>> SensorFaultDetection().detect(imu).faults_[["kind", "t_start_s", "t_end_s"]].round(2).values.tolist()
[['gap', 9.99, 12.0]]
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from pdr.base import Algorithm
from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError
from pdr.io.recording import ACC_COLUMNS, GYR_COLUMNS, MAG_COLUMNS, check_time
from pdr.schema import require_table
from pdr.signals.attitude import gravity_direction_lowpass
from pdr.signals.resample import moving_average, runs

FAULT_COLUMNS = ["kind", "sensor", "t_start_s", "t_end_s", "message"]
IMU_FAULT_KINDS = ("gap", "stuck", "saturation", "duplicated_samples", "rate_change", "mag_disturbance")
GNSS_FAULT_KINDS = ("gnss_jump", "gnss_inaccurate")
TRIADS = {"acc": ACC_COLUMNS, "gyr": GYR_COLUMNS, "mag": MAG_COLUMNS}
# The smallest full-scale ranges of MEMS IMUs (datasheets: +-2 g accelerometers, +-125 deg/s gyroscopes): a signal
# flat at its extreme below these is not clipped by a sensor range.
MIN_FULL_SCALE = {"acc": 2.0 * GRAVITY_MPS2 * 0.95, "gyr": np.radians(125.0) * 0.95}
_MAD_TO_SIGMA = 1.4826
MAG_DERIVATIVE_SMOOTH_S = 0.1  # the field is smoothed over this before its time derivative (noise)
MAG_ROTATION_FLOOR_UTPS = 5.0  # a residual below this (µT/s) is never a disturbance (a noiseless synthetic file)
CLIP_WINDOW_S = 2.5  # two gait cycles: a sensor range clips the extreme of every stretch this long around a clip
GRAVITY_TOLERANCE = 0.02  # |averaged specific force| within 2% of g: the average is gravity (no turn, no speed change)


def empty_faults() -> pd.DataFrame:
    return pd.DataFrame({"kind": pd.Series(dtype=str), "sensor": pd.Series(dtype=str),
                         "t_start_s": pd.Series(dtype=float), "t_end_s": pd.Series(dtype=float),
                         "message": pd.Series(dtype=str)})


def merge_intervals(intervals: list[tuple[float, float]], join_s: float) -> list[tuple[float, float]]:
    """Sorted, overlapping or closer than ``join_s`` intervals merged."""
    out: list[list[float]] = []
    for a, b in sorted(intervals):
        if out and a - out[-1][1] <= join_s:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def clipped_samples(values: np.ndarray, rate_hz: float, *, min_run: int = 3, min_abs: float = 0.0) -> np.ndarray:
    """Samples (bool mask, N) of an (N, C) signal held at the end of its sensor's range: a run of ``min_run`` or
    more identical samples at the largest (or the smallest) value the channel takes within ``CLIP_WINDOW_S`` on
    either side, at ``|value| >= min_abs``.

    A clipped channel cannot exceed its range, so its flat tops are the extreme of every stretch around them (a range
    clips every vigorous stride, and two gait cycles either side hold several); a quantised sensor repeats values
    at many peaks (the OpenShoe unit at 820 Hz repeats a peak for 3-6 samples), but larger peaks lie around those.
    """
    values = np.asarray(values, dtype=float).reshape(len(values), -1)
    mask = np.zeros(len(values), dtype=bool)
    if len(values) < min_run:
        return mask
    n = 2 * int(round(CLIP_WINDOW_S * rate_hz)) + 1
    for ch in range(values.shape[1]):
        x = values[:, ch]
        top = (x == maximum_filter1d(x, n, mode="nearest")) & (x >= min_abs)
        bottom = (x == minimum_filter1d(x, n, mode="nearest")) & (x <= -min_abs)
        for flat in (top, bottom):
            for a, b in runs(flat & np.r_[False, x[1:] == x[:-1]] | flat & np.r_[x[:-1] == x[1:], False]):
                if b - a >= min_run:
                    mask[a:b] = True
    return mask


class SensorFaultDetection(Algorithm):
    """Find the intervals of a recording where a sensor misbehaves, from the data alone.

    Parameters
    ----------
    gap_factor, min_gap_s : a sample interval longer than ``gap_factor`` median intervals and than ``min_gap_s`` is
        a gap (a dropout, or a clock that jumped forward).
    stuck_min_s : a triad (acc, gyr, mag) repeating exactly the same three values for at least this long (and at
        least ``3 x`` the recording's median repeat run, so a slower sensor held at the IMU rate is not flagged) is
        stuck. A live MEMS sensor's noise changes its last bits every sample.
    duplicate_window_s, duplicate_min_fraction : a window of this length in which more than this fraction of the
        samples repeat the previous one exactly (and three times the recording's own fraction) has duplicated samples.
    min_saturated_samples : an axis that holds the extreme value of the stretch around it, beyond the smallest full scale of
        MEMS sensors (``MIN_FULL_SCALE``), for this many consecutive samples is saturated (clipped, see
        :func:`clipped_samples`).
    rate_tolerance, rate_window_samples, min_rate_change_s : a running median of the sample interval (over this many
        samples) off the recording's median by more than the tolerance (fraction) for this long is a rate change.
    mag_norm_tolerance, mag_dip_tolerance_rad, mag_window_s, min_mag_disturbance_s : the field magnitude (or its dip),
        averaged over the window, off the recording's median by more than this fraction (angle) and 6 robust sigmas
        of its own variation, for this long, is a disturbed field (steel nearby). The magnitude tolerance is the
        heading's (``AttitudeStepHeading``) trust limit. The dip is measured from the apparent vertical, the
        accelerometer averaged over ``gravity_window_s`` (several steps, so that walking accelerations cancel), and
        only where that average has the magnitude of g; its tolerance is twice the heading's 10 degrees because a
        runner leans into a turn by up to about 15 degrees (tan(lean) = v^2 / (r g)), which the apparent vertical
        follows.
        With a gyroscope, also: the part of the field's change in the sensor frame that the gyroscope's rotation
        does not explain (``|dB/dt + w x (B - h)|``, ``h`` the hard-iron offset of an uncalibrated magnetometer fitted
        by least squares, averaged over the window) above ``mag_rotation_factor`` times its median over the recording
        (the noise floor of the derivative): this sees steel that keeps |B| and the dip.
    max_speed_mps, gnss_sigma_factor, default_h_acc_m : two fixes are consistent when the distance between them is at
        most ``max_speed_mps`` (a running pedestrian) times their time apart plus ``gnss_sigma_factor`` times their
        combined reported accuracy. The fixes split into runs of consistent fixes; the longest run is trusted, and a
        run is trusted when it is consistent with the nearest trusted fix before (or after) it. Fixes of the other
        runs jumped: they are reported and not used.
    max_h_acc_m : a fix reporting ``h_acc_m`` above this (1 sigma, m) is unusable: reported and not used, and left
        out of the jump test. 50 m is ten times the 1-sigma accuracy of a phone outdoors under open sky (about 5 m,
        van Diggelen & Enge, ION GNSS+ 2015) and more than a step model off by 5% drifts over a kilometre; it also
        catches the sentinel accuracies (999, 9999) that receivers write for a fix they do not have.
    join_s : flagged samples closer than this are one interval.

    Attributes
    ----------
    faults_ : table ``kind, sensor, t_start_s, t_end_s, message``, sorted by start.
    gnss_suspect_ : bool per GNSS row (True: a fix not to use: it jumped or its reported accuracy is too poor).
    gnss_inaccurate_ : bool per GNSS row (True: ``h_acc_m`` above ``max_h_acc_m``).

    Notes
    -----
    Every threshold comes from the sampling rate, the sensors' ranges or pedestrian physics; none from the fault
    injector (:mod:`pdr.sim.faults`), whose truth only the tests and ``benchmarks/bench_faults.py`` read.
    """

    GNSS_VOTES = 5

    def __init__(self, *, gap_factor: float = 5.0, min_gap_s: float = 0.1, stuck_min_s: float = 0.2,
                 duplicate_window_s: float = 1.0, duplicate_min_fraction: float = 0.2, min_saturated_samples: int = 3,
                 rate_tolerance: float = 0.3, rate_window_samples: int = 11, min_rate_change_s: float = 0.5,
                 mag_norm_tolerance: float = 0.15, mag_dip_tolerance_rad: float = float(np.radians(20.0)), mag_window_s: float = 0.5, min_mag_disturbance_s: float = 0.25,
                 gravity_window_s: float = 2.0, mag_rotation_factor: float = 3.0,
                 max_speed_mps: float = 6.0, gnss_sigma_factor: float = 3.0, default_h_acc_m: float = 5.0,
                 max_h_acc_m: float = 50.0, join_s: float = 0.5):
        self.gap_factor = gap_factor
        self.min_gap_s = min_gap_s
        self.stuck_min_s = stuck_min_s
        self.duplicate_window_s = duplicate_window_s
        self.duplicate_min_fraction = duplicate_min_fraction
        self.min_saturated_samples = min_saturated_samples
        self.rate_tolerance = rate_tolerance
        self.rate_window_samples = rate_window_samples
        self.min_rate_change_s = min_rate_change_s
        self.mag_norm_tolerance = mag_norm_tolerance
        self.mag_dip_tolerance_rad = mag_dip_tolerance_rad
        self.gravity_window_s = gravity_window_s
        self.mag_rotation_factor = mag_rotation_factor
        self.mag_window_s = mag_window_s
        self.min_mag_disturbance_s = min_mag_disturbance_s
        self.max_speed_mps = max_speed_mps
        self.gnss_sigma_factor = gnss_sigma_factor
        self.default_h_acc_m = default_h_acc_m
        self.max_h_acc_m = max_h_acc_m
        self.join_s = join_s

    # ------------------------------------------------------------------------------------------------------------
    def detect(self, imu: pd.DataFrame, gnss: pd.DataFrame | None = None) -> "SensorFaultDetection":
        """``imu``: a canonical IMU table; ``gnss``: fixes in the local frame (``t_s, e_m, n_m``, optional
        ``h_acc_m``; NaN positions are invalid fixes) or None."""
        require_table(imu, ("t_s", *ACC_COLUMNS), "imu")
        t = imu["t_s"].to_numpy(float)
        check_time(t, "imu", min_rows=2)
        rows: list[dict] = []
        dt = np.diff(t)
        med_dt = float(np.median(dt))
        rows += self._gaps(t, dt, med_dt)
        rows += self._rate_changes(t, dt, med_dt)
        for sensor, cols in TRIADS.items():
            if all(c in imu.columns for c in cols):
                x = imu[list(cols)].to_numpy(float)
                rows += self._stuck_and_duplicated(t, x, sensor, med_dt)
                if sensor in MIN_FULL_SCALE:
                    rows += self._saturation(t, x, sensor)
                if sensor == "mag":
                    gyr = imu[list(GYR_COLUMNS)].to_numpy(float) if all(c in imu.columns for c in GYR_COLUMNS) else None
                    rows += self._mag_disturbance(t, x, imu[list(ACC_COLUMNS)].to_numpy(float), gyr, med_dt)
        self.gnss_suspect_ = self.gnss_inaccurate_ = np.zeros(0, bool)
        if gnss is not None:
            inaccurate, inaccurate_rows = self._gnss_inaccurate(gnss)
            suspect, gnss_rows = self._gnss_jumps(gnss, inaccurate)
            self.gnss_suspect_, self.gnss_inaccurate_ = suspect | inaccurate, inaccurate
            rows += inaccurate_rows + gnss_rows
        faults = pd.DataFrame(rows, columns=FAULT_COLUMNS) if rows else empty_faults()
        self.faults_ = faults.sort_values(["t_start_s", "kind"], kind="stable").reset_index(drop=True)
        return self

    # ------------------------------------------------------------------------------------------------------------
    def _intervals(self, t: np.ndarray, mask: np.ndarray, min_s: float = 0.0) -> list[tuple[float, float]]:
        spans = [(float(t[a]), float(t[b - 1])) for a, b in runs(mask)]
        return [(a, b) for a, b in merge_intervals(spans, self.join_s) if b - a >= min_s]

    def _gaps(self, t, dt, med_dt) -> list[dict]:
        limit = max(self.gap_factor * med_dt, self.min_gap_s)
        out = []
        for i in np.flatnonzero(dt > limit):
            out.append({"kind": "gap", "sensor": "imu", "t_start_s": float(t[i]), "t_end_s": float(t[i + 1]),
                        "message": f"no IMU samples for {dt[i]:.3f} s (a dropout or a clock jump; limit {limit:.3f} s)"})
        return out

    def _rate_changes(self, t, dt, med_dt) -> list[dict]:
        n = max(3, int(self.rate_window_samples) | 1)
        if len(dt) < n:
            return []
        from scipy.ndimage import median_filter

        local = median_filter(dt, size=n, mode="nearest")
        ratio = local / med_dt
        off = (ratio > 1.0 + self.rate_tolerance) | (ratio < 1.0 / (1.0 + self.rate_tolerance))
        out = []
        for a, b in self._intervals(t[1:], off, self.min_rate_change_s):
            sel = (t[1:] >= a) & (t[1:] <= b)
            rate = 1.0 / float(np.median(dt[sel]))
            out.append({"kind": "rate_change", "sensor": "imu", "t_start_s": a, "t_end_s": b,
                        "message": f"sampling rate {rate:.1f} Hz instead of {1.0 / med_dt:.1f} Hz"})
        return out

    def _stuck_and_duplicated(self, t, x, sensor, med_dt) -> list[dict]:
        same = np.concatenate([[False], (np.diff(x, axis=0) == 0).all(axis=1)])
        repeat_runs = runs(same)
        if not repeat_runs:
            return []
        lengths = np.array([b - a for a, b in repeat_runs])
        n_min = max(int(np.ceil(self.stuck_min_s / med_dt)), 2)
        short = lengths[lengths < n_min]  # the recording's own holding pattern (a slower sensor), if any
        min_run = max(n_min, 3 * int(np.median(short)) if len(short) else 0)
        out = []
        stuck = np.zeros(len(t), bool)
        for a, b in repeat_runs:
            if b - a >= min_run:
                stuck[a - 1:b] = True
        for a, b in self._intervals(t, stuck):
            out.append({"kind": "stuck", "sensor": sensor, "t_start_s": a, "t_end_s": b,
                        "message": f"{sensor} repeats the same values for {b - a:.2f} s (a stuck sensor)"})
        rep = same & ~stuck
        win = max(3, int(round(self.duplicate_window_s / med_dt)))
        frac = moving_average(rep.astype(float), win)
        base = float(rep.mean())
        dup = rep & (frac > max(self.duplicate_min_fraction, 3.0 * base))
        for a, b in self._intervals(t, dup):
            sel = (t >= a) & (t <= b)
            n_rep = int(rep[sel].sum())
            if n_rep >= 3:
                out.append({"kind": "duplicated_samples", "sensor": sensor, "t_start_s": a, "t_end_s": b,
                            "message": f"{sensor}: {n_rep} samples repeat the previous one exactly"})
        return out

    def _saturation(self, t, x, sensor) -> list[dict]:
        clipped = clipped_samples(x, 1.0 / float(np.median(np.diff(t))), min_run=int(self.min_saturated_samples),
                                  min_abs=MIN_FULL_SCALE[sensor])
        levels = [float(np.abs(x[clipped]).max())] if clipped.any() else []
        out = []
        unit = "m/s²" if sensor == "acc" else "rad/s"
        for a, b in self._intervals(t, clipped):
            n = int(clipped[(t >= a) & (t <= b)].sum())
            out.append({"kind": "saturation", "sensor": sensor, "t_start_s": a, "t_end_s": b,
                        "message": f"{sensor}: {n} samples clipped at +-{max(levels):.3g} {unit} (sensor range)"})
        return out

    def _mag_disturbance(self, t, x, acc, gyr, med_dt) -> list[dict]:
        # The Earth's field has a constant magnitude and a constant dip (angle to the horizontal plane) whatever the
        # sensor's orientation; steel changes one or both.
        n_win = int(round(self.mag_window_s / med_dt))
        norm_raw = np.linalg.norm(x, axis=1)
        norm = moving_average(norm_raw, n_win)
        up = gravity_direction_lowpass(acc, 1.0 / med_dt, window_s=self.gravity_window_s)
        dip = moving_average(np.arcsin(np.clip(np.einsum("ij,ij->i", x, up) / np.maximum(norm_raw, 1e-9), -1, 1)), n_win)
        del up
        # the averaged accelerometer is gravity only where its magnitude is g (a turn adds a centripetal part)
        mean_acc = np.linalg.norm(moving_average(acc, int(round(self.gravity_window_s / med_dt))), axis=1)
        level = np.abs(mean_acc / GRAVITY_MPS2 - 1.0) <= GRAVITY_TOLERANCE
        off = np.zeros(len(t), bool)
        for signal, floor, where in ((norm, self.mag_norm_tolerance * float(np.median(norm)), np.ones(len(t), bool)),
                                     (dip, self.mag_dip_tolerance_rad, level)):
            med = float(np.median(signal[where])) if where.any() else 0.0
            sigma = _MAD_TO_SIGMA * float(np.median(np.abs(signal[where] - med))) if where.any() else 0.0
            off |= where & (np.abs(signal - med) > max(floor, 6.0 * sigma))
        if gyr is not None:
            # A field fixed in the world turns in the sensor frame exactly as the gyroscope says: dB/dt = -w x B.
            # Walking past steel adds a change the gyroscope does not explain (even one that keeps |B| and the dip).
            n_short = max(1, int(round(MAG_DERIVATIVE_SMOOTH_S / med_dt)))
            b = moving_average(x, n_short)
            w = moving_average(gyr, n_short)
            residual = np.gradient(b, t, axis=0)
            residual += np.cross(w, b)
            del b
            # an uncalibrated magnetometer's hard-iron offset h turns with the sensor: residual = w x h, linear in h;
            # its least squares through the 3x3 normal equations, sum(|w|^2 I - w w^T) h = sum(r x w) (min-norm where
            # the rotations leave a direction of h unseen), from the 3x3 sums W = sum w w^T and R = sum r w^T, so no
            # (samples x 3 x 3) matrix is held
            ww, rw = w.T @ w, residual.T @ w
            normal = np.trace(ww) * np.eye(3) - ww
            r_cross_w = np.array([rw[1, 2] - rw[2, 1], rw[2, 0] - rw[0, 2], rw[0, 1] - rw[1, 0]])
            hard_iron = np.linalg.lstsq(normal, r_cross_w, rcond=None)[0]
            residual -= np.cross(w, hard_iron)
            r = moving_average(np.linalg.norm(residual, axis=1), n_win)
            off |= r > max(self.mag_rotation_factor * float(np.median(r)), MAG_ROTATION_FLOOR_UTPS)
        med_norm, med_dip = float(np.median(norm)), float(np.median(dip))
        out = []
        for a, b in self._intervals(t, off, self.min_mag_disturbance_s):
            sel = (t >= a) & (t <= b)
            worst = float(np.max(np.abs(norm[sel] - med_norm)))
            worst_dip = float(np.degrees(np.max(np.abs(dip[sel] - med_dip))))
            out.append({"kind": "mag_disturbance", "sensor": "mag", "t_start_s": a, "t_end_s": b,
                        "message": f"|B| off the recording's {med_norm:.1f} µT by up to {worst:.1f} µT and its dip by up to "
                                   f"{worst_dip:.0f} deg (steel or electronics nearby); magnetic heading not used"})
        return out

    def _gnss_inaccurate(self, gnss: pd.DataFrame) -> tuple[np.ndarray, list[dict]]:
        """Valid fixes whose reported ``h_acc_m`` is above ``max_h_acc_m``, and one fault row per run of them."""
        if "h_acc_m" not in gnss.columns or "t_s" not in gnss.columns:
            return np.zeros(len(gnss), bool), []
        t = gnss["t_s"].to_numpy(float)
        acc = gnss["h_acc_m"].to_numpy(float)
        position = np.isfinite(gnss[[c for c in ("e_m", "n_m") if c in gnss.columns]].to_numpy(float)).all(axis=1)
        inaccurate = position & np.isfinite(t) & (acc > self.max_h_acc_m)
        idx = np.flatnonzero(position & np.isfinite(t))
        out = []
        for a, b in runs(inaccurate[idx]):
            rows = idx[a:b]
            out.append({"kind": "gnss_inaccurate", "sensor": "gnss", "t_start_s": float(t[rows[0]]),
                        "t_end_s": float(t[rows[-1]]),
                        "message": f"{len(rows)} GNSS fix(es) reporting h_acc_m {float(np.min(acc[rows])):.1f} m or worse "
                                   f"(limit max_h_acc_m = {self.max_h_acc_m:g} m); not used"})
        return inaccurate, out

    def _gnss_jumps(self, gnss: pd.DataFrame, skip: np.ndarray) -> tuple[np.ndarray, list[dict]]:
        """Fixes that jumped (see the class docstring); rows where ``skip`` is True take no part."""
        for c in ("t_s", "e_m", "n_m"):
            if c not in gnss.columns:
                raise InputError(f"gnss: expected columns t_s, e_m, n_m, found {', '.join(map(str, gnss.columns))}")
        t = gnss["t_s"].to_numpy(float)
        en = gnss[["e_m", "n_m"]].to_numpy(float)
        acc = gnss["h_acc_m"].to_numpy(float) if "h_acc_m" in gnss.columns else np.full(len(t), np.nan)
        acc = np.where(np.isfinite(acc) & (acc > 0), acc, self.default_h_acc_m)
        suspect = np.zeros(len(t), bool)
        idx = np.flatnonzero(np.isfinite(en).all(axis=1) & np.isfinite(t) & ~skip)
        if len(idx) < 2:
            return suspect, []

        def consistent(i: int, j: int) -> bool:
            limit = self.max_speed_mps * abs(t[j] - t[i]) + self.gnss_sigma_factor * np.hypot(acc[i], acc[j])
            return bool(np.hypot(*(en[j] - en[i])) <= limit)

        # runs of consecutive consistent fixes
        breaks = [k + 1 for k in range(len(idx) - 1) if not consistent(idx[k], idx[k + 1])]
        bounds = [0, *breaks, len(idx)]
        segs = [idx[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
        span = [(t[s[-1]] - t[s[0]], len(s)) for s in segs]
        seed = max(range(len(segs)), key=lambda k: span[k])
        trusted = np.zeros(len(segs), bool)
        trusted[seed] = True

        def agrees(j: int, track: list[int]) -> bool:
            # with most of the nearest trusted fixes (one outlier at a run's end does not decide alone)
            votes = [consistent(i, j) for i in track[:self.GNSS_VOTES]]
            return 2 * sum(votes) > len(votes)

        before = list(segs[seed][::-1])  # trusted fixes, nearest first
        for k in range(seed + 1, len(segs)):  # forward: against the trusted fixes before
            if agrees(segs[k][0], before):
                trusted[k] = True
                before = list(segs[k][::-1]) + before
        after = list(segs[seed])
        for k in range(seed - 1, -1, -1):  # backward: against the trusted fixes after
            if agrees(segs[k][-1], after):
                trusted[k] = True
                after = list(segs[k]) + after
        out = []
        for k in np.flatnonzero(~trusted):
            s = segs[k]
            suspect[s] = True
        for a, b in runs(suspect[idx]):
            rows = idx[a:b]
            good = idx[~suspect[idx]]
            dist = 0.0
            if len(good):
                ref = en[good[np.clip(np.searchsorted(t[good], t[rows]), 0, len(good) - 1)]]
                dist = float(np.max(np.hypot(*(en[rows] - ref).T)))
            out.append({"kind": "gnss_jump", "sensor": "gnss", "t_start_s": float(t[rows[0]]), "t_end_s": float(t[rows[-1]]),
                        "message": f"{len(rows)} GNSS fix(es) jumped about {dist:.0f} m away from the consistent track while "
                                   f"reporting h_acc_m {float(np.min(acc[rows])):.1f} m or better; not used"})
        return suspect, out
