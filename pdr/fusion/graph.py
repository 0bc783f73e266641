"""Batch factor-graph fusion (Levenberg-Marquardt smoothing) of steps, strides, heading and intermittent GNSS."""

from __future__ import annotations

import time

import gtsam
import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError, warn
from pdr.fusion._calibration import AndersonMixing, Calibration, Update
from pdr.fusion._initial import align_to_fixes, along_track, course_correction, dead_reckoning_poses
from pdr.fusion._inputs import Problem, empty_trajectory, prepare
from pdr.fusion._linear import deviation_design
from pdr.fusion._solve import build_graph, fix_d2, gate, initial_values, marginal_std, solve
from pdr.schema import wrap_rad

GNSS_FACTORS = ("shifted", "interpolated")
CHI2_2DOF_999 = 13.816  # 99.9% quantile of chi-square with 2 degrees of freedom
# Scale priors of sources whose length bias is measured: the shoe-IMU INS is within 0.3% on the gaitmap motion-capture
# strides and the simulated walks at normal and fast pace (benchmarks foot), so GNSS noise must not move it by 2-3%.
DEFAULT_STRIDE_SCALE_PRIOR_STD_BY_SOURCE = {"foot_imu": 0.02}
ANDERSON_DEPTH = 5  # past iterates used by the Anderson acceleration of the alternation


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
    the information GNSS gives a scale capped for correlated GNSS errors; ``pdr.fusion._calibration``.
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
        prior = np.array([self.source_scale_prior_std(name) for name in sources])
        return sources, index.reshape(-1).astype(int), prior

    def source_scale_prior_std(self, source: str) -> float:
        """The prior std of a stride source's length scale (``stride_scale_prior_std_by_source``, else the common one)."""
        by_source = self.stride_scale_prior_std_by_source
        if by_source is None:
            by_source = DEFAULT_STRIDE_SCALE_PRIOR_STD_BY_SOURCE
        return float(by_source.get(source, self.stride_scale_prior_std))

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
        cal = Calibration(self, problem, step_model)
        params, poses = self._initial_estimate(problem, cal)
        use = np.ones(len(problem.gnss_row), bool)
        mixing = AndersonMixing(ANDERSON_DEPTH)
        lm_iterations, converged, values = 0, False, None
        for alternation in range(1, self.max_alternations + 1):
            graph, _ = build_graph(problem, poses, cal.measurements(params), use, cal.absolute,
                                   gnss_factor=self.gnss_factor, huber_k=self.huber_k)
            values, iterations, final_error = solve(graph, initial_values(poses) if values is None else values)
            poses = gtsam.utilities.extractPose2(values)
            lm_iterations += iterations
            new_use = gate(fix_d2(problem, poses), self.gnss_gate_chi2, self.max_rejected_run)
            update = cal.update(poses, params, values, use)
            change_m = (update.params - params) * cal.scale_m
            same_gate = np.array_equal(new_use, use)
            if np.max(np.abs(change_m), initial=0.0) <= self.alternation_tol_m and same_gate:
                converged = True
                break
            params = mixing.next(change_m, update.params, restart=not same_gate)  # restarted when the gate changes
            use = new_use
        last_change_m = float(np.max(np.abs(change_m), initial=0.0))
        if not converged:
            blocks = cal.layout.labelled()
            worst = max(blocks, key=lambda b: np.max(np.abs(change_m[blocks[b]]), initial=0.0))
            what = "the GNSS gate still changing" if not same_gate else f"largest in the {worst}"
            kept = "; the step model given is kept" if cal.calibrate or cal.scale_steps else ""
            warn(f"graph fusion: the calibration did not converge in {alternation} alternations (last change "
                 f"{last_change_m:.3g} m > {self.alternation_tol_m:g} m, {what}){kept}")
        t_marg = time.perf_counter()
        pos_std = np.full((problem.n_steps + 1, 2), np.nan)
        if self.compute_covariance:
            pos_std = marginal_std(graph, values, poses)
        t_end = time.perf_counter()
        lay = cal.layout
        self.trajectory_ = trajectory_frame(problem, poses, pos_std)
        self.step_length_m_ = along_track(poses)
        self.gnss_used_ = np.zeros(problem.gnss_n_rows, bool)
        self.gnss_used_[problem.gnss_row] = use
        self.gyro_bias_radps_ = cal.bias(params)(problem.epoch_t_s[1:])
        self.mag_deviation_coef_ = params[lay.deviation].copy()
        self.mag_deviation_rad_ = deviation_design(poses[1:, 2]) @ self.mag_deviation_coef_
        self.step_scale_ = {"scale": float(params[lay.step_scale]), "std": update.step_scale_std,
                            "prior_std": cal.step_scale_prior_std, "calibrated": cal.scale_steps}
        self.stride_scales_ = {
            str(name): {"scale": float(params[lay.stride_scales][q]) if cal.estimate_scales else 1.0,
                        "std": float(update.stride_scale_std[q]), "prior_std": float(cal.scale_prior_std[q]),
                        "n_strides": int(np.sum(cal.src == q)), "calibrated": cal.estimate_scales}
            for q, name in enumerate(cal.sources)}
        # not converged: the last good model, the one given
        self.step_model_ = self._fitted_step_model(cal, params, update) if converged else cal.step_model
        self.solver_ = {"method": "levenberg_marquardt", "iterations": lm_iterations, "alternations": alternation,
                        "final_error": final_error, "time_s": t_end - t_begin, "marginals_time_s": t_end - t_marg,
                        "gnss_used": int(use.sum()), "gnss_rejected": int((~use).sum()), "converged": converged,
                        "last_change_m": last_change_m,
                        "gnss_factor": self.gnss_factor, "step_model_calibrated": cal.calibrate,
                        "stride_scales_calibrated": cal.estimate_scales}
        return self

    @staticmethod
    def _initial_estimate(problem: Problem, cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
        """The parameters and poses the alternation starts from: dead reckoning turned onto the GNSS course (a gyro
        bias can turn the raw chain by whole turns, a local minimum for LM) and moved onto the fixes."""
        params = cal.params0.copy()
        meas = cal.measurements(params)
        poses = dead_reckoning_poses(problem, meas.step_length_m, meas.dtheta_rad, (0.0, 0.0, problem.heading0_rad))
        correction = course_correction(poses, problem) if len(problem.gnss_row) >= 2 else None
        if correction is not None:
            turn, rate = correction
            if cal.estimate_bias:
                params[cal.layout.bias] = -rate
            meas = cal.measurements(params)
            poses = dead_reckoning_poses(problem, meas.step_length_m, meas.dtheta_rad - rate * cal.dt + np.diff(turn),
                                         (0.0, 0.0, problem.heading0_rad + turn[0]))
        if cal.absolute:
            poses = align_to_fixes(poses, problem)
        return params, poses

    @staticmethod
    def _fitted_step_model(cal: Calibration, params: np.ndarray, update: Update):
        """The step model of the converged parameters: the given one scaled, the calibrated regression, or the one
        given when neither is estimated."""
        step_model, lay = cal.step_model, cal.layout
        if cal.scale_steps and cal.own_scale:
            k = float(params[lay.step_scale])
            return step_model.with_theta(step_model.theta * k,
                                         np.array([[(update.step_scale_std * k * step_model.theta[0]) ** 2]]))
        if cal.calibrate:
            theta = params[lay.theta]
            cov = cal.model_prior.covariance if update.model_cov is None else update.model_cov
            return type(step_model)(a_m=float(theta[0]), b_m_per_hz=float(theta[1]), c_m_per_m2ps4=float(theta[2]),
                                    residual_std_m=cal.model_prior.residual_std_m, covariance=cov.tolist())
        return step_model
