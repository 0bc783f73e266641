"""Walking bouts and the external mechanical work of walking (Ladetto et al. 2000, section 6 and Table 1).

Per walking bout (``bouts.csv``): duration, steps, distance, speed, cadence, step length and its variability, and the
mechanics of the trunk per step:

- ``vertical_lift_m``: the rise of the trunk within a step, the sum of the *positive* height increments (the seed's
  convention: work is done lifting the body, lowering it is not counted), after removing the step's straight climb
  (a slope is not a lift);
- ``speed_variation_mps``: the range (max - min) of the forward speed within a step, around the average speed;
- ``power_gravity_w`` = m g (sum of lifts) / time, ``power_inertia_w`` = (sum of positive increments of the forward
  kinetic energy 1/2 m v^2) / time, ``power_external_w`` = (sum of positive increments of E_p + E_k) / time: the total
  external work of Cavagna et al. (1963, 1976), smaller than the sum of the two because potential and kinetic energy
  are exchanged (the inverted pendulum, the seed's "rolling egg").

Values per bout are means over its steps (lift, speed variation) and totals over their time (powers); the steps are
the intervals between consecutive contacts of a bout, the first contact's step (from standing) excluded.

Sources of the trunk's motion, in this order:

1. a trunk IMU (placement ``waist`` or ``trunk``), from the earth-frame acceleration low-passed at
   ``KINEMATICS_CUTOFF_HZ`` (zero lag). The vertical is the accelerometer's mean direction over a whole stride
   (Moe-Nilssen 1998, Clin Biomech 13:320-327; a stride cancels the gait's periodic accelerations) turned by the
   gyroscope's integrated rate about its own mean (small angles), so the trunk's pitch oscillation does not leak
   gravity into the forward acceleration. The forward axis is fixed on the trunk: the principal direction of the
   step-averaged horizontal acceleration in the sensor frame (the lateral acceleration changes sign with the stance
   leg and averages out), signed so that the forward speed is lowest when the trunk is highest (inverted pendulum:
   kinetic and potential energy fluctuate in opposition, Cavagna et al. 1976).

   - Height: double integration within each step, drift removed between contacts: the acceleration's mean over the
     step is removed (equal vertical velocities at consecutive contacts), then the velocity's (equal heights), the
     drift removal of Zijlstra & Hof (2003, Gait & Posture 18:1-10) for the trunk's vertical displacement, per step.
   - Forward speed: a complementary filter (Higgins 1975): below ``SPEED_CROSSOVER_HZ`` the step speeds (step length
     over duration), above it the integrated forward acceleration, so the speed may change from one step to the
     next; each step's mean is then its step speed. The sensor rides on the lower back, above the hip joints, and
     the pelvis pitches twice per stride: the sensor's velocity is the hips' plus the lever arm's rotation,
     ``v_sensor = v_hip + omega x r`` (rigid-body kinematics), so ``omega x r`` is removed along the forward axis,
     with ``omega`` the gyroscope's rate (low-passed as the acceleration) and ``r`` the sensor's height above the
     hips (:func:`sensor_above_hip_m`) along the up direction.
2. GNSS with a high rate and centimetre precision (the seed: DGPS at 5 Hz): heights and horizontal speed from the
   fixes, linearly interpolated between fixes. Fixes slower than ``MIN_GNSS_RATE_HZ``, without an altitude or with a
   median ``h_acc_m`` above ``MAX_GNSS_H_ACC_M`` (or none) are not used (said once).

Without a trunk sensor (phone in a pocket or a hand, a foot IMU...) and without such GNSS the mechanics columns are
empty, and without ``[subject] mass_kg`` the powers are (a warning once each).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.signal import butter, sosfiltfilt

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.io.recording import TRUNK_PLACEMENTS
from pdr.schema import BOUT_COLUMNS
from pdr.signals.resample import UniformImu
from pdr.step_length.models import LEG_LENGTH_PER_HEIGHT

STEP_COLUMNS = ("bout_id", "t_start_s", "t_end_s", "speed_mps", "lift_m", "speed_range_mps", "work_gravity_j",
                "work_inertia_j", "work_external_j")
MIN_GNSS_RATE_HZ = 4.5  # the seed's DGPS ran at 5 Hz: about three fixes per step
MAX_GNSS_H_ACC_M = 0.05  # differential code and phase solutions agree within 5 cm (the seed, after Perrin 1999)
GNSS_GRID_HZ = 50.0  # the fixes are interpolated onto this grid to be cut at the contacts
MISSED_CONTACT_RATIO = 1.6  # a step interval this many times the bout's median spans a missed contact: no mechanics
KINEMATICS_CUTOFF_HZ = 10.0  # five harmonics of a fast cadence (2 steps/s): the gait's trunk motion; noise above
DECIMATED_RATE_FACTOR = 5.0  # the low-passed signals are integrated at >= 5 x the cutoff (every k-th sample)
MEAN_TILT_WINDOW_S = 2.0  # vertical window outside the steps: a whole stride even at 1 step/s
WAVEFORM_BINS = 32  # phase bins of the step-averaged horizontal acceleration (forward axis)
SPEED_CROSSOVER_HZ = 0.25  # half the left/right alternation of slow walking (1 step/s): step-to-step changes pass


# ----------------------------------------------------------------------------------------------------------------
# Steps as segments of a sampled signal
# ----------------------------------------------------------------------------------------------------------------


def step_intervals(t_contact_s: np.ndarray, bout_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``k`` of the contacts that end a step inside a bout (contact ``k - 1`` starts it) and a mask of those
    whose duration is a single step (not longer than ``MISSED_CONTACT_RATIO`` times the bout's median)."""
    t, b = np.asarray(t_contact_s, float), np.asarray(bout_id)
    k = np.flatnonzero(b[1:] == b[:-1]) + 1
    dur = t[k] - t[k - 1]
    single = np.ones(len(k), bool)
    for bout in np.unique(b[k]):
        m = b[k] == bout
        single[m] = dur[m] <= MISSED_CONTACT_RATIO * np.median(dur[m])
    return k, single & (dur > 0)


