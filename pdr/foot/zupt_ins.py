"""Zero-velocity-aided inertial navigation of one foot: an error-state Kalman filter (attitude, velocity, position)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.ndimage import uniform_filter1d

from pdr.base import Algorithm
from pdr.constants import GRAVITY_MPS2
from pdr.errors import warn
from pdr.foot._checks import foot_imu_arrays
from pdr.foot._rotations import align_to_gravity, cumulative_rotations
from pdr.foot.footstep_tracker import empty_strides
from pdr.foot.zero_velocity import ZeroVelocityDetection

INS_STRIDE_COLUMNS = ["t_start_s", "t_end_s", "foot", "length_m", "length_std_m", "lateral_std_m", "source", "dx_m",
                      "dy_m", "dz_m", "heading_rad", "heading_change_rad", "heading_change_std_rad", "t_swing_start_s",
                      "t_swing_end_s"]
INS_TRAJECTORY_COLUMNS = ["t_s", "x_m", "y_m", "z_m", "vx_mps", "vy_mps", "vz_mps"]


def _skew(v: np.ndarray) -> np.ndarray:
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _small_rotation(r: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for one rotation vector, on Python floats (this runs once per update: 7 us a call against
    64 us for scipy's ``Rotation.from_rotvec(r).as_matrix()``, scipy 1.17, loaded machine)."""
    x, y, z = float(r[0]), float(r[1]), float(r[2])
    a = math.sqrt(x * x + y * y + z * z)
    if a < 1e-12:
        return np.eye(3)
    x, y, z = x / a, y / a, z / a
    s, c = math.sin(a), math.cos(a)
    u = 1.0 - c
    return np.array([[c + x * x * u, x * y * u - z * s, x * z * u + y * s],
                     [y * x * u + z * s, c + y * y * u, y * z * u - x * s],
                     [z * x * u - y * s, z * y * u + x * s, c + z * z * u]])


