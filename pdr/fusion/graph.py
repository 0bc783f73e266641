"""Batch factor-graph fusion (Levenberg-Marquardt smoothing) of steps, strides, heading and intermittent GNSS."""

from __future__ import annotations

import threading
import time
import gtsam
import numpy as np
import pandas as pd
import scipy.sparse
import scipy.sparse.linalg

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.fusion import factors
from pdr.fusion._inputs import BOUT_START_HEADING_STD_RAD, Problem, empty_trajectory, prepare
from pdr.fusion._linear import (
    SmoothSeries,
    StepModelParams,
    deviation_design,
    solve_deviation,
    solve_series,
    solve_step_model,
    solve_stride_scales,
    step_model_params,
    zero_series,
)
from pdr.schema import wrap_rad
from pdr.step_length import RegressionStepLength

GNSS_FACTORS = ("shifted", "interpolated")
CHI2_2DOF_999 = 13.816  # 99.9% quantile of chi-square with 2 degrees of freedom
# Scale priors of sources whose length bias is measured: the shoe-IMU INS is within 0.3% on the gaitmap motion-capture
# strides and the simulated walks at normal and fast pace (benchmarks foot), so GNSS noise must not move it by 2-3%.
DEFAULT_STRIDE_SCALE_PRIOR_STD_BY_SOURCE = {"foot_imu": 0.02}
ANDERSON_DEPTH = 5  # past iterates used by the Anderson acceleration of the alternation


def dead_reckoning_poses(problem: Problem, length_m: np.ndarray, dtheta_rad: np.ndarray,
                         start: tuple[float, float, float]) -> np.ndarray:
    """(N + 1, 3) poses ``e, n, heading`` of the step chain from ``start``: each step along the new heading."""
    heading = start[2] + np.concatenate([[0.0], np.cumsum(dtheta_rad)])
    e = start[0] + np.concatenate([[0.0], np.cumsum(length_m * np.cos(heading[1:]))])
    n = start[1] + np.concatenate([[0.0], np.cumsum(length_m * np.sin(heading[1:]))])
    return np.column_stack([e, n, heading])


def interpolate_positions(poses: np.ndarray, k: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    if len(poses) == 1:
        return np.repeat(poses[:1, :2], len(k), axis=0)
    return (1.0 - alpha)[:, None] * poses[k, :2] + alpha[:, None] * poses[k + 1, :2]


def align_to_fixes(poses: np.ndarray, problem: Problem) -> np.ndarray:
    """Rigidly move a dead-reckoned chain onto the GNSS fixes (2-D Procrustes, twice, dropping the worst third of
    the fixes the second time so that outliers do not set the start); only the initial estimate depends on this."""
    pos = interpolate_positions(poses, problem.gnss_k, problem.gnss_alpha)
    z = problem.gnss_en_m
    keep = np.ones(len(z), bool)
    rot, shift = np.eye(2), np.zeros(2)
    for _ in range(2):
        p, q = pos[keep], z[keep]
        pc, qc = p.mean(axis=0), q.mean(axis=0)
        if len(p) >= 2 and np.ptp(p, axis=0).max() > 5.0 and np.ptp(q, axis=0).max() > 5.0:
            u, _, vt = np.linalg.svd((p - pc).T @ (q - qc))
            d = np.sign(np.linalg.det(vt.T @ u.T))
            rot = vt.T @ np.diag([1.0, d]) @ u.T
        shift = qc - rot @ pc
        resid = np.linalg.norm(pos @ rot.T + shift - z, axis=1)
        if len(z) >= 6:
            keep = resid <= np.quantile(resid, 0.67)
    out = poses.copy()
    out[:, :2] = poses[:, :2] @ rot.T + shift
    out[:, 2] = poses[:, 2] + np.arctan2(rot[1, 0], rot[0, 0])
    return out


DEEP_STACK_BYTES = 1 << 30  # gtsam recurses along the elimination tree: a 100,000-pose chain overflows 8 MB


def with_deep_stack(fn, *args):
    """Run ``fn(*args)`` in a thread with a large stack (virtual memory only) and return its result or raise its error.

    gtsam's recursive elimination / marginalisation over a long chain (a walk of tens of thousands of steps) overflows
    the default 8 MB stack and crashes the interpreter."""
    out: dict = {}

    def target() -> None:
        try:
            out["value"] = fn(*args)
        except BaseException as exc:  # re-raised in the caller's thread
            out["error"] = exc

    previous = threading.stack_size(DEEP_STACK_BYTES)
    try:
        thread = threading.Thread(target=target, name="pdr-gtsam")
        thread.start()
    finally:
        threading.stack_size(previous)
    thread.join()
    if "error" in out:
        raise out["error"]
    return out["value"]


def chain_position_std(graph: gtsam.NonlinearFactorGraph, poses: np.ndarray) -> np.ndarray:
    """(N + 1, 2) east/north std of the poses from the start prior and the step factors alone (first-order
    propagation in the tangent space, ``P_k+1 = Ad(T^-1) P_k Ad(T^-1)^T + Q_k`` with ``T`` the measured step; Barfoot,
    *State Estimation for Robotics*, 2017, sec. 7.3): the exact marginals of the step chain, so upper bounds of those
    of a graph with further factors. A position is never farther from the start than the distance walked, so no std
    exceeds that distance (a linearised heading std of several radians says no more than that)."""
    prior, steps = None, {}
    for i in range(graph.size()):
        factor = graph.at(i)
        if isinstance(factor, gtsam.PriorFactorPose2) and factor.keys()[0] == factors.pose_key(0):
            prior = factor.noiseModel().covariance()
        elif isinstance(factor, gtsam.BetweenFactorPose2):
            steps[factor.keys()[0]] = factor
    cov = np.array(prior, float)
    out = np.empty((len(poses), 2))
    walked = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))])
    for k, pose in enumerate(poses):
        if k > 0:
            step = steps[factors.pose_key(k - 1)]
            adjoint = step.measured().inverse().AdjointMap()
            cov = adjoint @ cov @ adjoint.T + step.noiseModel().covariance()
        std = np.sqrt(np.maximum(np.diag(factors.world_position_cov(cov, pose[2])), 0.0))
        out[k] = np.minimum(std, max(walked[k], float(np.sqrt(prior[0, 0]))))
    return out