def _segments(t_s: np.ndarray, t_start_s: np.ndarray, t_end_s: np.ndarray) -> np.ndarray:
    """Segment index of each sample (``-1`` outside every ``[t_start, t_end)``); the segments are sorted, disjoint."""
    j = np.searchsorted(t_start_s, t_s, side="right") - 1
    inside = (j >= 0) & (t_s < t_end_s[np.maximum(j, 0)])
    return np.where(inside, j, -1)


def _per_segment_mean(x: np.ndarray, seg: np.ndarray, n: int) -> np.ndarray:
    ok = seg >= 0
    cnt = np.bincount(seg[ok], minlength=n)
    return np.bincount(seg[ok], weights=x[ok], minlength=n) / np.maximum(cnt, 1)


def _integrate_per_segment(x: np.ndarray, seg: np.ndarray, dt_s: float) -> np.ndarray:
    """Running integral of ``x`` restarting at 0 at the first sample of each segment (rectangle rule: the integral up
    to half a sample after each sample)."""
    c = np.cumsum(x * dt_s)
    first = np.flatnonzero((seg >= 0) & np.r_[True, seg[1:] != seg[:-1]])
    base = np.zeros(len(x))
    base[first] = c[first] - x[first] * dt_s
    start = np.maximum.accumulate(np.where(np.r_[True, seg[1:] != seg[:-1]], np.arange(len(x)), 0))
    return c - base[start]