def _inverse3(a: np.ndarray) -> np.ndarray:
    """Inverse of one 3x3 matrix by its adjugate, on Python floats (this runs once per update)."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = a.tolist()
    c00, c01, c02 = a11 * a22 - a12 * a21, a12 * a20 - a10 * a22, a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    return np.array([[c00, a02 * a21 - a01 * a22, a01 * a12 - a02 * a11],
                     [c01, a00 * a22 - a02 * a20, a02 * a10 - a00 * a12],
                     [c02, a01 * a20 - a00 * a21, a00 * a11 - a01 * a10]]) / det


def _cumtrapz(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t)[:, None], axis=0)
    return out


class ZuptInsStride(Algorithm):
    """Foot-mounted strapdown INS with zero-velocity updates in an error-state Kalman filter; per-stride
    displacement and its covariance.

    Parameters
    ----------
    foot : ``"left"`` or ``"right"`` (written in the strides table).
    acc_noise_mps2_rthz : accelerometer white-noise density of the process model, m/s^2/sqrt(Hz).
    gyr_noise_radps_rthz : gyroscope white-noise density, rad/s/sqrt(Hz). It is set well above a MEMS gyro's own
        noise: it stands for every attitude error of the swing (scale, misalignment, vibration at heel strike) and
        lets each stance's updates re-level the foot. This value and the detector's ``window_s`` are the candidate
        of ``benchmarks/bench_foot.py`` ``GRID`` with the least mean score over the declared tuning set (gaitmap
        mocap strides, x-io and OpenShoe loop closure, a simulated slow walk), each score divided by its target
        (3 cm, 0.5%); the benchmark prints each recording's score with the candidate chosen without it.
    zupt_std_mps : standard deviation of the zero-velocity pseudo-measurement of a foot that does not rotate: the
        floor under the rolling term below, for a sensor without noise. 3 mm/s is about the rolling term of a foot at
        rest (5 cm x 0.03-0.06 rad/s); 1 or 5 mm/s move the benchmark's loop closures by less than 0.02% of the path.
    sensor_above_sole_m : distance from the sensor to the point of the sole on the ground. A planted foot still rolls
        (heel strike to flat foot, heel rise): the sensor then moves at ``|w| x sensor_above_sole_m``, so each
        update's variance is ``zupt_std_mps^2 + sensor_above_sole_m^2 x`` the mean square angular rate over the
        detector's window, measured on the recording's own stance. 5 cm: a shoe's sole and heel are 2-4 cm thick,
        and a sensor on the instep or the heel cap sits some centimetres above them. It is not in the benchmark's
        leave-one-out grid, but 3-10 cm were looked at on its recordings: 3-7 cm give 0.04-0.17% (x-io) and
        0.41-0.51% (OpenShoe) loop closure and 1.8-2.6 cm gaitmap stride MAE; 10 cm gives OpenShoe 0.57%.
    zupt_rate_hz : zero-velocity updates are applied at this rate during stance (and at the first and last sample
        of every stance); between updates the error state is propagated in one exact step.
    initial_tilt_std_rad : standard deviation of roll and pitch after levelling on the first stance.
    gyr_bias_min_rest_s : when the recording starts with a rest at least this long, its mean angular rate is taken as
        the gyroscope bias (0, the default, disables it: removing the mean rate of a first rest of 1 s or more made
        the gaitmap strides 2.2 -> 5.9 cm MAE and the x-io loop 0.10 -> 0.17%, the OpenShoe loop 0.46 -> 0.30%; the
        first "rest" apparently holds slow foot motion, 10 times the mean rate that the sensor noise would leave).
    gravity_from_rest : subtract the gravity the accelerometer itself reads at rest (the norm of the mean specific
        force over that first rest, else the median over the stances) instead of the standard 9.80665 m/s^2, which
        removes the vertical part of an accelerometer bias / scale error (no measurable effect on the benchmark
        recordings, whose accelerometers read 9.81-9.90 m/s^2 at rest).
    min_length_std_m : floor of the stride-length standard deviation.
    zero_velocity : parameters of the :class:`ZeroVelocityDetection` used for the stance phases.

    Attributes
    ----------
    trajectory_ : DataFrame ``t_s, x_m, y_m, z_m, vx_mps, vy_mps, vz_mps`` per sample from the first stance on, in a
        local level frame (z up; x/y keep the yaw of the sensor at the first stance, since a foot IMU alone cannot
        observe the absolute heading).
    strides_ : strides table (CONTRACT.md) plus ``dx_m, dy_m, dz_m`` (displacement between consecutive mid-stances
        of this foot), ``heading_rad`` (direction of the displacement, in the local frame) and
        ``heading_change_rad`` (since the previous stride of this foot; NaN for the first),
        ``t_swing_start_s, t_swing_end_s`` (the swing between the two stances); ``length_m`` is the
        horizontal distance; ``length_std_m`` (along the stride) and ``heading_change_std_rad`` (the yaw error accrued
        over the stride) from the filter covariance; ``lateral_std_m`` (across the stride) equals ``length_std_m``.
    position_cov_m2_ : (K, 3, 3) position covariance at each mid-stance.
    final_position_m_ : position (3,) at the middle of the last stance.
    gyr_bias_radps_ : the gyroscope bias removed (zeros when none was estimated).
    gravity_mps2_ : the gravity magnitude subtracted.
    n_updates_ : number of zero-velocity updates applied.
    stance_ : the :class:`ZeroVelocityDetection` used.

    Notes
    -----
    Foot-mounted INS with ZUPT (Foxlin 2005, "Pedestrian tracking with shoe-mounted inertial sensors"; the error-state
    form of Solà 2017, "Quaternion kinematics for the error-state Kalman filter", sec. 5-7, with a global (left)
    attitude error). Nominal state: attitude ``R = M R_gyr(t)`` where ``R_gyr`` is the gyro-integrated attitude
    relative to the first sample and ``M`` is corrected at every update; velocity and position by integrating
    ``R f - g``. Error state ``[dp, dv, dtheta]``: ``dv' = -[R f x] dtheta + w_a``, ``dtheta' = w_g``. Between two
    updates ``M`` is constant, so the nominal state and the transition matrix over the interval follow in closed form
    from cumulative integrals of ``R_gyr f`` (a handful of numpy operations per update instead of a loop over samples);
    the process noise uses the interval's mean specific force. Updates: ``v = 0`` during stance, with the variance of
    a foot that rolls about its contact point (rigid-body velocity ``w x r``, ``|r|`` = ``sensor_above_sole_m``): each
    stance's own angular rate weighs its updates, so the landing and the heel rise count little and no fixed margin
    is cut from the ends of the stance. Per stride (mid-stance to mid-stance of the same foot) the displacement
    variance along the stride is ``u' (P_end - P_start) u`` (position errors accumulate as independent increments),
    and the heading-change variance is the increment of the yaw-error variance. Across the stride the increment of
    the absolute covariance is not the stride's own error: the yaw uncertainty swings the whole path walked so far
    (the lateral variance grows with the distance from the start), so the stride's error across is taken as the one
    along it and its direction error as the heading change's.

    Examples
    --------
    >>> ins = ZuptInsStride(foot="right").estimate(imu_right)                   # doctest: +SKIP
    >>> ins.strides_[["t_start_s", "length_m", "length_std_m"]]                  # doctest: +SKIP
    """

    def __init__(self, *, foot: str = "left", acc_noise_mps2_rthz: float = 0.03, gyr_noise_radps_rthz: float = 0.03,
                 zupt_std_mps: float = 0.003, sensor_above_sole_m: float = 0.05, zupt_rate_hz: float = 20.0,
                 initial_tilt_std_rad: float = 0.02, gyr_bias_min_rest_s: float = 0.0, gravity_from_rest: bool = True,
                 min_length_std_m: float = 0.015,
                 zero_velocity: dict | None = None) -> None:
        self.foot = foot
        self.acc_noise_mps2_rthz = acc_noise_mps2_rthz
        self.gyr_noise_radps_rthz = gyr_noise_radps_rthz
        self.zupt_std_mps = zupt_std_mps
        self.zupt_rate_hz = zupt_rate_hz
        self.sensor_above_sole_m = sensor_above_sole_m
        self.initial_tilt_std_rad = initial_tilt_std_rad
        self.gyr_bias_min_rest_s = gyr_bias_min_rest_s
        self.gravity_from_rest = gravity_from_rest
        self.min_length_std_m = min_length_std_m
        self.zero_velocity = zero_velocity

    def estimate(self, imu: pd.DataFrame, stance: ZeroVelocityDetection | None = None) -> ZuptInsStride:
        """Navigate one foot IMU (canonical IMU table); ``stance`` reuses a detection already made."""
        t, acc, gyr = foot_imu_arrays(imu, f"{self.foot} foot IMU")
        self.stance_ = stance if stance is not None else ZeroVelocityDetection(**(self.zero_velocity or {})).detect(imu)
        st = self.stance_.stances_
        self.trajectory_ = pd.DataFrame({c: pd.Series(dtype=float) for c in INS_TRAJECTORY_COLUMNS})
        self.strides_ = empty_strides(INS_STRIDE_COLUMNS)
        self.position_cov_m2_ = np.zeros((0, 3, 3))
        self.final_position_m_ = np.full(3, np.nan)
        self.gyr_bias_radps_ = np.zeros(3)
        self.gravity_mps2_ = GRAVITY_MPS2
        self.n_updates_ = 0
        if len(st) < 1:
            warn(f"{self.foot} foot IMU: no stance phase, the foot INS cannot start")
            return self
        i0, i1 = int(st["i_start"].iloc[0]), int(st["i_end"].iloc[0])
        if self.gyr_bias_min_rest_s > 0 and t[i1 - 1] - t[i0] >= self.gyr_bias_min_rest_s:
            trim = (i1 - i0) // 5  # the core of the rest: its ends may hold the heel rise and the landing
            self.gyr_bias_radps_ = gyr[i0 + trim:i1 - trim].mean(axis=0)
            self.gravity_mps2_ = float(np.linalg.norm(acc[i0 + trim:i1 - trim].mean(axis=0)))
        elif self.gravity_from_rest:
            means = [np.linalg.norm(acc[a:b].mean(axis=0)) for a, b in zip(st["i_start"], st["i_end"])]
            self.gravity_mps2_ = float(np.median(means))
        if not self.gravity_from_rest:
            self.gravity_mps2_ = GRAVITY_MPS2
        up = np.array([0.0, 0.0, self.gravity_mps2_])
        gyr = gyr - self.gyr_bias_radps_
        t, acc, gyr = t[i0:], acc[i0:], gyr[i0:]
        R_gyr = cumulative_rotations(gyr, np.diff(t))
        f_nav0 = np.einsum("nij,nj->ni", R_gyr, acc)  # specific force in the frame of the first sample
        G = _cumtrapz(f_nav0, t)
        H = _cumtrapz(G, t)
        epochs, mids = self._epochs(st, i0, t)
        n_ep = len(epochs)
        level = align_to_gravity(acc[: max(2, i1 - i0)].mean(axis=0))
        M = level.copy()  # R(t) = M @ R_gyr(t); R_gyr(0) = I
        p, v = np.zeros(3), np.zeros(3)
        P = np.diag([1e-8] * 3 + [self.zupt_std_mps**2] * 3 + [self.initial_tilt_std_rad**2] * 2 + [1e-10])
        gyr_ms = uniform_filter1d((gyr**2).sum(axis=1), max(3, self.stance_.window_samples_), mode="nearest")
        zupt_var = self.zupt_std_mps**2 + self.sensor_above_sole_m**2 * gyr_ms[epochs]  # the rolling foot's velocity
        eye3 = np.eye(3)
        na2, ng2 = self.acc_noise_mps2_rthz**2, self.gyr_noise_radps_rthz**2
        ep_p, ep_v = np.zeros((n_ep, 3)), np.zeros((n_ep, 3))
        ep_M, ep_P = np.zeros((n_ep, 3, 3)), np.zeros((n_ep, 9, 9))
        ep_p[0], ep_v[0], ep_M[0], ep_P[0] = p, v, M, P
        # everything that does not depend on the corrections, for all update intervals at once
        jj, kk = epochs[:-1], epochs[1:]
        Ts = t[kk] - t[jj]
        dG = G[kk] - G[jj]
        dH = H[kk] - H[jj] - G[jj] * Ts[:, None]
        Q = np.zeros((n_ep - 1, 9, 9))
        for i in range(3):
            Q[:, i, i] = na2 * Ts**3 / 3.0
            Q[:, i, 3 + i] = Q[:, 3 + i, i] = na2 * Ts**2 / 2.0
            Q[:, 3 + i, 3 + i] = na2 * Ts
            Q[:, 6 + i, 6 + i] = ng2 * Ts
        phi = np.eye(9)
        for m in range(1, n_ep):
            T = Ts[m - 1]
            C = M @ dG[m - 1]
            D = M @ dH[m - 1]
            p = p + v * T + D - 0.5 * up * T * T
            v = v + C - up * T
            Cx = _skew(C)
            phi[0, 3] = phi[1, 4] = phi[2, 5] = T
            phi[0:3, 6:9] = -_skew(D)
            phi[3:6, 6:9] = -Cx
            q = Q[m - 1]
            q[3:6, 3:6] += ng2 * T / 3.0 * (Cx @ Cx.T)
            q[3:6, 6:9] = -ng2 * T / 2.0 * Cx
            q[6:9, 3:6] = q[3:6, 6:9].T
            P = phi @ P @ phi.T + q
            # zero-velocity update: z = 0 - v, H = [0 I 0]
            K = P[:, 3:6] @ _inverse3(P[3:6, 3:6] + zupt_var[m] * eye3)
            dx = K @ (-v)
            p = p + dx[0:3]
            v = v + dx[3:6]
            M = _small_rotation(dx[6:9]) @ M
            P = P - K @ P[3:6, :]
            P = 0.5 * (P + P.T)
            ep_p[m], ep_v[m], ep_M[m], ep_P[m] = p, v, M, P
        self.n_updates_ = n_ep - 1
        self.trajectory_ = self._trajectory(t, G, H, epochs, ep_p, ep_v, ep_M, up)
        mid_ep = np.searchsorted(epochs, mids)
        pos, cov = ep_p[mid_ep], ep_P[mid_ep][:, 0:3, 0:3]
        self.position_cov_m2_ = cov
        self.final_position_m_ = pos[-1]
        self.strides_ = self._strides(t[mids], pos, cov, ep_P[mid_ep][:, 8, 8], st["t_end_s"].to_numpy(),
                                      st["t_start_s"].to_numpy())
        return self

    def _epochs(self, st: pd.DataFrame, i0: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Update epochs (indices after ``i0``, sorted, unique) and the epoch index of each mid-stance."""
        rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0
        step = max(1, int(round(rate / self.zupt_rate_hz)))
        parts, mids = [np.array([0])], []
        for s, e, mid in zip(st["i_start"] - i0, st["i_end"] - i0, st["i_mid"] - i0):
            parts.append(np.arange(s, e, step))
            parts.append(np.array([e - 1, mid]))
            mids.append(mid)
        epochs = np.unique(np.concatenate(parts))
        return epochs.astype(int), np.asarray(mids, dtype=int)

    def _trajectory(self, t, G, H, epochs, ep_p, ep_v, ep_M, up) -> pd.DataFrame:
        """Position and velocity at every sample from the corrected state of the last update before it."""
        seg = np.searchsorted(epochs, np.arange(len(t)), side="right") - 1
        j = epochs[seg]
        tau = (t - t[j])[:, None]
        Mseg = ep_M[seg]
        dv = np.einsum("nij,nj->ni", Mseg, G - G[j]) - up * tau
        dp = np.einsum("nij,nj->ni", Mseg, H - H[j] - G[j] * tau) - 0.5 * up * tau**2
        v = ep_v[seg] + dv
        p = ep_p[seg] + ep_v[seg] * tau + dp
        return pd.DataFrame({"t_s": t, "x_m": p[:, 0], "y_m": p[:, 1], "z_m": p[:, 2],
                             "vx_mps": v[:, 0], "vy_mps": v[:, 1], "vz_mps": v[:, 2]})

    def _strides(self, t_mid: np.ndarray, pos: np.ndarray, cov: np.ndarray, yaw_var: np.ndarray,
                 stance_end: np.ndarray, stance_start: np.ndarray) -> pd.DataFrame:
        if len(t_mid) < 2:
            return empty_strides(INS_STRIDE_COLUMNS)
        d = np.diff(pos, axis=0)
        length = np.hypot(d[:, 0], d[:, 1])
        u = d[:, :2] / np.maximum(length, 1e-9)[:, None]
        dcov = cov[1:, :2, :2] - cov[:-1, :2, :2]
        var = np.einsum("ni,nij,nj->n", u, dcov, u)
        std = np.sqrt(np.maximum(var, 0.0) + self.min_length_std_m**2)
        heading = np.arctan2(d[:, 1], d[:, 0])
        return pd.DataFrame({
            "t_start_s": t_mid[:-1], "t_end_s": t_mid[1:], "foot": self.foot, "length_m": length,
            "length_std_m": std, "lateral_std_m": std,
            "source": "foot_imu", "dx_m": d[:, 0], "dy_m": d[:, 1], "dz_m": d[:, 2],
            "heading_rad": heading, "heading_change_rad": np.r_[np.nan, np.diff(np.unwrap(heading))],
            "heading_change_std_rad": np.sqrt(np.maximum(np.diff(yaw_var), 0.0)),
            "t_swing_start_s": stance_end[:-1], "t_swing_end_s": stance_start[1:],
        })[INS_STRIDE_COLUMNS]
