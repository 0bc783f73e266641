"""Incremental (causal) factor-graph fusion with iSAM2: steps are processed as they come."""

from __future__ import annotations

import inspect
import time

import gtsam
import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.fusion import factors
from pdr.fusion._inputs import empty_trajectory
from pdr.fusion._linear import deviation_design
from pdr.fusion._initial import along_track
from pdr.fusion._solve import with_deep_stack
from pdr.fusion.graph import FactorGraphFusion, trajectory_frame

_BATCH = inspect.signature(FactorGraphFusion.__init__).parameters  # the shared parameters take the batch defaults


class IncrementalFusion(FactorGraphFusion):
    """The graph of :class:`~pdr.fusion.FactorGraphFusion`, grown one step at a time and solved by iSAM2.

    For GPS-denied navigation runs: every step adds its pose, its step factor, its magnetometer heading and the GNSS
    fixes up to its time, and the newest pose is read out at once. ``trajectory_`` is therefore the *filtered*
    (causal) trajectory: row ``i`` uses only data up to epoch ``i``. ``smoothed_trajectory_`` is the final iSAM2
    estimate of all poses (what a batch solve of the same graph would give).

    Parameters
    ----------
    relinearize_threshold, relinearize_skip, wildfire_threshold
        iSAM2 relinearisation and back-substitution settings (gtsam ``ISAM2Params``, ``ISAM2GaussNewtonParams``);
        the partial relinearisation check is on.
    gyro_bias_radps, mag_deviation_coef
        A calibration from an earlier batch run (``FactorGraphFusion.gyro_bias_radps_[-1]``,
        ``mag_deviation_coef_``): removed from the heading changes / magnetometer headings. Default: none.
    stride_scales
        Length scale per stride source (``{"leg_camera": 1.08}``, e.g. the ``scale`` of an earlier batch run's
        ``stride_scales_``): each stride's length is multiplied by its source's scale. Default: 1 for every source.
    stride_scale_prior_std, stride_scale_prior_std_by_source
        The stds reported with the given scales in ``stride_scales_`` (as :class:`~pdr.fusion.FactorGraphFusion`).
    default_step_length_std_m, default_heading_change_std_rad, lateral_std_m, default_h_acc_m, gnss_time_tolerance_s
        As :class:`~pdr.fusion.FactorGraphFusion` (same defaults).
    huber_k, gnss_gate_chi2, max_rejected_run, max_step_duration_s, gap_speed_std_mps
        As :class:`~pdr.fusion.FactorGraphFusion` (same defaults). The step model, heading-rate bias, magnetometer
        deviation and stride scales are *not* re-estimated here (a navigation run uses a calibration, e.g. from
        ``pdr calibrate`` or an earlier batch run): step lengths are the table's ``step_length_m``, and the batch
        fusion's calibration parameters do not apply.

    Attributes
    ----------
    trajectory_, step_model_ (the given model), step_length_m_, gnss_used_ (causal gate), solver_
        As :class:`~pdr.fusion.FactorGraphFusion`; ``solver_["time_per_step_ms"]`` is the mean update time.
    gyro_bias_radps_, mag_deviation_coef_, mag_deviation_rad_
        The given calibration (``gyro_bias_radps`` at every step, ``mag_deviation_coef`` and the deviation it gives).
    stride_scales_ : dict
        As :class:`~pdr.fusion.FactorGraphFusion`, with the given scales (``calibrated`` False, ``std`` the prior's).
    smoothed_trajectory_ : DataFrame
        The final estimate of every pose (``e_std_m``, ``n_std_m`` from the iSAM2 marginals).

    Notes
    -----
    Kaess et al. (2012), "iSAM2: Incremental smoothing and mapping using the Bayes tree". Each GNSS fix is gated
    (chi-square on its innovation against the predicted position and its marginal covariance; after
    ``max_rejected_run`` rejections in a row the next fix is taken) before it is added,
    behind the same Huber kernel, tied to the nearest epoch with the fix moved along the current step.

    Examples
    --------
    >>> IncrementalFusion().fuse(steps, gnss=fixes).solver_["time_per_step_ms"]  # doctest: +SKIP
    """

    def __init__(self, *, relinearize_threshold: float = 0.1, relinearize_skip: int = 10, wildfire_threshold: float = 0.01,
                 gyro_bias_radps: float = 0.0, mag_deviation_coef: list[float] | None = None,
                 stride_scales: dict[str, float] | None = None,
                 default_step_length_std_m: float = _BATCH["default_step_length_std_m"].default,
                 default_heading_change_std_rad: float = _BATCH["default_heading_change_std_rad"].default,
                 lateral_std_m: float = _BATCH["lateral_std_m"].default,
                 default_h_acc_m: float = _BATCH["default_h_acc_m"].default,
                 gnss_time_tolerance_s: float = _BATCH["gnss_time_tolerance_s"].default,
                 huber_k: float = _BATCH["huber_k"].default, gnss_gate_chi2: float = _BATCH["gnss_gate_chi2"].default,
                 max_rejected_run: int = _BATCH["max_rejected_run"].default,
                 stride_scale_prior_std: float = _BATCH["stride_scale_prior_std"].default,
                 stride_scale_prior_std_by_source: dict[str, float] | None = _BATCH["stride_scale_prior_std_by_source"].default,
                 max_step_duration_s: float = _BATCH["max_step_duration_s"].default,
                 gap_speed_std_mps: float = _BATCH["gap_speed_std_mps"].default):
        self.relinearize_threshold = relinearize_threshold
        self.relinearize_skip = relinearize_skip
        self.wildfire_threshold = wildfire_threshold
        self.gyro_bias_radps = gyro_bias_radps
        self.mag_deviation_coef = mag_deviation_coef
        self.stride_scales = stride_scales
        self.default_step_length_std_m = default_step_length_std_m
        self.default_heading_change_std_rad = default_heading_change_std_rad
        self.lateral_std_m = lateral_std_m
        self.default_h_acc_m = default_h_acc_m
        self.gnss_time_tolerance_s = gnss_time_tolerance_s
        self.huber_k = huber_k
        self.gnss_gate_chi2 = gnss_gate_chi2
        self.max_rejected_run = max_rejected_run
        self.stride_scale_prior_std = stride_scale_prior_std
        self.stride_scale_prior_std_by_source = stride_scale_prior_std_by_source
        self.max_step_duration_s = max_step_duration_s
        self.gap_speed_std_mps = gap_speed_std_mps

    def fuse(self, steps: pd.DataFrame, *, gnss: pd.DataFrame | None = None, strides: pd.DataFrame | None = None,
             step_model=None, t_start_s: float | None = None) -> IncrementalFusion:
        """Process the steps in time order (strides are added when their end step arrives)."""
        return with_deep_stack(self._fuse, steps, gnss, strides, step_model, t_start_s)

    def _fuse(self, steps, gnss, strides, step_model, t_start_s) -> IncrementalFusion:
        t_begin = time.perf_counter()
        self._check_params()
        if not (isinstance(self.relinearize_skip, int) and self.relinearize_skip >= 1 and self.relinearize_threshold > 0):
            raise InputError(f"IncrementalFusion: expected relinearize_skip >= 1 and relinearize_threshold > 0, found "
                             f"{self.relinearize_skip!r}, {self.relinearize_threshold!r}")
        problem = self._prepare(steps, gnss, strides, t_start_s)
        if problem is None:
            self._empty(gnss, step_model)
            self.smoothed_trajectory_ = empty_trajectory()
            self.solver_.update(method="isam2", time_per_step_ms=0.0)
            return self
        n = problem.n_steps
        n_fix = len(problem.gnss_row)
        n_dev = deviation_design(np.zeros(1)).shape[1]
        deviation = np.zeros(n_dev) if self.mag_deviation_coef is None else np.asarray(self.mag_deviation_coef, float)
        if deviation.shape != (n_dev,) or not np.isfinite(deviation).all() or not np.isfinite(self.gyro_bias_radps):
            raise InputError(f"IncrementalFusion: expected mag_deviation_coef of {n_dev} finite numbers and a finite "
                             f"gyro_bias_radps, found {self.mag_deviation_coef!r}, {self.gyro_bias_radps!r}")
        given = self.stride_scales or {}
        if not (isinstance(given, dict) and all(isinstance(k, str) and isinstance(v, (int, float)) and np.isfinite(v)
                                                and v > 0 for k, v in given.items())):
            raise InputError(f"IncrementalFusion stride_scales: expected a table of source name -> number > 0, "
                             f"found {self.stride_scales!r}")
        sources, src, scale_prior_std = self._stride_sources(problem)
        source_scale = np.array([float(given.get(name, 1.0)) for name in sources])
        stride_length = problem.stride_length_m * source_scale[src]
        dtheta = problem.dtheta_rad - self.gyro_bias_radps * problem.step_duration_s
        dtheta[0] = 0.0
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(self.relinearize_threshold)
        params.relinearizeSkip = self.relinearize_skip
        params.enablePartialRelinearizationCheck = True
        params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(self.wildfire_threshold))
        isam = gtsam.ISAM2(params)
        start = gtsam.Pose2(0.0, 0.0, problem.heading0_rad)
        if n_fix:
            start = gtsam.Pose2(problem.gnss_en_m[0][0], problem.gnss_en_m[0][1], problem.heading0_rad)
        graph = gtsam.NonlinearFactorGraph()
        graph.add(factors.start_prior(start, anchored=n_fix == 0))
        values = gtsam.Values()
        values.insert(factors.pose_key(0), start)
        try:
            isam.update(graph, values)
        except RuntimeError as exc:
            raise InputError(f"fusion: iSAM2 could not start ({str(exc).splitlines()[0]})") from None
        poses = np.empty((n + 1, 3))
        pos_std = np.empty((n + 1, 2))
        poses[0] = (start.x(), start.y(), start.theta())
        pos_cov = factors.world_position_cov(isam.marginalCovariance(factors.pose_key(0)), start.theta())
        pos_std[0] = np.sqrt(np.diag(pos_cov))
        used = np.zeros(n_fix, bool)
        fix_order = np.argsort(problem.gnss_k + problem.gnss_alpha, kind="stable")
        stride_end = problem.stride_k[:, 1] if len(problem.stride_k) else np.zeros(0, int)
        cursor, rejected_in_row = 0, 0
        current = start
        t_steps = time.perf_counter()
        for i in range(n):
            graph = gtsam.NonlinearFactorGraph()
            values = gtsam.Values()
            step = factors.step_factor(i, problem.step_length_m[i], dtheta[i], problem.step_length_std_m[i],
                                       problem.dtheta_std_rad[i], problem.lateral_std_m[i])
            graph.add(step)
            predicted = current.compose(step.measured())
            values.insert(factors.pose_key(i + 1), predicted)
            if np.isfinite(problem.mag_rad[i]):
                mag = problem.mag_rad[i] - float(deviation_design(np.array([predicted.theta()]))[0] @ deviation)
                graph.add(factors.heading_factor(i + 1, mag, problem.mag_std_rad[i], self.huber_k))
            for j in np.flatnonzero(stride_end == i + 1):
                k0, k1 = problem.stride_k[j]
                graph.add(factors.stride_factor(k0, k1, stride_length[j], problem.stride_std_m[j], self.huber_k))
            ends = np.array([[current.x(), current.y()], [predicted.x(), predicted.y()]])
            while cursor < n_fix and problem.gnss_k[fix_order[cursor]] <= i:
                j = fix_order[cursor]
                cursor += 1
                alpha = problem.gnss_alpha[j] if problem.gnss_k[j] == i else 1.0
                near = 0 if alpha < 0.5 else 1
                at_fix = (1.0 - alpha) * ends[0] + alpha * ends[1]
                innovation = problem.gnss_en_m[j] - at_fix
                cov = pos_cov + np.eye(2) * problem.gnss_std_m[j] ** 2
                if (i > 0 and used.any() and innovation @ np.linalg.solve(cov, innovation) > self.gnss_gate_chi2
                        and rejected_in_row < self.max_rejected_run):
                    rejected_in_row += 1
                    continue
                rejected_in_row = 0
                used[j] = True
                graph.add(factors.gnss_shifted_factor(i + near, problem.gnss_en_m[j], ends[near] - at_fix,
                                                      factors.gnss_noise(problem.gnss_std_m[j], self.huber_k)))
            try:
                isam.update(graph, values)
            except RuntimeError as exc:
                raise InputError(f"fusion: iSAM2 update failed at step {i} ({str(exc).splitlines()[0]})") from None
            current = isam.calculateEstimatePose2(factors.pose_key(i + 1))
            poses[i + 1] = (current.x(), current.y(), current.theta())
            pos_cov = factors.world_position_cov(isam.marginalCovariance(factors.pose_key(i + 1)), current.theta())
            pos_std[i + 1] = np.sqrt(np.maximum(np.diag(pos_cov), 0.0))
        t_loop = time.perf_counter() - t_steps
        estimate = isam.calculateEstimate()
        final = gtsam.utilities.extractPose2(estimate)
        final_std = np.array([np.sqrt(np.maximum(np.diag(factors.world_position_cov(
            isam.marginalCovariance(factors.pose_key(k)), final[k, 2])), 0.0)) for k in range(n + 1)])
        self.trajectory_ = trajectory_frame(problem, poses, pos_std)
        self.smoothed_trajectory_ = trajectory_frame(problem, final, final_std)
        self.step_length_m_ = along_track(poses)
        self.step_model_ = step_model
        self.gnss_used_ = np.zeros(problem.gnss_n_rows, bool)
        self.gnss_used_[problem.gnss_row] = used
        self.gyro_bias_radps_ = np.full(n, float(self.gyro_bias_radps))
        self.mag_deviation_coef_ = deviation
        self.mag_deviation_rad_ = deviation_design(poses[1:, 2]) @ deviation
        self.stride_scales_ = {str(name): {"scale": float(source_scale[q]), "std": float(scale_prior_std[q]),
                                           "prior_std": float(scale_prior_std[q]), "n_strides": int(np.sum(src == q)),
                                           "calibrated": False} for q, name in enumerate(sources)}
        self.solver_ = {
            "method": "isam2", "iterations": n, "alternations": 0,
            "final_error": float(isam.getFactorsUnsafe().error(estimate)), "time_s": time.perf_counter() - t_begin,
            "time_per_step_ms": 1e3 * t_loop / max(n, 1), "gnss_used": int(used.sum()),
            "gnss_rejected": int((~used).sum()), "causal": True}
        return self