def step_energies(t_s: np.ndarray, z_m: np.ndarray, v_mps: np.ndarray, t_start_s: np.ndarray, t_end_s: np.ndarray,
                  mass_kg: float | None) -> pd.DataFrame:
    """Lift, forward-speed range and positive work of each step from a sampled trunk height and forward speed.

    ``t_s`` increasing; steps ``[t_start_s, t_end_s)`` sorted and disjoint. The height's straight climb over each step
    is removed; then the lift is the sum of its positive increments, and the works are the sums of the positive
    increments of m g z (gravity), 1/2 m v^2 (inertia) and their sum (external). Works are NaN without a mass.
    Returns ``lift_m, speed_range_mps, work_gravity_j, work_inertia_j, work_external_j`` (one row per step; NaN
    where a step holds fewer than two samples).
    """
    t_s, z_m, v_mps = (np.asarray(a, float) for a in (t_s, z_m, v_mps))
    n = len(t_start_s)
    seg = _segments(t_s, np.asarray(t_start_s, float), np.asarray(t_end_s, float))
    same = (seg[1:] == seg[:-1]) & (seg[1:] >= 0)
    s = seg[1:][same]
    cnt = np.bincount(seg[seg >= 0], minlength=n)
    # the straight line through each step's first and last samples
    idx = np.arange(len(t_s))
    ok = seg >= 0
    first, last = np.full(n, len(t_s)), np.full(n, -1)
    np.minimum.at(first, seg[ok], idx[ok])
    np.maximum.at(last, seg[ok], idx[ok])
    has = cnt >= 2
    f, la = np.where(has, first, 0), np.where(has, last, 0)
    slope = np.where(has, (z_m[la] - z_m[f]) / np.where(has, t_s[la] - t_s[f], 1.0), 0.0)
    dz = np.diff(z_m)[same] - slope[s] * np.diff(t_s)[same]
    de_k = 0.5 * np.diff(v_mps**2)[same]

    def positive(x):
        return np.bincount(s, weights=np.maximum(x, 0.0), minlength=n)

    lift = np.where(has, positive(dz), np.nan)
    vmax = np.full(n, -np.inf)
    vmin = np.full(n, np.inf)
    np.maximum.at(vmax, seg[ok], v_mps[ok])
    np.minimum.at(vmin, seg[ok], v_mps[ok])
    out = {"lift_m": lift, "speed_range_mps": np.where(has, vmax - vmin, np.nan)}
    m = float(mass_kg) if mass_kg is not None else np.nan
    out["work_gravity_j"] = m * GRAVITY_MPS2 * lift
    out["work_inertia_j"] = np.where(has, m * positive(de_k), np.nan)
    out["work_external_j"] = np.where(has, m * positive(GRAVITY_MPS2 * dz + de_k), np.nan)
    return pd.DataFrame(out)


# ----------------------------------------------------------------------------------------------------------------
# Trunk IMU
# ----------------------------------------------------------------------------------------------------------------


def _window_mean(x: np.ndarray, width_n: np.ndarray) -> np.ndarray:
    """Centred mean of ``x`` (N, 3) over a window of ``width_n[i]`` samples (fractional: the end samples weighted by
    the part inside; shrinking at the ends of the record)."""
    i = np.arange(len(x)) + 0.5  # sample i covers [i, i + 1) in the index of the running sums
    lo, hi = np.clip(i - 0.5 * width_n, 0, len(x)), np.clip(i + 0.5 * width_n, 0, len(x))
    k = np.arange(len(x) + 1)
    out = np.empty(x.shape)
    for j in range(x.shape[1]):  # a column at a time: a long recording holds one column's running sums
        c = np.concatenate([[0.0], np.cumsum(x[:, j])])  # c[k]: sum of the first k samples
        out[:, j] = np.interp(hi, k, c) - np.interp(lo, k, c)
    out /= (hi - lo)[:, None]
    return out


def _up_in_sensor(acc_mps2: np.ndarray, angle_rad: np.ndarray | None, width_n: np.ndarray) -> np.ndarray:
    """Unit up direction in the sensor frame per sample: the accelerometer's mean direction over a window of
    ``width_n`` samples (a whole stride: the gait's periodic accelerations cancel), turned by the gyroscope's
    integrated rate ``angle_rad`` about its mean over the same window (small angles: ``u(t) = u_mean - theta x
    u_mean``)."""
    up = _window_mean(acc_mps2, width_n)
    up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-9)
    if angle_rad is not None:
        turn = _window_mean(angle_rad, width_n)
        np.subtract(angle_rad, turn, out=turn)
        up -= np.cross(turn, up)
        del turn
        up /= np.maximum(np.linalg.norm(up, axis=1, keepdims=True), 1e-9)
    return up