def gate(d2: np.ndarray, threshold: float, max_run: int) -> np.ndarray:
    """Chi-square gate of the fixes (in time order), except that a run of more than ``max_run`` consecutive rejected
    fixes is kept: outliers come alone, a long consistent run means the path, not the fixes, is wrong."""
    use = d2 <= threshold
    rejected = np.concatenate([[0], (~use).astype(np.int8), [0]])
    starts = np.flatnonzero(np.diff(rejected) == 1)
    ends = np.flatnonzero(np.diff(rejected) == -1)
    for a, b in zip(starts, ends):
        if b - a > max_run:
            use[a:b] = True
    return use


def course_correction(poses: np.ndarray, problem: Problem, window_s: float = 30.0) -> tuple[np.ndarray, float] | None:
    """Heading correction of a dead-reckoned chain from the GNSS course: over windows of ``window_s`` the angle between
    the fixes' displacement and the chain's, median-filtered over 5 windows (robust to outliers) and unwrapped.
    Returns the correction at every epoch and its slope (rad/s, minus the mean heading-rate bias), or None when
    fewer than 3 windows qualify. Only the initial estimate depends on this."""
    t, z = problem.gnss_t_s, problem.gnss_en_m
    p = interpolate_positions(poses, problem.gnss_k, problem.gnss_alpha)
    if len(t) < 2:
        return None
    j = np.arange(len(t))
    j2 = np.searchsorted(t, t + window_s)
    ok = (j2 < len(t)) & (j % 5 == 0)
    j, j2 = j[ok], j2[ok]
    dz, dp = z[j2] - z[j], p[j2] - p[j]
    ok = (np.linalg.norm(dz, axis=1) > 10.0) & (np.linalg.norm(dp, axis=1) > 10.0) & (t[j2] - t[j] < 3.0 * window_s)
    if ok.sum() < 3:
        return None
    angle = wrap_rad(np.arctan2(dz[ok, 1], dz[ok, 0]) - np.arctan2(dp[ok, 1], dp[ok, 0]))
    angle = np.unwrap(angle)
    angle = pd.Series(angle).rolling(5, center=True, min_periods=1).median().to_numpy()
    t_mid = 0.5 * (t[j[ok]] + t[j2[ok]])
    slope = float(np.polyfit(t_mid, angle, 1)[0])
    return np.interp(problem.epoch_t_s, t_mid, angle), slope


