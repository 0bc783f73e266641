"""Forward extended Kalman filter PDR: the causal baseline the factor graph is compared with."""

from __future__ import annotations

import time

import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError
from pdr.fusion._inputs import empty_trajectory, prepare
from pdr.fusion.graph import CHI2_2DOF_999, trajectory_frame
from pdr.schema import wrap_rad
from pdr.step_length import RegressionStepLength

CHI2_1DOF_999 = 10.83  # 99.9% quantile of chi-square with 1 degree of freedom
FORCED_AFTER_REJECTIONS = 10  # consecutive rejected fixes after which the filter re-anchors on the next fix
UNKNOWN_POSITION_STD_M = 1e4


class EkfFusion(Algorithm):
    """Forward EKF of the walk: state ``(e, n, heading, step scale, heading-rate bias)``, one prediction per step.

    Parameters
    ----------
    default_step_length_std_m, default_heading_change_std_rad, lateral_std_m, default_h_acc_m, gnss_time_tolerance_s,
    max_step_duration_s, gap_speed_std_mps
        As :class:`~pdr.fusion.FactorGraphFusion`.
    gnss_gate_chi2, mag_gate_chi2
        Innovation gates (2-dof and 1-dof chi-square, 99.9%).
    initial_heading_std_rad
        Heading uncertainty of the start when GNSS is present (without GNSS the start defines the frame).
    scale_prior_std, scale_rw_per_sqrt_step
        Step-length scale factor (1 = the table's lengths): prior and random walk; estimated only with GNSS.
    gyro_bias_prior_std_radps, gyro_bias_rw_radps_per_sqrt_s
        Heading-rate bias: prior and random walk; estimated only with GNSS or magnetometer heading.

    Attributes
    ----------
    trajectory_, step_model_, step_length_m_, gnss_used_, solver_
        As :class:`~pdr.fusion.FactorGraphFusion`; the trajectory is the filtered (causal) one. ``step_model_`` is
        the given regression model times the estimated scale (exact for a model linear in its parameters).

    Notes
    -----
    Prediction per step: ``heading += dtheta - b dt``, ``position += s L (cos, sin)(heading)``, first-order covariance
    propagation. GNSS update of the position interpolated back from the step end to the fix time, with innovation
    gating; after ``FORCED_AFTER_REJECTIONS`` rejected fixes in a row the position is re-anchored (a diverged filter
    would otherwise reject everything). Magnetometer heading updates, gated. The classic loosely coupled PDR/GNSS
    filter (e.g. Ladetto et al. 2000 for the idea of a Kalman step calibration from GNSS).

    Examples
    --------
    >>> EkfFusion().fuse(steps, gnss=fixes).trajectory_  # doctest: +SKIP
    """

    def __init__(self, *, default_step_length_std_m: float = 0.05, default_heading_change_std_rad: float = 0.01,
                 lateral_std_m: float = 0.02, default_h_acc_m: float = 5.0, gnss_time_tolerance_s: float = 1.0,
                 gnss_gate_chi2: float = CHI2_2DOF_999, mag_gate_chi2: float = CHI2_1DOF_999,
                 initial_heading_std_rad: float = 0.5, scale_prior_std: float = 0.1, scale_rw_per_sqrt_step: float = 1e-3,
                 gyro_bias_prior_std_radps: float = 0.01, gyro_bias_rw_radps_per_sqrt_s: float = 1e-5,
                 max_step_duration_s: float = 2.0, gap_speed_std_mps: float = 1.0):
        self.default_step_length_std_m = default_step_length_std_m
        self.default_heading_change_std_rad = default_heading_change_std_rad
        self.lateral_std_m = lateral_std_m
        self.default_h_acc_m = default_h_acc_m
        self.gnss_time_tolerance_s = gnss_time_tolerance_s
        self.gnss_gate_chi2 = gnss_gate_chi2
        self.mag_gate_chi2 = mag_gate_chi2
        self.initial_heading_std_rad = initial_heading_std_rad
        self.scale_prior_std = scale_prior_std
        self.scale_rw_per_sqrt_step = scale_rw_per_sqrt_step
        self.gyro_bias_prior_std_radps = gyro_bias_prior_std_radps
        self.gyro_bias_rw_radps_per_sqrt_s = gyro_bias_rw_radps_per_sqrt_s
        self.max_step_duration_s = max_step_duration_s
        self.gap_speed_std_mps = gap_speed_std_mps

    def fuse(self, steps: pd.DataFrame, *, gnss: pd.DataFrame | None = None, strides: pd.DataFrame | None = None,
             step_model=None, t_start_s: float | None = None) -> EkfFusion:
        """Filter the walk forward in time (strides are not used by this baseline)."""
        t_begin = time.perf_counter()
        for name, value in self.get_params().items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise InputError(f"EkfFusion {name}: expected a number > 0, found {value!r}")
        problem = prepare(steps, gnss, None, t_start_s=t_start_s, default_step_length_std_m=self.default_step_length_std_m,
                          default_heading_change_std_rad=self.default_heading_change_std_rad,
                          default_h_acc_m=self.default_h_acc_m, gnss_time_tolerance_s=self.gnss_time_tolerance_s,
                          lateral_std_m=self.lateral_std_m, max_step_duration_s=self.max_step_duration_s,
                          gap_speed_std_mps=self.gap_speed_std_mps)
        n_rows = 0 if gnss is None else len(gnss)
        if problem is None:
            self.trajectory_, self.step_model_, self.step_length_m_ = empty_trajectory(), step_model, np.zeros(0)
            self.gnss_used_ = np.zeros(n_rows, bool)
            self.solver_ = {"method": "ekf", "iterations": 0, "final_error": 0.0, "time_s": 0.0, "step_scale": 1.0}
            return self
        n = problem.n_steps
        n_fix = len(problem.gnss_row)
        mag_ok = np.isfinite(problem.mag_rad)
        x = np.array([0.0, 0.0, problem.heading0_rad, 1.0, 0.0])
        p = np.zeros((5, 5))
        if n_fix:
            x[:2] = problem.gnss_en_m[0]
            p[0, 0] = p[1, 1] = UNKNOWN_POSITION_STD_M ** 2
            p[2, 2] = self.initial_heading_std_rad ** 2
        if n_fix >= 2:
            p[3, 3] = self.scale_prior_std ** 2
        if n_fix >= 2 or mag_ok.any():
            p[4, 4] = self.gyro_bias_prior_std_radps ** 2
        dt = problem.step_duration_s
        states = np.empty((n + 1, 5))
        stds = np.empty((n + 1, 2))
        states[0], stds[0] = x, np.sqrt(np.diag(p)[:2])
        used = np.zeros(n_fix, bool)
        fix_order = np.argsort(problem.gnss_k + problem.gnss_alpha, kind="stable")
        cursor, rejected_in_row = 0, 0
        for i in range(n):
            length, l_std, dth_std = problem.step_length_m[i], problem.step_length_std_m[i], problem.dtheta_std_rad[i]
            heading = x[2] + problem.dtheta_rad[i] - x[4] * dt[i]
            c, s = np.cos(heading), np.sin(heading)
            sl = x[3] * length
            f = np.eye(5)
            f[2, 4] = -dt[i]
            f[0, 2], f[0, 3], f[0, 4] = -sl * s, length * c, sl * s * dt[i]
            f[1, 2], f[1, 3], f[1, 4] = sl * c, length * s, -sl * c * dt[i]
            g = np.array([[x[3] * c, -sl * s, -s], [x[3] * s, sl * c, c], [0.0, 1.0, 0.0], [0, 0, 0], [0, 0, 0]])
            q = g @ np.diag([l_std ** 2, dth_std ** 2, problem.lateral_std_m[i] ** 2]) @ g.T
            if p[3, 3] > 0:
                q[3, 3] = self.scale_rw_per_sqrt_step ** 2
            if p[4, 4] > 0:
                q[4, 4] = self.gyro_bias_rw_radps_per_sqrt_s ** 2 * dt[i]
            x = np.array([x[0] + sl * c, x[1] + sl * s, heading, x[3], x[4]])
            p = f @ p @ f.T + q
            if mag_ok[i]:
                h = np.array([0.0, 0.0, 1.0, 0.0, 0.0])
                innovation = wrap_rad(problem.mag_rad[i] - x[2])
                s_mag = p[2, 2] + problem.mag_std_rad[i] ** 2
                if innovation ** 2 / s_mag <= self.mag_gate_chi2:
                    gain = p @ h / s_mag
                    x = x + gain * innovation
                    p = p - np.outer(gain, h @ p)
            while cursor < n_fix and problem.gnss_k[fix_order[cursor]] <= i:
                j = fix_order[cursor]
                cursor += 1
                back = (1.0 - problem.gnss_alpha[j]) if problem.gnss_k[j] == i else 0.0
                pred = x[:2] - back * sl * np.array([c, s])
                h = np.zeros((2, 5))
                h[0, 0] = h[1, 1] = 1.0
                h[0, 2], h[1, 2] = back * sl * s, -back * sl * c
                h[0, 3], h[1, 3] = -back * length * c, -back * length * s
                r = np.eye(2) * problem.gnss_std_m[j] ** 2
                innovation = problem.gnss_en_m[j] - pred
                s_cov = h @ p @ h.T + r
                d2 = float(innovation @ np.linalg.solve(s_cov, innovation))
                if d2 > self.gnss_gate_chi2 and rejected_in_row < FORCED_AFTER_REJECTIONS:
                    rejected_in_row += 1
                    continue
                if d2 > self.gnss_gate_chi2:  # diverged: re-anchor the position on this fix
                    p[:2, :] = 0.0
                    p[:, :2] = 0.0
                    p[0, 0] = p[1, 1] = UNKNOWN_POSITION_STD_M ** 2
                    s_cov = h @ p @ h.T + r
                rejected_in_row = 0
                used[j] = True
                gain = p @ h.T @ np.linalg.inv(s_cov)
                x = x + gain @ innovation
                ikh = np.eye(5) - gain @ h
                p = ikh @ p @ ikh.T + gain @ r @ gain.T  # Joseph form
            states[i + 1], stds[i + 1] = x, np.sqrt(np.maximum(np.diag(p)[:2], 0.0))
        self.trajectory_ = trajectory_frame(problem, states[:, :3], stds)
        self.step_length_m_ = problem.step_length_m * states[1:, 3]
        self.gnss_used_ = np.zeros(n_rows, bool)
        self.gnss_used_[problem.gnss_row] = used
        scale = float(x[3])
        if isinstance(step_model, RegressionStepLength) and n_fix >= 2:
            self.step_model_ = RegressionStepLength(a_m=step_model.a_m * scale, b_m_per_hz=step_model.b_m_per_hz * scale,
                                                    c_m_per_m2ps4=step_model.c_m_per_m2ps4 * scale,
                                                    residual_std_m=step_model.residual_std_m,
                                                    covariance=step_model.covariance)
        else:
            self.step_model_ = step_model
        self.solver_ = {"method": "ekf", "iterations": n, "final_error": 0.0, "time_s": time.perf_counter() - t_begin,
                        "step_scale": scale, "gyro_bias_radps": float(x[4]), "gnss_used": int(used.sum()),
                        "gnss_rejected": int((~used).sum())}
        return self