def sensor_above_hip_m(subject: dict | None) -> float:
    """Height of a trunk sensor above the hip joints from ``meta.toml`` ``[subject]``: ``sensor_height_m`` minus the
    standing hip height (``leg_length_m``, else 0.53 ``height_m``: greater-trochanter height, Winter 2009). 0 without
    ``sensor_height_m`` or a hip height (the sensor taken at the hips, as the inverted-pendulum step model takes it)
    and where the sensor is measured below the hips."""
    subject = subject or {}
    sensor, leg, height = (subject.get(k) for k in ("sensor_height_m", "leg_length_m", "height_m"))
    hip = leg if leg is not None else (LEG_LENGTH_PER_HEIGHT * height if height is not None else None)
    if sensor is None or hip is None:
        return 0.0
    return max(float(sensor) - float(hip), 0.0)


def _lowpass(x: np.ndarray, rate_hz: float, every: int = 1) -> np.ndarray:
    """Zero-lag low-pass at ``KINEMATICS_CUTOFF_HZ`` (second-order Butterworth, forward and backward) of each column
    of ``x``, then every ``every``-th sample (a column at a time: a long recording's filter copies stay a column's)."""
    if rate_hz <= 2.5 * KINEMATICS_CUTOFF_HZ:
        return x[::every]
    sos = butter(2, KINEMATICS_CUTOFF_HZ, fs=rate_hz, output="sos")
    return np.stack([sosfiltfilt(sos, x[:, j])[::every] for j in range(x.shape[1])], axis=1)