def trajectory_frame(problem: Problem, poses: np.ndarray, pos_std: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame({"t_s": problem.epoch_t_s, "e_m": poses[:, 0], "n_m": poses[:, 1],
                         "heading_rad": wrap_rad(poses[:, 2]), "e_std_m": pos_std[:, 0], "n_std_m": pos_std[:, 1]})


class FactorGraphFusion(Algorithm):
    """Batch (smoothing) fusion of a walk in a GTSAM factor graph, solved by Levenberg-Marquardt.

    One ``Pose2`` (east, north, heading) per step epoch: the start pose, then the pose at each step's contact.

    Parameters
    ----------
    default_step_length_std_m, default_heading_change_std_rad
        Per-step noise where the steps table gives none (m, rad).
    lateral_std_m
        Noise across each step (m): sway of the body, and what keeps the step covariance full rank.
    default_h_acc_m
        1-sigma GNSS accuracy of fixes without ``h_acc_m`` (m).
    gnss_time_tolerance_s
        Fixes up to this far before the start / after the last step are tied to the first / last pose; others unused.
    gnss_factor
        ``"shifted"`` (default; built-in ``PoseTranslationPrior2D`` on the nearest epoch, the fix moved by the
        current estimate of the path between that epoch and the fix time) or ``"interpolated"`` (a Python
        ``CustomFactor`` on the two poses around the fix, linear interpolation). Both interpolate, none snaps.
    huber_k
        Huber threshold (whitened units) of every robust factor (GNSS, magnetometer heading, strides).
    gnss_gate_chi2
        A fix whose squared whitened residual exceeds this after a solve is rejected (2-dof chi-square 99.9%).
    calibrate_step_model
        Estimate the regression parameters ``(A, B, C)`` from the data while reconstructing (needs the feature
        columns ``step_freq_hz``, ``acc_var_m2ps4`` and at least two used fixes or stride factors).
    prior_a_std_m, prior_b_std_m_per_hz, prior_c_std_m_per_m2ps4
        Prior standard deviations of ``(A, B, C)`` where the step model carries no ``covariance``.
    calibrate_step_scale, step_scale_prior_std
        When the regression is not calibrated (``calibrate_step_model`` False, or another step model), estimate one
        multiplicative scale of the steps' own lengths, prior 1 +- ``step_scale_prior_std``, under the same
        conditions (``pdr run`` with per-form step models: their relative lengths are kept, GNSS sets the user's
        level). Reported as ``step_scale_``.
    calibrate_stride_scales
        Estimate a multiplicative length scale ``s`` per stride source (the records' ``source``: ``leg_camera``,
        ``foot_imu``, ...), prior 1, from GNSS (at least two fixes); without GNSS every scale stays 1.
    stride_scale_prior_std, stride_scale_prior_std_by_source
        Prior standard deviation of the scales (how far a source is trusted a priori, e.g. 0.07 = 7%), and
        per-source overrides (default ``{"foot_imu": 0.02}``, measured; ``{}`` gives every source the common prior).
    gnss_correlated_std_m, gnss_correlation_s
        The slowly varying part of the GNSS error (m per axis) and its correlation time (s). The GNSS factors treat
        fixes as independent, which is fine for positions but claims far too much about a length scale over a short
        walk (a few metres of drift over 40 s is a 10% scale error); the information GNSS gives a stride scale is
        capped at ``D^2 / (2 m sigma^2)`` (``D`` metres walked with fixes and strides of that source, ``m`` the number
        of correlation times in it, at least 1).
    gyro_bias_knot_s, gyro_bias_rw_radps_per_sqrt_s, gyro_bias_prior_std_radps
        Heading-rate bias of the relative heading changes: piecewise linear between knots this far apart, a random
        walk between knots, zero-mean prior.
    mag_deviation_prior_std_rad
        Prior of the coefficients of the magnetometer deviation curve (offset + first and second harmonic of the
        heading: hard and soft iron), calibrated against GNSS and gyro while outdoors and used indoors.
    max_alternations, alternation_tol_m
        Outer iterations of (pose solve, closed-form parameter update) and the stop criterion: the largest change
        of the predicted step lengths and of the heading corrections (times the step length), in metres.
    max_step_duration_s, gap_speed_std_mps
        A step longer than this (missed steps, a stop) is a gap: its displacement is known only to
        ``gap_speed_std_mps`` times its duration, and it is left out of the step-model calibration.
    max_rejected_run
        A run of more than this many consecutive fixes failing the gate is kept (the path is wrong, not the fixes).
    compute_covariance
        Marginal covariance of every pose (``e_std_m``, ``n_std_m``); False leaves them NaN and saves time.

    Attributes
    ----------
    trajectory_ : DataFrame
        ``t_s, e_m, n_m, heading_rad, e_std_m, n_std_m``: the start pose, then one row per step.
    step_model_ : the calibrated regression step model (same class as the one given), or the one given.
    step_length_m_ : ndarray
        Per-step length after fusion (distance between consecutive poses along the step).
    gnss_used_ : ndarray of bool
        One per GNSS row: True if the fix was used and not rejected by the chi-square gate.
    gyro_bias_radps_, mag_deviation_rad_ : ndarray
        The estimated heading-rate bias and magnetometer deviation at each step.
    mag_deviation_coef_ : ndarray
        The deviation curve's coefficients (``[1, cos h, sin h, cos 2h, sin 2h]``), for an :class:`IncrementalFusion`.
    step_scale_ : dict
        ``scale`` (multiplies the steps' lengths; 1 unless ``calibrate_step_scale`` applies), ``std`` (conditional on
        the poses), ``prior_std``, ``calibrated``.
    stride_scales_ : dict
        Per stride source: ``scale`` (multiplies its lengths), ``std`` (marginal over the poses and the step model,
        conditional on the heading parameters; the prior std when not calibrated), ``prior_std``, ``n_strides``,
        ``calibrated``. Empty without strides.
    solver_ : dict
        ``method, iterations`` (LM, summed), ``alternations, final_error, time_s, marginals_time_s, gnss_used,
        gnss_rejected, converged``.

    Notes
    -----
    Factors: ``BetweenFactorPose2`` per step (length ``A + B f + C v`` along the heading turned by the gyro heading
    change minus the bias), ``RangeFactorPose2`` per stride, robust ``PoseRotationPrior2D`` per magnetometer heading
    (minus its deviation), GNSS factors behind a Huber kernel plus a chi-square gate, a prior on the start pose (tight
    at the origin and the first step's heading when nothing absolute is known, the documented default; very weak
    otherwise). Parameters that enter the step measurements linearly (step model after Ladetto et al. 2000,
    ``length = A + B f + C v``; heading-rate bias; magnetometer deviation) are solved in closed form given the poses,
    alternating with the pose solve (block coordinate descent on the joint least-squares objective, the fixed point
    accelerated by Anderson mixing, Walker & Ni 2011), so every per-step factor stays built-in (a shared (A, B, C)
    variable in 10,000 Python factors is not tractable, see DESIGN.md); each re-solve starts from the previous
    solution. Stride scales (one per source, ``range = s L``, with GNSS only): given the poses they would barely move
    (the strides themselves set the path length), so each alternation takes a Gauss-Newton step of the scales and
    the step model jointly with the poses (the poses eliminated from the linearised graph, a Schur complement), with
    the information GNSS gives a scale capped for correlated GNSS errors; :meth:`_joint_step`.
    The first estimate is dead reckoning turned onto the GNSS course (a gyro bias can wind the raw chain
    by whole turns, a local minimum for LM). GNSS factor: the built-in shifted prior gives the same path as the
    exact interpolating ``CustomFactor`` (2 mm apart on the benchmark walk) about 9 times faster, hence the default.
    Ordering METIS, and LM / marginals run on a thread with a large stack (a 100,000-pose chain overflows the default
    stack in gtsam's recursive elimination). Covariances: ``gtsam.Marginals`` of the final graph, rotated from the
    pose frame to east-north; they are conditional on the calibrated parameters and treat GNSS errors as white.

    Examples
    --------
    >>> fusion = FactorGraphFusion().fuse(steps, gnss=fixes, step_model=model)  # doctest: +SKIP
    >>> fusion.trajectory_[["e_m", "n_m"]].iloc[-1]  # doctest: +SKIP
    """

    def __init__(self, *, default_step_length_std_m: float = 0.05, default_heading_change_std_rad: float = 0.01,
                 lateral_std_m: float = 0.02, default_h_acc_m: float = 5.0, gnss_time_tolerance_s: float = 1.0,
                 gnss_factor: str = "shifted", huber_k: float = 1.345, gnss_gate_chi2: float = CHI2_2DOF_999,
                 calibrate_step_model: bool = True, prior_a_std_m: float = 0.2, prior_b_std_m_per_hz: float = 0.1,
                 prior_c_std_m_per_m2ps4: float = 0.02, calibrate_step_scale: bool = False,
                 step_scale_prior_std: float = 0.1, calibrate_stride_scales: bool = True,
                 stride_scale_prior_std: float = 0.07, stride_scale_prior_std_by_source: dict[str, float] | None = None,
                 gnss_correlated_std_m: float = 3.0, gnss_correlation_s: float = 120.0,
                 gyro_bias_knot_s: float = 60.0,
                 gyro_bias_rw_radps_per_sqrt_s: float = 1e-5, gyro_bias_prior_std_radps: float = 0.01,
                 mag_deviation_prior_std_rad: float = 0.3, max_alternations: int = 12, alternation_tol_m: float = 0.002,
                 max_step_duration_s: float = 2.0, gap_speed_std_mps: float = 1.0, max_rejected_run: int = 10,
                 compute_covariance: bool = True):
        self.default_step_length_std_m = default_step_length_std_m
        self.default_heading_change_std_rad = default_heading_change_std_rad
        self.lateral_std_m = lateral_std_m
        self.default_h_acc_m = default_h_acc_m
        self.gnss_time_tolerance_s = gnss_time_tolerance_s
        self.gnss_factor = gnss_factor
        self.huber_k = huber_k
        self.gnss_gate_chi2 = gnss_gate_chi2
        self.calibrate_step_model = calibrate_step_model
        self.prior_a_std_m = prior_a_std_m
        self.prior_b_std_m_per_hz = prior_b_std_m_per_hz
        self.prior_c_std_m_per_m2ps4 = prior_c_std_m_per_m2ps4
        self.calibrate_step_scale = calibrate_step_scale
        self.step_scale_prior_std = step_scale_prior_std
        self.calibrate_stride_scales = calibrate_stride_scales
        self.stride_scale_prior_std = stride_scale_prior_std
        self.stride_scale_prior_std_by_source = stride_scale_prior_std_by_source
        self.gnss_correlated_std_m = gnss_correlated_std_m
        self.gnss_correlation_s = gnss_correlation_s
        self.gyro_bias_knot_s = gyro_bias_knot_s
        self.gyro_bias_rw_radps_per_sqrt_s = gyro_bias_rw_radps_per_sqrt_s
        self.gyro_bias_prior_std_radps = gyro_bias_prior_std_radps
        self.mag_deviation_prior_std_rad = mag_deviation_prior_std_rad
        self.max_alternations = max_alternations
        self.alternation_tol_m = alternation_tol_m
        self.max_step_duration_s = max_step_duration_s
        self.gap_speed_std_mps = gap_speed_std_mps
        self.max_rejected_run = max_rejected_run
        self.compute_covariance = compute_covariance

    # ------------------------------------------------------------------------------------------------------------
    def _check_params(self) -> None:
        """Check the parameters this class has (an :class:`IncrementalFusion` has a subset)."""
        own = set(self.param_names())
        if "gnss_factor" in own and self.gnss_factor not in GNSS_FACTORS:
            raise InputError(f"gnss_factor: expected one of {', '.join(GNSS_FACTORS)}, found {self.gnss_factor!r}")
        positive = ["default_step_length_std_m", "default_heading_change_std_rad", "lateral_std_m", "default_h_acc_m",
                    "huber_k", "gnss_gate_chi2", "gyro_bias_knot_s", "gyro_bias_rw_radps_per_sqrt_s",
                    "gyro_bias_prior_std_radps", "mag_deviation_prior_std_rad", "alternation_tol_m", "prior_a_std_m",
                    "prior_b_std_m_per_hz",
                    "prior_c_std_m_per_m2ps4", "max_step_duration_s", "gap_speed_std_mps", "stride_scale_prior_std",
                    "step_scale_prior_std",
                    "gnss_correlated_std_m", "gnss_correlation_s"]
        for name in [n for n in positive if n in own]:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise InputError(f"{type(self).__name__} {name}: expected a number > 0, found {value!r}")
        for name in [n for n in ("max_alternations", "max_rejected_run") if n in own]:
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 1):
                raise InputError(f"{type(self).__name__} {name}: expected an integer >= 1, found {value!r}")
        by_source = self.stride_scale_prior_std_by_source
        if by_source is not None and not (isinstance(by_source, dict) and all(
                isinstance(k, str) and isinstance(v, (int, float)) and np.isfinite(v) and v > 0
                for k, v in by_source.items())):
            raise InputError(f"{type(self).__name__} stride_scale_prior_std_by_source: expected a table of source name "
                             f"-> number > 0, found {by_source!r}")

    def _stride_sources(self, problem: Problem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The stride sources (sorted names), each stride's index into them, and each source's scale prior std."""
        sources, index = np.unique(problem.stride_source.astype(str), return_inverse=True)
        by_source = self.stride_scale_prior_std_by_source
        if by_source is None:
            by_source = DEFAULT_STRIDE_SCALE_PRIOR_STD_BY_SOURCE
        prior = np.array([float(by_source.get(name, self.stride_scale_prior_std)) for name in sources])
        return sources, index.reshape(-1).astype(int), prior

    def _prepare(self, steps, gnss, strides, t_start_s) -> Problem | None:
        return prepare(steps, gnss, strides, t_start_s=t_start_s,
                       default_step_length_std_m=self.default_step_length_std_m,
                       default_heading_change_std_rad=self.default_heading_change_std_rad,
                       default_h_acc_m=self.default_h_acc_m, gnss_time_tolerance_s=self.gnss_time_tolerance_s,
                       lateral_std_m=self.lateral_std_m, max_step_duration_s=self.max_step_duration_s,
                       gap_speed_std_mps=self.gap_speed_std_mps)

    def _empty(self, gnss: pd.DataFrame | None, step_model) -> FactorGraphFusion:
        self.trajectory_ = empty_trajectory()
        self.step_model_ = step_model
        self.step_length_m_ = np.zeros(0)
        self.gnss_used_ = np.zeros(0 if gnss is None else len(gnss), bool)
        self.gyro_bias_radps_ = np.zeros(0)
        self.mag_deviation_rad_ = np.zeros(0)
        self.mag_deviation_coef_ = np.zeros(deviation_design(np.zeros(1)).shape[1])
        self.stride_scales_ = {}
        self.solver_ = {"method": "levenberg_marquardt", "iterations": 0, "alternations": 0, "final_error": 0.0,
                        "time_s": 0.0, "marginals_time_s": 0.0, "gnss_used": 0, "gnss_rejected": 0, "converged": True,
                        "last_change_m": 0.0}
        return self

    # ------------------------------------------------------------------------------------------------------------
    def fuse(self, steps: pd.DataFrame, *, gnss: pd.DataFrame | None = None, strides: pd.DataFrame | None = None,
             step_model=None, t_start_s: float | None = None) -> FactorGraphFusion:
        """Reconstruct the walk. ``t_start_s``: time of the start pose (default: one step duration before the first
        step). ``step_model``: a ``RegressionStepLength`` (prior of the calibration); None: the population preset."""
        t_begin = time.perf_counter()
        self._check_params()
        problem = self._prepare(steps, gnss, strides, t_start_s)
        if problem is None:
            self.step_scale_ = {"scale": 1.0, "std": self.step_scale_prior_std, "prior_std": self.step_scale_prior_std,
                                "calibrated": False}
            return self._empty(gnss, step_model)
        n = problem.n_steps
        n_fix = len(problem.gnss_row)
        absolute = n_fix >= 1
        observable = n_fix >= 2 or len(problem.stride_length_m) > 0
        feats_ok = (np.isfinite(problem.features).all(axis=1) & ~problem.gap if problem.features is not None
                    else np.zeros(n, bool))
        regression = step_model is None or isinstance(step_model, RegressionStepLength)
        calibrate = bool(self.calibrate_step_model and regression and observable and problem.features is not None
                         and feats_ok.sum() >= 3)
        # the steps' own lengths (per-form models, or a one-parameter model such as Zijlstra's) times one scale
        own_scale = step_model is not None and not regression and len(getattr(step_model, "theta_names", ())) == 1
        scale_steps = bool((self.calibrate_step_scale or (self.calibrate_step_model and own_scale))
                           and not calibrate and observable)
        model_prior = None
        if calibrate:
            if step_model is None:
                step_model = RegressionStepLength.population()
            model_prior = step_model_params(step_model, (self.prior_a_std_m, self.prior_b_std_m_per_hz,
                                                         self.prior_c_std_m_per_m2ps4))
        has_mag = np.isfinite(problem.mag_rad)
        estimate_bias = n_fix >= 2 or bool(has_mag.any())
        sources, src, scale_prior_std = self._stride_sources(problem)
        n_src = len(sources)
        estimate_scales = bool(self.calibrate_stride_scales and n_fix >= 2 and n_src > 0)
        scale_std = scale_prior_std.copy()
        bias = zero_series(problem.epoch_t_s, self.gyro_bias_knot_s)
        n_dev = deviation_design(np.zeros(1)).shape[1]
        nb = len(bias.values)
        i_bias, i_dev = slice(3, 3 + nb), slice(3 + nb, 3 + nb + n_dev)
        i_scale = slice(3 + nb + n_dev, 3 + nb + n_dev + n_src)
        i_step_scale = 3 + nb + n_dev + n_src
        dt = problem.step_duration_s
        known_turn = problem.dtheta_std_rad < BOUT_START_HEADING_STD_RAD
        known_turn[0] = False
        t_step = problem.epoch_t_s[1:]
        model_cov = None
        theta0 = model_prior.theta if calibrate else np.zeros(3)
        params = np.concatenate([theta0, bias.values, np.zeros(n_dev), np.ones(n_src), np.ones(1)])
        # each parameter in metres of effect on the path (convergence test and acceleration)
        mean_length = float(np.mean(problem.step_length_m)) if n else 1.0
        mean_speed = mean_length / float(np.median(dt)) if n else 1.0
        feat_scale = np.abs(np.nanmean(problem.features[feats_ok], axis=0)) if calibrate else np.ones(3)
        mean_stride = np.bincount(src, problem.stride_length_m, n_src) / np.maximum(np.bincount(src, minlength=n_src), 1)
        scale = np.concatenate([feat_scale, np.full(nb, 0.5 * self.gyro_bias_knot_s ** 2 * mean_speed),
                                np.full(n_dev, 10.0 * mean_length), mean_stride, [mean_length]])
        scale_prior_std_own = self.step_scale_prior_std
        if own_scale and step_model.covariance_matrix is not None:  # the model's own prior on its one parameter
            scale_prior_std_own = float(np.sqrt(step_model.covariance_matrix[0, 0]) / abs(step_model.theta[0]))
        step_scale_std = scale_prior_std_own
        step_scale_prior = StepModelParams(np.ones(1), np.array([[scale_prior_std_own ** 2]]), 0.0)
        nonnegative = tuple(RegressionStepLength.theta_names.index(n) for n in RegressionStepLength.nonnegative)

        def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            b = SmoothSeries(bias.t0_s, bias.knot_s, p[i_bias])
            length = (np.where(feats_ok, np.nan_to_num(problem.features) @ p[:3], problem.step_length_m)
                      if calibrate else problem.step_length_m * p[i_step_scale])
            return length, problem.dtheta_rad - b(t_step) * dt, p[i_dev], problem.stride_length_m * p[i_scale][src]

        def update(poses: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
            """The closed-form parameter solve given the poses (each block kept where it is not observable)."""
            nonlocal step_scale_std
            out, cov = p.copy(), None
            if estimate_bias:
                resid = wrap_rad(np.diff(poses[:, 2]) - problem.dtheta_rad)
                ok = known_turn & (dt > 0)
                if ok.sum() >= 2:
                    out[i_bias] = solve_series(bias, t_step[ok], resid[ok], -dt[ok], problem.dtheta_std_rad[ok],
                                                 self.gyro_bias_rw_radps_per_sqrt_s,
                                                 self.gyro_bias_prior_std_radps).values
            if has_mag.any():
                heading = poses[1:, 2][has_mag]
                y = wrap_rad(problem.mag_rad[has_mag] - heading)
                inlier = (np.abs(wrap_rad(y - deviation_design(heading) @ p[i_dev]))
                          <= 5.0 * problem.mag_std_rad[has_mag])
                if inlier.any():
                    out[i_dev] = solve_deviation(y[inlier], heading[inlier], problem.mag_std_rad[has_mag][inlier],
                                                   self.mag_deviation_prior_std_rad)
            if calibrate:
                along = self._along_track(poses)
                out[:3], cov = solve_step_model(along[feats_ok], problem.features[feats_ok],
                                                problem.step_length_std_m[feats_ok], model_prior, nonnegative)
            if scale_steps:  # along = k x length + e, prior k ~ N(1, step_scale_prior_std^2)
                ok = ~problem.gap
                k, k_cov = solve_step_model(self._along_track(poses)[ok], problem.step_length_m[ok, None],
                                            problem.step_length_std_m[ok], step_scale_prior)
                out[i_step_scale], step_scale_std = float(k[0]), float(np.sqrt(k_cov[0, 0]))
            if estimate_scales:
                joint = self._joint_step(problem, poses, values, p, unpack, use, absolute, calibrate, feats_ok,
                                         model_prior, src, scale_prior_std, i_scale)
                if joint is None:  # the joint system is singular: the closed form, conditional on the poses
                    k0, k1 = problem.stride_k[:, 0], problem.stride_k[:, 1]
                    distance = np.linalg.norm(poses[k1, :2] - poses[k0, :2], axis=1)
                    out[i_scale], scale_std[:] = solve_stride_scales(distance, problem.stride_length_m,
                                                                     problem.stride_std_m, src, scale_prior_std,
                                                                     p[i_scale], self.huber_k)
                else:
                    theta_new, out[i_scale], scale_std[:] = joint
                    if calibrate and all(theta_new[j] >= 0 for j in nonnegative):  # else the bounded closed form
                        out[:3] = theta_new
            return out, cov

        length0, dtheta0, _, _ = unpack(params)
        poses = dead_reckoning_poses(problem, length0, dtheta0, (0.0, 0.0, problem.heading0_rad))
        correction = course_correction(poses, problem) if n_fix >= 2 else None
        if correction is not None:  # start from the GNSS course: a gyro bias can turn the chain by whole turns
            if estimate_bias:
                params[i_bias] = -correction[1]
            length0, dtheta0, _, _ = unpack(params)
            poses = dead_reckoning_poses(problem, length0, dtheta0 - correction[1] * dt + np.diff(correction[0]),
                                         (0.0, 0.0, problem.heading0_rad + correction[0][0]))
        if absolute:
            poses = align_to_fixes(poses, problem)
        use = np.ones(n_fix, bool)
        lm_iterations, final_error, converged, alternation = 0, 0.0, False, 0
        graph = values = None
        history_f: list[np.ndarray] = []
        history_g: list[np.ndarray] = []
        prev_f = prev_g = None
        for alternation in range(1, self.max_alternations + 1):
            graph = self._graph(problem, poses, *unpack(params), use, absolute)
            values, iters, final_error = self._solve(graph, values if values is not None else self._values(poses))
            poses = gtsam.utilities.extractPose2(values)
            lm_iterations += iters
            pos = interpolate_positions(poses, problem.gnss_k, problem.gnss_alpha)
            d2 = np.sum(np.square(pos - problem.gnss_en_m), axis=1) / np.square(problem.gnss_std_m)
            new_use = gate(d2, self.gnss_gate_chi2, self.max_rejected_run)
            mapped, cov = update(poses, params)
            if cov is not None:
                model_cov = cov
            f = (mapped - params) * scale
            same_gate = np.array_equal(new_use, use)
            if np.max(np.abs(f), initial=0.0) <= self.alternation_tol_m and same_gate:
                converged = True
                break
            # Anderson acceleration of the fixed point params = update(solve(params)); restarted when the gate changes
            if not same_gate or prev_f is None or np.linalg.norm(f) > 2.0 * np.linalg.norm(prev_f):
                history_f.clear()
                history_g.clear()
            else:
                history_f.append(f - prev_f)
                history_g.append(mapped - prev_g)
                del history_f[:-ANDERSON_DEPTH], history_g[:-ANDERSON_DEPTH]
            prev_f, prev_g = f, mapped
            if history_f:
                gamma = np.linalg.lstsq(np.column_stack(history_f), f, rcond=None)[0]
                params = mapped - np.column_stack(history_g) @ gamma
            else:
                params = mapped
            use = new_use
        last_change_m = float(np.max(np.abs(f), initial=0.0))
        if not converged and (calibrate or scale_steps):
            blocks = {"step model": slice(0, 3), "gyro bias": i_bias, "magnetometer deviation": i_dev,
                      "stride scales": i_scale, "step scale": slice(i_step_scale, i_step_scale + 1)}
            worst = max(blocks, key=lambda b: np.max(np.abs(f[blocks[b]]), initial=0.0))
            what = "the GNSS gate still changing" if not same_gate else f"largest in the {worst}"
            warn(f"graph fusion: the calibration did not converge in {alternation} alternations (last change "
                 f"{last_change_m:.3g} m > {self.alternation_tol_m:g} m, {what}); the step model given is kept")
        theta = params[:3]
        bias = SmoothSeries(bias.t0_s, bias.knot_s, params[i_bias])
        t_marg = time.perf_counter()
        pos_std = np.full((n + 1, 2), np.nan)
        if self.compute_covariance:
            pos_std = self._marginal_std(graph, values, poses)
        t_end = time.perf_counter()

        self.trajectory_ = trajectory_frame(problem, poses, pos_std)
        self.step_length_m_ = self._along_track(poses)
        self.gnss_used_ = np.zeros(problem.gnss_n_rows, bool)
        self.gnss_used_[problem.gnss_row] = use
        self.gyro_bias_radps_ = bias(problem.epoch_t_s[1:])
        self.mag_deviation_coef_ = params[i_dev].copy()
        self.step_scale_ = {"scale": float(params[i_step_scale]), "std": step_scale_std,
                            "prior_std": scale_prior_std_own, "calibrated": scale_steps}
        self.stride_scales_ = {
            str(name): {"scale": float(params[i_scale][q]) if estimate_scales else 1.0,
                        "std": float(scale_std[q]), "prior_std": float(scale_prior_std[q]),
                        "n_strides": int(np.sum(src == q)), "calibrated": estimate_scales}
            for q, name in enumerate(sources)}
        self.mag_deviation_rad_ = deviation_design(poses[1:, 2]) @ self.mag_deviation_coef_
        if not converged:  # the last good model: the one given
            self.step_model_ = step_model
        elif scale_steps and own_scale:
            k = float(params[i_step_scale])
            self.step_model_ = step_model.with_theta(step_model.theta * k, np.array([[(step_scale_std * k * step_model.theta[0]) ** 2]]))
        elif calibrate:
            self.step_model_ = type(step_model)(a_m=float(theta[0]), b_m_per_hz=float(theta[1]),
                                                c_m_per_m2ps4=float(theta[2]),
                                                residual_std_m=model_prior.residual_std_m,
                                                covariance=(model_prior.covariance if model_cov is None else model_cov).tolist())
        else:
            self.step_model_ = step_model
        self.solver_ = {"method": "levenberg_marquardt", "iterations": lm_iterations, "alternations": alternation,
                        "final_error": final_error, "time_s": t_end - t_begin, "marginals_time_s": t_end - t_marg,
                        "gnss_used": int(use.sum()), "gnss_rejected": int((~use).sum()), "converged": converged,
                        "last_change_m": last_change_m,
                        "gnss_factor": self.gnss_factor, "step_model_calibrated": calibrate,
                        "stride_scales_calibrated": estimate_scales}
        return self

    # ------------------------------------------------------------------------------------------------------------
    @staticmethod
    def _along_track(poses: np.ndarray) -> np.ndarray:
        d = np.diff(poses[:, :2], axis=0)
        return d[:, 0] * np.cos(poses[1:, 2]) + d[:, 1] * np.sin(poses[1:, 2])

    def _graph(self, problem: Problem, poses: np.ndarray, length: np.ndarray, dtheta: np.ndarray,
               deviation: np.ndarray, stride_length: np.ndarray, use: np.ndarray,
               absolute: bool) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        if absolute:
            graph.add(factors.start_prior(gtsam.Pose2(*poses[0]), anchored=False))
        else:
            graph.add(factors.start_prior(gtsam.Pose2(0.0, 0.0, problem.heading0_rad), anchored=True))
        for i in range(problem.n_steps):
            graph.add(factors.step_factor(i, length[i], dtheta[i], problem.step_length_std_m[i],
                                          problem.dtheta_std_rad[i], problem.lateral_std_m[i]))
        mag_idx = np.flatnonzero(np.isfinite(problem.mag_rad))
        mag = problem.mag_rad[mag_idx] - deviation_design(poses[mag_idx + 1, 2]) @ deviation
        for i, m in zip(mag_idx, mag):
            graph.add(factors.heading_factor(i + 1, m, problem.mag_std_rad[i], self.huber_k))
        for (k0, k1), length_m, std in zip(problem.stride_k, stride_length, problem.stride_std_m):
            graph.add(factors.stride_factor(k0, k1, length_m, std, self.huber_k))
        idx = np.flatnonzero(use)
        k, alpha = problem.gnss_k[idx], problem.gnss_alpha[idx]
        if self.gnss_factor == "interpolated" and problem.n_steps > 0:
            for j, kk, a in zip(idx, k, alpha):
                graph.add(factors.gnss_interpolated_factor(kk, a, problem.gnss_en_m[j],
                                                           factors.gnss_noise(float(problem.gnss_std_m[j]), self.huber_k)))
        else:
            nearest = np.where(alpha < 0.5, k, np.minimum(k + 1, problem.n_steps))
            shift = poses[nearest, :2] - interpolate_positions(poses, k, alpha)
            for j, m, s in zip(idx, nearest, shift):
                graph.add(factors.gnss_shifted_factor(m, problem.gnss_en_m[j], s,
                                                      factors.gnss_noise(float(problem.gnss_std_m[j]), self.huber_k)))
        return graph

    @staticmethod
    def _values(poses: np.ndarray) -> gtsam.Values:
        values = gtsam.Values()
        for i, p in enumerate(poses):
            values.insert(factors.pose_key(i), gtsam.Pose2(*p))
        return values

    @staticmethod
    def _solve(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values) -> tuple[gtsam.Values, int, float]:
        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(1e-5)
        params.setMaxIterations(100)
        params.setOrderingType("METIS")
        # a pose chain with unary fixes has little fill-in: the sequential factorisation needs less memory than the
        # multifrontal one (100,000 steps: 670 MB instead of 810 MB peak) and is faster, with the same solution
        params.setLinearSolverType("SEQUENTIAL_CHOLESKY")
        try:
            optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
            result = with_deep_stack(optimizer.optimize)
        except RuntimeError as exc:  # gtsam's "Indeterminant linear system" and friends never reach the user
            raise InputError(f"fusion: the factor graph could not be solved (expected every pose to be constrained "
                             f"by steps and an anchor; gtsam says: {str(exc).splitlines()[0]})") from None
        return result, optimizer.iterations(), optimizer.error()

    def _gnss_scale_info(self, problem: Problem, poses: np.ndarray, use: np.ndarray, src: np.ndarray) -> np.ndarray:
        """Per stride source, the most information (1 / scale variance) GNSS with correlated errors can give its scale:
        ``D^2 / (2 m sigma^2)`` over the stretch covered by both used fixes and that source's strides."""
        n_src = int(src.max()) + 1 if len(src) else 0
        out = np.zeros(n_src)
        k_fix = problem.gnss_k[use]
        if len(k_fix) < 2:
            return out
        walked = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))])
        for q in range(n_src):
            k = problem.stride_k[src == q]
            lo, hi = max(int(k_fix.min()), int(k[:, 0].min())), min(int(k_fix.max()) + 1, int(k[:, 1].max()))
            if hi <= lo:
                continue
            distance = walked[hi] - walked[lo]
            m = max(1.0, (problem.epoch_t_s[hi] - problem.epoch_t_s[lo]) / self.gnss_correlation_s)
            out[q] = distance ** 2 / (2.0 * m * self.gnss_correlated_std_m ** 2)
        return out

    def _joint_step(self, problem: Problem, poses: np.ndarray, values: gtsam.Values, p: np.ndarray, unpack,
                    use: np.ndarray, absolute: bool, calibrate: bool, feats_ok: np.ndarray, model_prior,
                    src: np.ndarray, scale_prior_std: np.ndarray, i_scale: slice):
        """Gauss-Newton step of the stride scales (and the step model, when calibrated) jointly with the poses.

        Given the poses alone the scales barely move (the strides, not GNSS, set the path length: block coordinate
        descent would crawl), so the poses are eliminated instead: the graph linearised at ``values`` (gtsam's
        whitened, robust-weighted rows ``A dx = b``) gets one column per parameter (derivatives of the whitened errors
        by finite differences of ``b``), and the Schur complement of the poses gives the parameters' reduced
        system ``S dq = r``. With the priors that is the MAP step and the parameters' marginal covariance. Each
        scale's information from GNSS is capped at :meth:`_gnss_scale_info` (the cap taken as a tighter prior with the
        same posterior mean). Returns ``(theta, scales, scale_std)`` or None when the system is singular.
        """
        n_src = len(scale_prior_std)
        length, dtheta, deviation, stride_length = unpack(p)
        n_pose = 3 * values.size()  # all keys are Pose2, in key order: pose k -> columns 3k..3k+2

        def jacobian(step_len: np.ndarray, stride_len: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            graph = self._graph(problem, poses, step_len, dtheta, deviation, stride_len, use, absolute)
            m = np.asarray(graph.linearize(values).sparseJacobian_())
            return m[0].astype(int) - 1, m[1].astype(int) - 1, m[2]

        rows, cols, vals = jacobian(length, stride_length)
        n_rows = int(rows.max()) + 1
        is_b = cols == n_pose

        def b_of(r: np.ndarray, c: np.ndarray, v: np.ndarray) -> np.ndarray:
            return np.bincount(r[c == n_pose], v[c == n_pose], n_rows)[:n_rows]

        b0 = b_of(rows, cols, vals)
        # rows in the order of _graph: start prior (3), steps (3 each), magnetometer headings (1 each), strides (1 each)
        n_steps, n_mag = problem.n_steps, int(np.isfinite(problem.mag_rad).sum())
        step_rows = 3 + np.arange(3 * n_steps)
        stride_rows = 3 + 3 * n_steps + n_mag + np.arange(len(stride_length))
        if n_rows != 3 + 3 * n_steps + n_mag + len(stride_length) + 2 * int(use.sum()):
            return None  # not the row layout assumed here
        columns = []
        h = 1e-3
        if calibrate:  # d(whitened error)/d(step length), then the chain rule through length = features . theta
            d_len = -(b_of(*jacobian(length + h * feats_ok, stride_length)) - b0) / h
            design = np.where(feats_ok[:, None], np.nan_to_num(problem.features), 0.0)
            for k in range(3):
                col = np.zeros(n_rows)
                col[step_rows] = d_len[step_rows] * np.repeat(design[:, k], 3)
                columns.append(col)
        d_scale = -(b_of(*jacobian(length, stride_length + h * problem.stride_length_m)) - b0) / h
        for q in range(n_src):
            col = np.zeros(n_rows)
            col[stride_rows[src == q]] = d_scale[stride_rows[src == q]]
            columns.append(col)
        a_pp = scipy.sparse.csc_matrix((vals[~is_b], (rows[~is_b], cols[~is_b])), shape=(n_rows, n_pose))
        j_q = np.column_stack(columns)
        h_pq = np.asarray(a_pp.T @ j_q)
        try:
            lu = scipy.sparse.linalg.splu(scipy.sparse.csc_matrix(a_pp.T @ a_pp))
            x = lu.solve(np.column_stack([h_pq, a_pp.T @ b0]))
        except RuntimeError:
            return None
        if not np.isfinite(x).all():
            return None
        s_red = j_q.T @ j_q - h_pq.T @ x[:, :-1]
        r_red = j_q.T @ b0 - h_pq.T @ x[:, -1]
        n_th = 3 if calibrate else 0
        q_now = np.concatenate([p[:3] if calibrate else np.zeros(0), p[i_scale]])
        q_prior = np.concatenate([model_prior.theta if calibrate else np.zeros(0), np.ones(n_src)])
        prior = np.zeros((n_th + n_src, n_th + n_src))
        if calibrate:
            prior[:3, :3] = np.linalg.inv(model_prior.covariance)
        info_prior = 1.0 / np.square(scale_prior_std)
        info_cap = self._gnss_scale_info(problem, poses, use, src)
        try:
            prior[n_th:, n_th:] = np.diag(info_prior)
            cov = np.linalg.inv(s_red + prior)
            info_white = np.maximum(1.0 / np.diag(cov)[n_th:] - info_prior, 0.0)
            capped = info_white > info_cap
            # the capped posterior mean = the white-noise one with a prior of info_prior * info_white / info_cap
            prior[n_th:, n_th:] = np.diag(np.where(capped, info_prior * info_white / np.maximum(info_cap, 1e-12),
                                                   info_prior))
            step = np.linalg.solve(s_red + prior, r_red - prior @ (q_now - q_prior))
        except np.linalg.LinAlgError:
            return None
        q_new = q_now + step
        std = 1.0 / np.sqrt(np.minimum(info_white, info_cap) + info_prior)
        return (q_new[:3] if calibrate else None), q_new[n_th:], std

    @staticmethod
    def _marginal_std(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, poses: np.ndarray) -> np.ndarray:
        try:
            marginals = with_deep_stack(gtsam.Marginals, graph, values)
        except RuntimeError as exc:
            reason = " ".join(str(exc).strip().split("\n\n")[0].split()) or type(exc).__name__
            warn(f"fusion: gtsam marginal covariances unavailable ({reason}); e_std_m/n_std_m propagated "
                 "along the step chain from the start pose's prior instead (magnetometer, stride and GNSS "
                 "factors ignored: upper bounds)")
            return chain_position_std(graph, poses)
        out = np.empty((len(poses), 2))
        for i, p in enumerate(poses):
            cov = factors.world_position_cov(marginals.marginalCovariance(factors.pose_key(i)), p[2])
            out[i] = np.sqrt(np.maximum(np.diag(cov), 0.0))
        return out
