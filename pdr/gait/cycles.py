"""Gait cycles and their Fourier features (Watanabe et al., section 3, eq. 2).

A gait cycle is a stride: two consecutive steps, the phase running from 0 to 2*pi. Each gait parameter sampled over
the cycle is represented by its Fourier expansion to the 5th order (:mod:`pdr.gait.fourier`); the coefficients of all
parameters, plus a few per-cycle scalars, are the cycle's feature vector.

Two sources of cycles, with different feature layouts (a forms file remembers its layout):

- **Body-worn IMU** (waist, trunk, pocket, hand): :func:`imu_cycles` cuts the steps found by the step pipeline
  (``pdr.pipelines.steps.detect_steps``: contact times, bouts, per-step heading) into strides of two steps within a
  bout. The phase is piecewise linear: 0 at the first contact, pi at the middle one, 2*pi at the last. Parameters:
  vertical, antero-posterior and medio-lateral acceleration (earth frame, gravity removed; the antero-posterior axis
  is the step pipeline's walking direction) and the angular rates about the antero-posterior (roll), medio-lateral
  (pitch) and vertical (yaw) axes; scalars: speed (step lengths of the step model / duration), turn rate (sum of the
  per-step heading changes / duration) and step frequency.
  A trunk sensor cannot tell a stride that starts with the left foot from one that starts with the right; the two
  differ by a phase shift of pi, which flips the sign of every odd harmonic. The cycles of a recording are put in
  one convention: the first harmonic of the medio-lateral acceleration (the sway towards the stance leg, which
  alternates each step) is aligned with its recording-wide principal axis (the doubled-angle mean), whose sign is
  fixed physically (left-positive medio-lateral axis: the pelvis accelerates to the right in the first half of the
  cycle, b1 < 0), so phase 0 is always the contact of the same foot.
- **Shoe IMU**: :func:`foot_cycles` takes the stance phases of :class:`pdr.foot.ZeroVelocityDetection` (a stride runs
  from one mid-stance to the next, as ``pdr.foot``'s stride estimators) and the data-derived foot frame of
  :func:`pdr.foot.estimate_foot_frame` (x right of the walking direction, y forward, z up), so the features do not
  depend on how the sensor sits on the shoe. The phase is linear in time. Parameters: forward, up and lateral
  acceleration and the pitch, roll and yaw rates in the foot frame; the left foot is mirrored onto the right
  (lateral acceleration, roll and yaw rate change sign) so both feet share one layout. Scalars: speed and climb rate
  from the stride displacement (:func:`pdr.foot.frame.swing_displacements`, zero velocity at both mid-stances), turn
  rate and stride frequency.

Cycles shorter than ``MIN_CYCLE_S`` or longer than ``MAX_CYCLE_S`` are not gait (a stop inside a bout, a missed or an
extra contact) and are dropped with a warning, as are cycles over a gap of the IMU clock.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError, warn
from pdr.foot import ZeroVelocityDetection, estimate_foot_frame
from pdr.foot.frame import swing_displacements
from pdr.gait.fourier import DEFAULT_ORDER, coefficient_names, fourier_coefficients, n_coefficients
from pdr.signals.attitude import Attitude, earth_acceleration, rotate
from pdr.signals.resample import UniformImu

# A stride of 0.5 s is two steps at 4 Hz (a sprint cadence); one of 2.5 s is two steps at 0.8 Hz (48 steps/min, the
# slowest cadence still counted as walking). Outside this range the "cycle" is a stop or a detection error.
MIN_CYCLE_S = 0.5
MAX_CYCLE_S = 2.5

IMU_CHANNELS = ("acc_v_mps2", "acc_ap_mps2", "acc_ml_mps2", "gyr_roll_radps", "gyr_pitch_radps", "gyr_yaw_radps")
IMU_SCALARS = ("speed_mps", "turn_rate_radps", "step_freq_hz")
FOOT_CHANNELS = ("acc_fwd_mps2", "acc_up_mps2", "acc_lat_mps2", "gyr_pitch_radps", "gyr_roll_radps", "gyr_yaw_radps")
FOOT_SCALARS = ("speed_mps", "climb_rate_mps", "turn_rate_radps", "step_freq_hz")
CYCLE_COLUMNS = ["t_start_s", "t_end_s", "duration_s", "source", "bout_id", "speed_mps", "turn_rate_radps",
                 "step_freq_hz", "climb_rate_mps"]
IMU_SOURCE = "imu"
_FLIP_CHANNEL = "acc_ml_mps2"


def feature_columns(channels, scalars, order: int = DEFAULT_ORDER) -> list[str]:
    """The feature layout: ``<channel>_<coef>`` for every channel and coefficient (a0, a1, b1, ...), then the scalars."""
    return [f"{ch}_{c}" for ch in channels for c in coefficient_names(order)] + list(scalars)


def imu_layout(order: int = DEFAULT_ORDER) -> list[str]:
    """Feature layout of :func:`imu_cycles`."""
    return feature_columns(IMU_CHANNELS, IMU_SCALARS, order)


def foot_layout(order: int = DEFAULT_ORDER) -> list[str]:
    """Feature layout of :func:`foot_cycles`."""
    return feature_columns(FOOT_CHANNELS, FOOT_SCALARS, order)


def empty_cycles(layout: list[str]) -> pd.DataFrame:
    """A correctly typed cycles table without rows."""
    cols = {c: pd.Series(dtype=float) for c in CYCLE_COLUMNS}
    cols["source"] = pd.Series(dtype=object)
    cols["bout_id"] = pd.Series(dtype=int)
    cols.update({c: pd.Series(dtype=float) for c in layout if c not in cols})
    return pd.DataFrame(cols)


def _duration_ok(t0: np.ndarray, t1: np.ndarray, what: str) -> np.ndarray:
    dur = t1 - t0
    ok = (dur >= MIN_CYCLE_S) & (dur <= MAX_CYCLE_S)
    if (~ok).any():
        short, long_ = int((dur < MIN_CYCLE_S).sum()), int((dur > MAX_CYCLE_S).sum())
        warn(f"{what}: {int((~ok).sum())} cycle(s) dropped as not gait ({short} shorter than {MIN_CYCLE_S:g} s, "
             f"{long_} longer than {MAX_CYCLE_S:g} s)")
    return ok


def _fit_cycles(t_grid: np.ndarray, signals: np.ndarray, valid: np.ndarray, knots: list[np.ndarray], order: int,
                what: str) -> tuple[np.ndarray, np.ndarray]:
    """Fourier coefficients (n_cycles, n_channels, 2K+1) of ``signals`` over cycles whose phase runs linearly between
    ``knots`` (times at phase 0, ..., 2*pi); and a mask of cycles that could be fitted."""
    n_ch = signals.shape[1]
    out = np.full((len(knots), n_ch, n_coefficients(order)), np.nan)
    ok = np.zeros(len(knots), bool)
    n_few = n_gap = 0
    for j, kn in enumerate(knots):
        a, b = np.searchsorted(t_grid, [kn[0], kn[-1]])
        if b - a < n_coefficients(order):
            n_few += 1
            continue
        if not valid[a:b].all():
            n_gap += 1
            continue
        t = t_grid[a:b]
        phase = np.interp(t, kn, np.linspace(0.0, 2.0 * np.pi, len(kn)))
        out[j] = fourier_coefficients(phase, signals[a:b], order).T
        ok[j] = True
    if n_few:
        warn(f"{what}: {n_few} cycle(s) dropped: fewer samples than the {n_coefficients(order)} Fourier "
             "coefficients (sampling rate too low)")
    if n_gap:
        warn(f"{what}: {n_gap} cycle(s) dropped: they span a gap of the IMU clock")
    return out, ok


def _flip_odd(coef: np.ndarray, flip: np.ndarray) -> np.ndarray:
    """Shift the phase of the flagged cycles by pi: odd harmonics change sign."""
    order = (coef.shape[-1] - 1) // 2
    sign = np.ones(coef.shape[-1])
    for k in range(1, order + 1, 2):
        sign[2 * k - 1:2 * k + 1] = -1.0
    out = coef.copy()
    out[flip] = out[flip] * sign
    return out


def side_convention(c1: np.ndarray) -> np.ndarray:
    """Which cycles to shift by pi so that the first harmonics ``c1 = a1 + i b1`` (complex, one per cycle) of a
    stride-periodic channel all lie on the same side of their principal axis, the side with b1 < 0."""
    c1 = np.asarray(c1, complex)
    if len(c1) == 0:
        return np.zeros(0, bool)
    mag = np.abs(c1)
    axis2 = np.sum(np.where(mag > 0, c1 ** 2 / np.maximum(mag, 1e-300), 0.0))
    u = np.exp(0.5j * np.angle(axis2)) if abs(axis2) > 0 else 1.0 + 0.0j
    if u.imag > 0 or (u.imag == 0 and u.real < 0):
        u = -u
    return (c1 * np.conj(u)).real < 0


def _forward_convention(coef: np.ndarray) -> np.ndarray:
    """Make the antero-posterior axis of every cycle point forward.

    The ground pushes the body backwards in the first half of each stance and forwards in the second (the
    antero-posterior ground reaction force, walking and running alike), so the trunk's forward acceleration over a
    step is about -sin(2 pi t / T_step): in stride phase, its second harmonic has b2 < 0. A cycle with b2 > 0 has its
    walking direction reversed (the step pipeline's direction is 180 degrees off, as it can be when running, where
    its walking phase relation does not hold): the horizontal axes are turned by 180 degrees (antero-posterior and
    medio-lateral acceleration, roll and pitch rate change sign)."""
    i_ap = IMU_CHANNELS.index("acc_ap_mps2")
    back = coef[:, i_ap, 4] > 0
    if back.any():
        coef = coef.copy()
        for ch in ("acc_ap_mps2", "acc_ml_mps2", "gyr_roll_radps", "gyr_pitch_radps"):
            coef[back, IMU_CHANNELS.index(ch)] *= -1.0
    return coef


def _table(t0, t1, source, bout, scalars: dict[str, np.ndarray], coef: np.ndarray, channels, order) -> pd.DataFrame:
    n = len(t0)
    data = {"t_start_s": t0, "t_end_s": t1, "duration_s": t1 - t0, "source": np.asarray(source, dtype=object),
            "bout_id": np.asarray(bout, int), "climb_rate_mps": np.full(n, np.nan)}
    data.update(scalars)
    names = coefficient_names(order)
    for i, ch in enumerate(channels):
        for k, c in enumerate(names):
            data[f"{ch}_{c}"] = coef[:, i, k]
    df = pd.DataFrame(data)
    front = [c for c in CYCLE_COLUMNS if c in df.columns]
    return df[front + [c for c in df.columns if c not in front]]


def imu_cycles(u: UniformImu, attitude: Attitude, steps: pd.DataFrame, *, order: int = DEFAULT_ORDER,
               what: str = "gait cycles") -> pd.DataFrame:
    """Strides of a body-worn IMU with their Fourier features (see the module docstring).

    Parameters
    ----------
    u, attitude : the IMU on its uniform grid and its attitude (:func:`pdr.signals.estimate_attitude`).
    steps : the steps table of the step pipeline: ``t_s, bout_id, heading_rad``; optional ``heading_change_rad``
        (turn rate; 0 without it) and ``step_length_m`` (speed; NaN without it).

    Returns
    -------
    One row per cycle: ``t_start_s, t_end_s, duration_s, source ("imu"), bout_id, speed_mps, turn_rate_radps,
    step_freq_hz, climb_rate_mps`` (NaN) and the features of :func:`imu_layout`. Empty (with a warning) when the
    steps give no cycle.
    """
    if not isinstance(steps, pd.DataFrame):
        raise InputError(f"{what}: expected the steps as a DataFrame, found {type(steps).__name__}")
    missing = [c for c in ("t_s", "bout_id", "heading_rad") if c not in steps.columns]
    if missing:
        raise InputError(f"{what}: expected steps columns t_s, bout_id, heading_rad, missing {', '.join(missing)}")
    if u.gyr_radps is None:
        raise InputError(f"{what}: expected a gyroscope (angular rates are gait parameters), found accelerometer only")
    layout = imu_layout(order)
    st = steps.sort_values("t_s", kind="stable").reset_index(drop=True)
    t_step = st["t_s"].to_numpy(float)
    bout = st["bout_id"].to_numpy(int)
    i0 = []
    for b in np.unique(bout):
        idx = np.flatnonzero(bout == b)
        i0 += list(idx[:-2:2]) if len(idx) >= 3 else []
    i0 = np.asarray(i0, int)
    if len(i0) == 0:
        warn(f"{what}: no gait cycle (fewer than three steps in every bout)")
        return empty_cycles(layout)
    t0, t1 = t_step[i0], t_step[i0 + 2]
    keep = _duration_ok(t0, t1, what)
    i0, t0, t1 = i0[keep], t0[keep], t1[keep]
    # body-frame-free signals: earth-frame acceleration and angular rate, horizontal axes along the walking direction
    acc_e = earth_acceleration(u.acc_mps2, attitude.q_wxyz)
    gyr_e = rotate(attitude.q_wxyz, u.gyr_radps)
    heading = np.interp(u.t_s, t_step, np.unwrap(st["heading_rad"].to_numpy(float)))
    ch, sh = np.cos(heading), np.sin(heading)
    ap = acc_e[:, 0] * ch + acc_e[:, 1] * sh
    ml = -acc_e[:, 0] * sh + acc_e[:, 1] * ch  # left-positive
    roll = gyr_e[:, 0] * ch + gyr_e[:, 1] * sh  # about the antero-posterior axis
    pitch = -gyr_e[:, 0] * sh + gyr_e[:, 1] * ch  # about the (left) medio-lateral axis
    sig = np.column_stack([acc_e[:, 2], ap, ml, roll, pitch, gyr_e[:, 2]])
    knots = [t_step[k:k + 3] for k in i0]
    coef, ok = _fit_cycles(u.t_s, sig, u.valid, knots, order, what)
    i0, t0, t1, coef = i0[ok], t0[ok], t1[ok], coef[ok]
    if len(i0) == 0:
        warn(f"{what}: no gait cycle left")
        return empty_cycles(layout)
    if order >= 2:
        coef = _forward_convention(coef)
    if order >= 1:
        m = IMU_CHANNELS.index(_FLIP_CHANNEL)
        coef = _flip_odd(coef, side_convention(coef[:, m, 1] + 1j * coef[:, m, 2]))
    dur = t1 - t0
    if "step_length_m" in st.columns:
        length = st["step_length_m"].to_numpy(float)
        speed = (length[i0 + 1] + length[i0 + 2]) / dur
    else:
        speed = np.full(len(i0), np.nan)
    if "heading_change_rad" in st.columns:
        dh = np.nan_to_num(st["heading_change_rad"].to_numpy(float))
        turn = (dh[i0 + 1] + dh[i0 + 2]) / dur
    else:
        turn = np.zeros(len(i0))
    scal = {"speed_mps": speed, "turn_rate_radps": turn, "step_freq_hz": 2.0 / dur}
    return _table(t0, t1, [IMU_SOURCE] * len(i0), bout[i0], scal, coef, IMU_CHANNELS, order)


def foot_cycles(imu: pd.DataFrame, foot: str, *, order: int = DEFAULT_ORDER,
                stance: ZeroVelocityDetection | None = None) -> pd.DataFrame:
    """Strides of one shoe IMU (mid-stance to mid-stance) with their Fourier features (see the module docstring).

    Parameters
    ----------
    imu : canonical IMU table of the shoe (``t_s``, ``acc_*_mps2``, ``gyr_*_radps``).
    foot : ``"left"`` or ``"right"`` (the left foot is mirrored onto the right).
    stance : a detection already run on ``imu`` (default: :class:`ZeroVelocityDetection` with its defaults).

    Returns
    -------
    One row per stride: the columns of :func:`imu_cycles` with ``source = "foot_<foot>"``, ``bout_id`` counting
    runs of consecutive strides, ``climb_rate_mps`` (vertical displacement / duration) and the features of
    :func:`foot_layout`. Empty (with a warning) without two stances.
    """
    if foot not in ("left", "right"):
        raise InputError(f"foot cycles: expected foot 'left' or 'right', found {foot!r}")
    what = f"{foot} foot gait cycles"
    layout = foot_layout(order)
    stance = stance if stance is not None else ZeroVelocityDetection().detect(imu)
    st = stance.stances_
    if len(st) < 2:
        warn(f"{what}: fewer than two stance phases, no gait cycle")
        return empty_cycles(layout)
    t = imu["t_s"].to_numpy(float)
    acc = imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy(float)
    gyr = imu[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy(float)
    i_mid = st["i_mid"].to_numpy(int)
    R_fs = estimate_foot_frame(acc, gyr, t, stance.stance_, i_mid)
    t0, t1 = t[i_mid[:-1]], t[i_mid[1:]]
    keep = _duration_ok(t0, t1, what)
    idx = np.flatnonzero(keep)
    if len(idx) == 0:
        warn(f"{what}: no gait cycle left")
        return empty_cycles(layout)
    a_f = acc @ R_fs.T
    w_f = gyr @ R_fs.T
    mirror = -1.0 if foot == "left" else 1.0
    # foot frame: x right (pitch axis), y forward, z up; a_up with gravity removed (at rest the foot reads +g)
    sig = np.column_stack([a_f[:, 1], a_f[:, 2] - GRAVITY_MPS2, mirror * a_f[:, 0], w_f[:, 0], mirror * w_f[:, 1],
                           mirror * w_f[:, 2]])
    valid = np.ones(len(t), bool)
    coef, ok = _fit_cycles(t, sig, valid, [np.array([t0[j], t1[j]]) for j in idx], order, what)
    idx, coef = idx[ok], coef[ok]
    if len(idx) == 0:
        return empty_cycles(layout)
    disp = swing_displacements(acc, gyr, t, i_mid)[idx] @ R_fs.T  # in the foot frame of each stride's start
    dur = t1[idx] - t0[idx]
    dt = np.diff(t)
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (w_f[1:, 2] + w_f[:-1, 2]) * dt)])
    turn = (yaw[i_mid[idx + 1]] - yaw[i_mid[idx]]) / dur
    run_id = np.concatenate([[0], np.cumsum(np.diff(idx) > 1)])
    scal = {"speed_mps": np.hypot(disp[:, 0], disp[:, 1]) / dur, "turn_rate_radps": turn, "step_freq_hz": 2.0 / dur}
    df = _table(t0[idx], t1[idx], [f"foot_{foot}"] * len(idx), run_id, scal, coef, FOOT_CHANNELS, order)
    df["climb_rate_mps"] = disp[:, 2] / dur
    return df