def _complementary_speed(t_s: np.ndarray, a_fwd_mps2: np.ndarray, lever_mps: np.ndarray, seg: np.ndarray,
                         t_start_s: np.ndarray, t_end_s: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
    """Forward speed of the hips per sample: the step speeds below ``SPEED_CROSSOVER_HZ`` and the integrated forward
    acceleration minus the lever arm's velocity ``lever_mps`` above (a complementary filter, Higgins 1975, IEEE Trans.
    Aerosp. Electron. Syst. 11:321-325), over each run of consecutive steps; then each step's mean is set to its step
    speed. NaN outside the steps."""
    n = len(t_start_s)
    rate = 1.0 / (t_s[1] - t_s[0])
    mid = 0.5 * (t_start_s + t_end_s)
    run = np.cumsum(np.r_[True, t_start_s[1:] != t_end_s[:-1]]) - 1  # consecutive steps share a contact
    label = np.where(seg >= 0, run[np.maximum(seg, 0)], -1)
    edges = np.flatnonzero(np.diff(np.r_[-2, label, -2]))  # blocks of samples with one run label
    sos = butter(2, SPEED_CROSSOVER_HZ, btype="low", fs=rate, output="sos")
    out = np.full(len(t_s), np.nan)
    for i0, i1 in zip(edges[:-1], edges[1:]):
        r = label[i0]
        if r < 0 or i1 - i0 < 2:
            continue
        steps = np.flatnonzero(run == r)
        a = a_fwd_mps2[i0:i1]
        v_int = (np.cumsum(a) - 0.5 * a) / rate - lever_mps[i0:i1]  # trapezoid: the velocity at the samples
        drift = v_int - np.interp(t_s[i0:i1], mid[steps], speed_mps[steps])
        out[i0:i1] = v_int - sosfiltfilt(sos, drift, padlen=min(i1 - i0 - 1, int(rate / SPEED_CROSSOVER_HZ)))
    ok = np.isfinite(out)
    mean = np.bincount(seg[ok], weights=out[ok], minlength=n) / np.maximum(np.bincount(seg[ok], minlength=n), 1)
    return out - mean[np.maximum(seg, 0)] + speed_mps[np.maximum(seg, 0)]


def trunk_motion(u: UniformImu, t_start_s: np.ndarray, t_end_s: np.ndarray, speed_mps: np.ndarray,
                 sensor_above_hip_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trunk height (m) and forward speed (m/s) of the hips (module docstring), on the IMU grid thinned to at least
    ``DECIMATED_RATE_FACTOR`` x the low-pass cutoff.

    ``speed_mps``: the average speed of each step (its length over its duration). ``sensor_above_hip_m``: the lever
    arm whose rotation is removed from the forward speed (with a gyroscope). Returns ``(t_s, z_m, v_mps)``
    restricted to the samples inside the steps (and valid).
    """
    n = len(t_start_s)
    every = max(1, int(u.rate_hz // (DECIMATED_RATE_FACTOR * KINEMATICS_CUTOFF_HZ)))  # after the low-pass
    rate = u.rate_hz / every
    dt = 1.0 / rate
    t_s = u.t_s[::every]
    seg = _segments(t_s, t_start_s, t_end_s)
    seg = np.where(u.valid[::every], seg, -1)
    bad = np.bincount(seg[seg >= 0], minlength=n) < 2
    acc = _lowpass(u.acc_mps2, u.rate_hz, every)
    if u.gyr_radps is None:
        angle = None
    else:  # the integrated rate at each sample's own time (trapezoid rule)
        angle = (np.cumsum(u.gyr_radps, axis=0)[::every] - 0.5 * u.gyr_radps[::every]) / u.rate_hz
    # the mean over one stride (a step each side) inside the steps, MEAN_TILT_WINDOW_S elsewhere
    stride_s = np.where(seg >= 0, 2.0 * (t_end_s - t_start_s)[np.maximum(seg, 0)], MEAN_TILT_WINDOW_S)
    up = _up_in_sensor(acc, angle, stride_s * rate)
    del angle, stride_s  # here and below: a long recording's arrays freed once used
    a_up = np.einsum("ij,ij->i", acc, up)
    a_h = acc - a_up[:, None] * up
    del acc

    def detrended_double(a):
        """Velocity half a sample after each sample and position at the samples (midpoint rule), both zero-mean
        and equal at the step's ends."""
        a = a - _per_segment_mean(a, seg, n)[np.maximum(seg, 0)]
        v = _integrate_per_segment(a, seg, dt)
        v = v - _per_segment_mean(v, seg, n)[np.maximum(seg, 0)]
        return v, _integrate_per_segment(v, seg, dt) - v * dt

    _, z = detrended_double(a_up)
    del a_up
    # forward axis: principal direction of the step-averaged horizontal acceleration (lateral cancels over L/R)
    ok = seg >= 0
    a_hc = a_h - np.stack([_per_segment_mean(a_h[:, i], seg, n) for i in range(3)], 1)[np.maximum(seg, 0)]
    phase = (t_s - t_start_s[np.maximum(seg, 0)]) / (t_end_s - t_start_s)[np.maximum(seg, 0)]
    b = np.clip((phase * WAVEFORM_BINS).astype(int), 0, WAVEFORM_BINS - 1)[ok]
    wave = np.stack([np.bincount(b, weights=a_hc[ok, i], minlength=WAVEFORM_BINS) for i in range(3)], 1)
    fwd = np.linalg.svd(wave, full_matrices=False)[2][0]
    del a_hc, phase, b
    a_fwd = a_h @ fwd
    del a_h
    lever = np.zeros(len(t_s))  # the velocity of the sensor about the hips, omega x r, along the forward axis
    if u.gyr_radps is not None and sensor_above_hip_m > 0:  # (w x r up) . fwd = w . (r up x fwd)
        lever = np.einsum("ij,ij->i", _lowpass(u.gyr_radps, u.rate_hz, every), np.cross(sensor_above_hip_m * up, fwd))
    del up
    dv, _ = detrended_double(a_fwd)
    dv -= lever - _per_segment_mean(lever, seg, n)[np.maximum(seg, 0)]
    if np.sum(dv[ok] * z[ok]) > 0:  # forward speed lowest when the trunk is highest
        a_fwd, lever = -a_fwd, -lever
    v = _complementary_speed(t_s, a_fwd, lever, seg, t_start_s, t_end_s, np.asarray(speed_mps, float))
    keep = ok & ~bad[np.maximum(seg, 0)]
    return t_s[keep], z[keep], v[keep]


# ----------------------------------------------------------------------------------------------------------------
# GNSS
# ----------------------------------------------------------------------------------------------------------------


def gnss_usable(gnss: pd.DataFrame | None) -> tuple[bool, str]:
    """Whether fixes ``t_s, e_m, n_m, u_m, h_acc_m`` are fast and precise enough for the mechanics, and why not."""
    if gnss is None or len(gnss) < 3:
        return False, "no GNSS"
    ok = np.isfinite(gnss[["e_m", "n_m"]].to_numpy(float)).all(axis=1)
    if "u_m" not in gnss.columns or not np.isfinite(gnss["u_m"].to_numpy(float)[ok]).any():
        return False, "GNSS without altitude"
    rate = 1.0 / float(np.median(np.diff(gnss["t_s"].to_numpy(float)[ok]))) if ok.sum() > 2 else 0.0
    h_acc = float(np.nanmedian(gnss["h_acc_m"].to_numpy(float)[ok])) if ok.any() and np.isfinite(gnss["h_acc_m"]).any() else np.nan
    if rate < MIN_GNSS_RATE_HZ:
        return False, f"GNSS at {rate:.1f} Hz (needs >= {MIN_GNSS_RATE_HZ:g} Hz)"
    if not h_acc <= MAX_GNSS_H_ACC_M:
        return False, f"GNSS with median h_acc_m {h_acc:.2f} m (needs <= {MAX_GNSS_H_ACC_M:g} m)"
    return True, ""


def gnss_motion(gnss: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Height and horizontal speed from the fixes, interpolated linearly on a ``GNSS_GRID_HZ`` grid."""
    g = gnss[np.isfinite(gnss[["e_m", "n_m", "u_m"]].to_numpy(float)).all(axis=1)]
    t = g["t_s"].to_numpy(float)
    e, n, h = (g[c].to_numpy(float) for c in ("e_m", "n_m", "u_m"))
    speed = np.hypot(np.diff(e), np.diff(n)) / np.diff(t)
    t_mid = 0.5 * (t[1:] + t[:-1])
    grid = np.arange(t[0], t[-1], 1.0 / GNSS_GRID_HZ)
    return grid, np.interp(grid, t, h), np.interp(grid, t_mid, speed)


# ----------------------------------------------------------------------------------------------------------------
# Bouts
# ----------------------------------------------------------------------------------------------------------------


def bout_table(steps: pd.DataFrame, step_mech: pd.DataFrame) -> pd.DataFrame:
    """One row per bout of ``steps`` (``t_s, bout_id, step_length_m``) with the mechanics of its steps."""
    t = steps["t_s"].to_numpy(float)
    bout = steps["bout_id"].to_numpy(int)
    length = steps["step_length_m"].to_numpy(float)
    rows = []
    for b in pd.unique(bout):
        idx = np.flatnonzero(bout == b)
        t0, t1 = float(t[idx[0]]), float(t[idx[-1]])
        inner = length[idx[1:]]
        dur = t1 - t0
        mech = step_mech[step_mech["bout_id"] == b]
        mech = mech[np.isfinite(mech["lift_m"].to_numpy(float))]
        time_s = float((mech["t_end_s"] - mech["t_start_s"]).sum())
        row = {"bout_id": int(b), "t_start_s": t0, "t_end_s": t1, "n_steps": len(idx),
               "distance_m": float(length[idx].sum()),
               "speed_mps": float(inner.sum() / dur) if dur > 0 else np.nan,
               "cadence_spm": 60.0 * (len(idx) - 1) / dur if dur > 0 else np.nan,
               "step_length_m": float(inner.mean()) if len(inner) else np.nan,
               "step_length_cv": float(inner.std(ddof=1) / inner.mean()) if len(inner) > 1 and inner.mean() > 0 else np.nan,
               "vertical_lift_m": float(mech["lift_m"].mean()) if len(mech) else np.nan,
               "speed_variation_mps": float(mech["speed_range_mps"].mean()) if len(mech) else np.nan}
        for kind in ("gravity", "inertia", "external"):
            row[f"power_{kind}_w"] = float(mech[f"work_{kind}_j"].sum(min_count=1) / time_s) if time_s > 0 else np.nan
        rows.append(row)
    out = pd.DataFrame(rows, columns=BOUT_COLUMNS[:-1])
    return out.astype({"bout_id": int, "n_steps": int})


def walking_bouts(steps: pd.DataFrame, *, placement: str, imu: UniformImu | None = None,
                  gnss: pd.DataFrame | None = None, mass_kg: float | None = None, sensor_above_hip_m: float = 0.0,
                  what: str = "recording") -> tuple[pd.DataFrame, pd.DataFrame]:
    """``bouts.csv`` and the per-step mechanics (``STEP_COLUMNS``) of a steps table.

    ``steps``: ``t_s, bout_id, step_length_m`` (contacts, sorted). ``imu``: the main IMU on a uniform grid, used when
    ``placement`` is a trunk placement (``sensor_above_hip_m``: its height above the hips, :func:`sensor_above_hip_m`);
    else ``gnss`` (``t_s, e_m, n_m, u_m, h_acc_m``) when fast and precise enough.
    Warnings (once each): no source of trunk motion, GNSS not usable, no body mass, bouts of one step.
    """
    missing = [c for c in ("t_s", "bout_id", "step_length_m") if c not in steps.columns]
    if missing:
        raise InputError(f"{what}: expected a steps table with t_s, bout_id, step_length_m, found {', '.join(map(str, steps.columns)) or 'no columns'}")
    if mass_kg is not None and not (np.isfinite(mass_kg) and mass_kg > 0):
        raise InputError(f"{what}: expected a body mass > 0 kg, found {mass_kg!r}")
    steps = steps.sort_values("t_s", kind="stable")
    t = steps["t_s"].to_numpy(float)
    bout = steps["bout_id"].to_numpy(int)
    length = steps["step_length_m"].to_numpy(float)
    k, single = step_intervals(t, bout)
    k = k[single]
    t0, t1 = t[k - 1], t[k]
    step_mech = pd.DataFrame({"bout_id": bout[k], "t_start_s": t0, "t_end_s": t1, "speed_mps": length[k] / (t1 - t0)})
    source = ""
    trunk = placement in TRUNK_PLACEMENTS and imu is not None
    usable, why = gnss_usable(gnss)
    if len(k) and trunk:
        source = "trunk_imu"
        motion = trunk_motion(imu, t0, t1, step_mech["speed_mps"].to_numpy(), sensor_above_hip_m)
    elif len(k) and usable:
        source = "gnss"
        motion = gnss_motion(gnss)
    if source:
        if mass_kg is None:
            warn(f"{what}: no [subject] mass_kg in meta.toml: the powers of bouts.csv are empty")
        energies = step_energies(*motion, t0, t1, mass_kg)
    else:
        if len(k):
            gnss_part = "" if gnss is None else f"; {why}: not used for the mechanics"
            warn(f"{what}: placement {placement!r} does not move with the trunk{gnss_part}: the mechanics "
                 f"columns of bouts.csv are empty")
        energies = pd.DataFrame(np.nan, index=range(len(k)), columns=list(STEP_COLUMNS[4:]))
    step_mech = pd.concat([step_mech, energies.set_index(step_mech.index)], axis=1)
    bouts = bout_table(steps, step_mech)
    bouts["mechanics_source"] = source
    one = int((bouts["n_steps"] == 1).sum())
    if one:
        warn(f"{what}: {one} bout(s) of one step: no speed, cadence or mechanics for them")
    return bouts, step_mech[list(STEP_COLUMNS)]
