"""The calibrated parameters of the batch fusion and their updates after each pose solve.

The parameters enter the measurements of the graph's factors (step model ``length = A + B f + C v`` after Ladetto et
al. 2000, or one scale of the steps' own lengths; heading-rate bias; magnetometer deviation; one scale per stride
source). After each pose solve they take one Gauss-Newton step jointly with the poses
(:meth:`Calibration.joint_step`); the closed forms given the poses are the fallback. The fixed point
``params = update(solve(params))`` is accelerated by Anderson mixing (Walker & Ni 2011).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import gtsam
import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from pdr.fusion._initial import along_track
from pdr.fusion._inputs import BOUT_START_HEADING_STD_RAD, Problem
from pdr.fusion._linear import (
    SmoothSeries,
    StepModelParams,
    deviation_design,
    solve_deviation,
    solve_series,
    series_prior_information,
    series_weights,
    solve_step_model,
    solve_stride_scales,
    step_model_params,
    zero_series,
)
from pdr.fusion._solve import Measurements, build_graph, graph_rows, named_blocks
from pdr.schema import wrap_rad
from pdr.step_length import RegressionStepLength


FD_STEP = 1e-3  # finite-difference step of the measurements (m, rad, or relative for the stride scales)
MAX_JOINT_BIAS_KNOTS = 64  # about an hour at one knot a minute
MAX_BAND = 64  # widest band of the poses' normal matrix solved as a band (columns: 3 a pose)


@dataclasses.dataclass(frozen=True)
class ParamLayout:
    """The blocks of the parameter vector, in order: step model ``(A, B, C)``, gyro-bias knots, magnetometer deviation
    coefficients, one length scale per stride source, one scale of the steps' own lengths (an index)."""

    theta: slice
    bias: slice
    deviation: slice
    stride_scales: slice
    step_scale: int

    @classmethod
    def of(cls, n_bias: int, n_deviation: int, n_sources: int) -> ParamLayout:
        blocks = named_blocks({"theta": 3, "bias": n_bias, "deviation": n_deviation, "stride_scales": n_sources,
                               "step_scale": 1})
        return cls(blocks["theta"], blocks["bias"], blocks["deviation"], blocks["stride_scales"],
                   blocks["step_scale"].start)

    def block(self, name: str) -> slice:
        """The block of a parameter name (``theta``, ``bias``, ``deviation``, ``stride_scales``, ``step_scale``)."""
        if name == "step_scale":
            return slice(self.step_scale, self.step_scale + 1)
        return getattr(self, name)

    def labelled(self) -> dict[str, slice]:
        """The blocks by the names a message gives them."""
        return {"step model": self.theta, "gyro bias": self.bias, "magnetometer deviation": self.deviation,
                "stride scales": self.stride_scales, "step scale": slice(self.step_scale, self.step_scale + 1)}


class Update(NamedTuple):
    """One closed-form update: the new parameters, the step model's covariance (None unless calibrated), the std of
    the steps' scale and of each stride source's scale (their priors' where not estimated)."""

    params: np.ndarray
    model_cov: np.ndarray | None
    step_scale_std: float
    stride_scale_std: np.ndarray


def solve_normal(h: scipy.sparse.spmatrix, rhs: np.ndarray) -> np.ndarray | None:
    """``h^-1 rhs`` for the poses' normal matrix ``h`` (symmetric positive definite); None when it is singular.

    Every factor links poses a few epochs apart (a step, a stride, a GNSS fix between two epochs), so ``h`` is a band
    matrix in key order: a banded Cholesky factor needs (bandwidth + 1) numbers a pose column, less memory than a
    general sparse LU. A wider band (a stride over many epochs) takes the sparse LU."""
    lower = scipy.sparse.tril(h).tocoo()
    band = int((lower.row - lower.col).max(initial=0))
    try:
        if band <= MAX_BAND:
            packed = np.zeros((band + 1, h.shape[0]))
            packed[lower.row - lower.col, lower.col] = lower.data
            return scipy.linalg.cho_solve_banded((scipy.linalg.cholesky_banded(packed, lower=True), True), rhs)
        return scipy.sparse.linalg.splu(scipy.sparse.csc_matrix(h)).solve(rhs)
    except (RuntimeError, np.linalg.LinAlgError):
        return None


class JointStep(NamedTuple):
    """The joint Gauss-Newton step: each estimated block's new values and marginal standard deviations, by name."""

    params: dict[str, np.ndarray]
    std: dict[str, np.ndarray]


class AndersonMixing:
    """Anderson acceleration of a fixed point ``x = g(x)`` with residual ``f = g(x) - x`` (Walker & Ni 2011), over
    the last ``depth`` differences; restarted on request or when the residual more than doubles."""

    def __init__(self, depth: int):
        self.depth = depth
        self._df: list[np.ndarray] = []
        self._dg: list[np.ndarray] = []
        self._f = self._g = None

    def next(self, f: np.ndarray, g: np.ndarray, restart: bool) -> np.ndarray:
        """The next iterate from the residual ``f`` (any scaling) and the mapped point ``g``."""
        if restart or self._f is None or np.linalg.norm(f) > 2.0 * np.linalg.norm(self._f):
            self._df.clear()
            self._dg.clear()
        else:
            self._df.append(f - self._f)
            self._dg.append(g - self._g)
            del self._df[:-self.depth], self._dg[:-self.depth]
        self._f, self._g = f, g
        if not self._df:
            return g
        gamma = np.linalg.lstsq(np.column_stack(self._df), f, rcond=None)[0]
        return g - np.column_stack(self._dg) @ gamma


class Calibration:
    """What a walk lets the fusion estimate, the parameter vector's start and the updates given the poses.

    ``fusion`` is the :class:`~pdr.fusion.FactorGraphFusion` whose parameters apply; ``step_model`` as its ``fuse``.
    """

    def __init__(self, fusion, problem: Problem, step_model):
        self.fusion, self.problem = fusion, problem
        n, n_fix = problem.n_steps, len(problem.gnss_row)
        self.absolute = n_fix >= 1
        observable = n_fix >= 2 or len(problem.stride_length_m) > 0
        self.feats_ok = (np.isfinite(problem.features).all(axis=1) & ~problem.gap if problem.features is not None
                         else np.zeros(n, bool))
        regression = step_model is None or isinstance(step_model, RegressionStepLength)
        self.calibrate = bool(fusion.calibrate_step_model and regression and observable
                              and problem.features is not None and self.feats_ok.sum() >= 3)
        # the steps' own lengths (per-form models, or a one-parameter model such as Zijlstra's) times one scale
        self.own_scale = (step_model is not None and not regression
                          and len(getattr(step_model, "theta_names", ())) == 1)
        self.scale_steps = bool((fusion.calibrate_step_scale or (fusion.calibrate_step_model and self.own_scale))
                                and not self.calibrate and observable)
        self.model_prior = None
        if self.calibrate:
            if step_model is None:
                step_model = RegressionStepLength.population()
            self.model_prior = step_model_params(step_model, (fusion.prior_a_std_m, fusion.prior_b_std_m_per_hz,
                                                              fusion.prior_c_std_m_per_m2ps4))
        self.step_model = step_model
        self.has_mag = np.isfinite(problem.mag_rad)
        self.estimate_bias = n_fix >= 2 or bool(self.has_mag.any())
        self.sources, self.src, self.scale_prior_std = fusion._stride_sources(problem)
        n_src = len(self.sources)
        self.estimate_scales = bool(fusion.calibrate_stride_scales and n_fix >= 2 and n_src > 0)
        self.bias0 = zero_series(problem.epoch_t_s, fusion.gyro_bias_knot_s)
        n_dev = deviation_design(np.zeros(1)).shape[1]
        nb = len(self.bias0.values)
        self.layout = ParamLayout.of(nb, n_dev, n_src)
        self.dt = problem.step_duration_s
        self.known_turn = problem.dtheta_std_rad < BOUT_START_HEADING_STD_RAD
        self.known_turn[0] = False
        self.t_step = problem.epoch_t_s[1:]
        theta0 = self.model_prior.theta if self.calibrate else np.zeros(3)
        self.params0 = np.concatenate([theta0, self.bias0.values, np.zeros(n_dev), np.ones(n_src), np.ones(1)])
        # each parameter in metres of effect on the path (convergence test and acceleration)
        mean_length = float(np.mean(problem.step_length_m)) if n else 1.0
        mean_speed = mean_length / float(np.median(self.dt)) if n else 1.0
        feat_scale = (np.abs(np.nanmean(problem.features[self.feats_ok], axis=0)) if self.calibrate
                      else np.ones(3))
        src = self.src
        mean_stride = np.bincount(src, problem.stride_length_m, n_src) / np.maximum(np.bincount(src, minlength=n_src), 1)
        # a bias knot turns the path over a knot's span, or over the whole walk when it is shorter
        bias_span_s = min(fusion.gyro_bias_knot_s, float(problem.epoch_t_s[-1] - problem.epoch_t_s[0])) if n else 1.0
        self.scale_m = np.concatenate([feat_scale, np.full(nb, 0.5 * bias_span_s ** 2 * mean_speed),
                                       np.full(n_dev, 10.0 * mean_length), mean_stride, [mean_length]])
        self.step_scale_prior_std = fusion.step_scale_prior_std
        if self.own_scale and step_model.covariance_matrix is not None:  # the model's own prior on its one parameter
            self.step_scale_prior_std = float(np.sqrt(step_model.covariance_matrix[0, 0]) / abs(step_model.theta[0]))
        self.step_scale_prior = StepModelParams(np.ones(1), np.array([[self.step_scale_prior_std ** 2]]), 0.0)
        # the blocks the joint step solves with the poses; a bias of more knots than MAX_JOINT_BIAS_KNOTS (walks of
        # hours) keeps its closed form: the poses' elimination would hold a dense (3 poses x knots) matrix
        self.joint_blocks = tuple(name for name, on in (
            ("theta", self.calibrate), ("step_scale", self.scale_steps),
            ("bias", self.estimate_bias and nb <= MAX_JOINT_BIAS_KNOTS), ("deviation", bool(self.has_mag.any())),
            ("stride_scales", self.estimate_scales)) if on)
        self.nonnegative = tuple(RegressionStepLength.theta_names.index(name)
                                 for name in RegressionStepLength.nonnegative)

    def bias(self, p: np.ndarray) -> SmoothSeries:
        """The heading-rate bias (rad/s) of the parameters ``p``."""
        return SmoothSeries(self.bias0.t0_s, self.bias0.knot_s, p[self.layout.bias])

    def measurements(self, p: np.ndarray) -> Measurements:
        """The step lengths, heading changes, deviation coefficients and stride lengths of the parameters ``p``."""
        problem, lay = self.problem, self.layout
        length = (np.where(self.feats_ok, np.nan_to_num(problem.features) @ p[lay.theta], problem.step_length_m)
                  if self.calibrate else problem.step_length_m * p[lay.step_scale])
        dtheta = problem.dtheta_rad - self.bias(p)(self.t_step) * self.dt
        return Measurements(length, dtheta, p[lay.deviation], problem.stride_length_m * p[lay.stride_scales][self.src])

    def update(self, poses: np.ndarray, p: np.ndarray, values: gtsam.Values, use: np.ndarray) -> Update:
        """The parameters after a solve: the joint Gauss-Newton step of the estimated blocks (:meth:`joint_step`, at
        the solved ``poses`` / ``values`` with the fixes ``use`` the graph had), else (a singular joint system) each
        block's closed form given the ``poses``; a block that is not observable is kept. The step model's covariance
        is its closed form's."""
        problem, lay, fusion = self.problem, self.layout, self.fusion
        out, cov = p.copy(), None
        step_scale_std, scale_std = self.step_scale_prior_std, self.scale_prior_std.copy()
        joint = self.joint_step(poses, values, p, use) if self.joint_blocks else None
        solved = set() if joint is None else set(joint.params)
        if joint is not None:
            for name, value in joint.params.items():
                out[lay.block(name)] = value  # a negative cadence slope is replaced by the bounded closed form below
            step_scale_std = float(joint.std.get("step_scale", [step_scale_std])[0])
            scale_std = joint.std.get("stride_scales", scale_std)
        if self.estimate_bias and "bias" not in solved:
            resid = wrap_rad(np.diff(poses[:, 2]) - problem.dtheta_rad)
            ok = self.known_turn & (self.dt > 0)
            if ok.sum() >= 2:
                out[lay.bias] = solve_series(self.bias0, self.t_step[ok], resid[ok], -self.dt[ok],
                                             problem.dtheta_std_rad[ok], fusion.gyro_bias_rw_radps_per_sqrt_s,
                                             fusion.gyro_bias_prior_std_radps).values
        if self.has_mag.any() and "deviation" not in solved:
            has_mag = self.has_mag
            heading = poses[1:, 2][has_mag]
            y = wrap_rad(problem.mag_rad[has_mag] - heading)
            inlier = (np.abs(wrap_rad(y - deviation_design(heading) @ p[lay.deviation]))
                      <= 5.0 * problem.mag_std_rad[has_mag])
            if inlier.any():
                out[lay.deviation] = solve_deviation(y[inlier], heading[inlier], problem.mag_std_rad[has_mag][inlier],
                                                     fusion.mag_deviation_prior_std_rad)
        if self.calibrate:  # its covariance always; its value where the joint step gave none or a negative parameter
            ok = self.feats_ok
            theta, cov = solve_step_model(along_track(poses)[ok], problem.features[ok],
                                          problem.step_length_std_m[ok], self.model_prior, self.nonnegative)
            if "theta" not in solved or any(joint.params["theta"][j] < 0 for j in self.nonnegative):
                out[lay.theta] = theta
        if self.scale_steps and "step_scale" not in solved:  # along = k x length + e, prior k ~ N(1, std^2)
            ok = ~problem.gap
            k, k_cov = solve_step_model(along_track(poses)[ok], problem.step_length_m[ok, None],
                                        problem.step_length_std_m[ok], self.step_scale_prior)
            out[lay.step_scale], step_scale_std = float(k[0]), float(np.sqrt(k_cov[0, 0]))
        if self.estimate_scales and "stride_scales" not in solved:  # the closed form, conditional on the poses
            k0, k1 = problem.stride_k[:, 0], problem.stride_k[:, 1]
            distance = np.linalg.norm(poses[k1, :2] - poses[k0, :2], axis=1)
            out[lay.stride_scales], scale_std = solve_stride_scales(
                distance, problem.stride_length_m, problem.stride_std_m, self.src, self.scale_prior_std,
                p[lay.stride_scales], fusion.huber_k)
        return Update(out, cov, step_scale_std, scale_std)

    def gnss_scale_info(self, poses: np.ndarray, use: np.ndarray, spans: list[tuple[int, int]]) -> np.ndarray:
        """Per span of epochs ``[k0, k1]`` (a stride source's, or the whole walk for the steps' scale), the most
        information (1 / scale variance) GNSS with correlated errors can give a length scale there: ``D^2 / (2 m
        sigma^2)`` over the stretch covered by both the used fixes and the span."""
        problem = self.problem
        out = np.zeros(len(spans))
        k_fix = problem.gnss_k[use]
        if len(k_fix) < 2:
            return out
        walked = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1))])
        for q, (k0, k1) in enumerate(spans):
            lo, hi = max(int(k_fix.min()), k0), min(int(k_fix.max()) + 1, k1)
            if hi <= lo:
                continue
            distance = walked[hi] - walked[lo]
            m = max(1.0, (problem.epoch_t_s[hi] - problem.epoch_t_s[lo]) / self.fusion.gnss_correlation_s)
            out[q] = distance ** 2 / (2.0 * m * self.fusion.gnss_correlated_std_m ** 2)
        return out

    def scale_spans(self, name: str) -> list[tuple[int, int]]:
        """The epochs each length scale of a block covers: a stride source's first to last stride, or every step."""
        if name == "step_scale":
            return [(0, self.problem.n_steps)]
        k = self.problem.stride_k
        return [(int(k[self.src == q, 0].min()), int(k[self.src == q, 1].max())) for q in range(len(self.sources))]

    def joint_step(self, poses: np.ndarray, values: gtsam.Values, p: np.ndarray, use: np.ndarray) -> JointStep | None:
        """Gauss-Newton step of every estimated parameter block (:attr:`joint_blocks`) jointly with the poses.

        Given the poses alone the parameters crawl (the strides, not GNSS, set the path length; the gyro bias and the
        magnetometer deviation both turn the path, and each block's solve undoes much of the other's: block
        coordinate descent takes tens of alternations), so the poses are eliminated instead: the graph of the
        parameters ``p`` built at the solved ``poses`` and linearised at them (``values``: gtsam's whitened,
        robust-weighted rows ``A dx = b``) gets one column per parameter: the derivatives of the whitened errors, by
        finite differences of ``b`` in each measurement a block enters (the step lengths, the heading changes, the
        magnetometer headings, the stride lengths). Each row depends on its own measurement only, so one difference
        serves a whole block, and blocks on other rows share a graph. The Schur complement of the poses gives the
        parameters' reduced system ``S dq = r``; with the priors that is the MAP step and the parameters' marginal
        covariance. Each length scale's information from GNSS is capped at :meth:`gnss_scale_info` (the cap taken as a
        tighter prior with the same posterior mean). None when the system is singular.
        """
        problem, lay = self.problem, self.layout
        meas = self.measurements(p)
        n_pose = 3 * values.size()  # all keys are Pose2, in key order: pose k -> columns 3k..3k+2

        blocks = graph_rows(problem, use)
        n_rows = blocks["gnss"].stop

        def linearized(m: Measurements, with_a: bool) -> tuple[scipy.sparse.csr_matrix | None, np.ndarray] | None:
            """The whitened system ``A dx = b`` of the graph of the measurements ``m`` at ``values`` (``A`` only if
            ``with_a``), the step factors' noise held at the current lengths (a Gauss-Newton step); None when its
            rows are not those of :func:`graph_rows`."""
            g, _ = build_graph(problem, poses, m, use, self.absolute, gnss_factor=self.fusion.gnss_factor,
                               huber_k=self.fusion.huber_k, noise_length_m=meas.step_length_m)
            r, c, v = np.asarray(g.linearize(values).sparseJacobian_())
            r, c = r.astype(np.int64) - 1, c.astype(np.int64) - 1
            if r.max(initial=-1) + 1 != n_rows:
                return None
            is_b = c == n_pose
            b = np.bincount(r[is_b], v[is_b], n_rows)
            keep = ~is_b
            a = scipy.sparse.csr_matrix((v[keep], (r[keep], c[keep])), shape=(n_rows, n_pose)) if with_a else None
            return a, b

        base = linearized(meas, True)
        if base is None:
            return None
        a_pp, b0 = base

        def d_rows(**changed) -> np.ndarray:
            """-d b / d(measurement) per row, the measurements of the named kinds moved by the amounts given."""
            _, b = linearized(meas._replace(**{k: getattr(meas, k) + d for k, d in changed.items()}), False)
            return -(b - b0) / FD_STEP

        step_rows, heading_rows = np.arange(n_rows)[blocks["steps"]], np.arange(n_rows)[blocks["heading"]]
        stride_rows = np.arange(n_rows)[blocks["strides"]]

        def on_rows(rows_of: np.ndarray, derivative: np.ndarray, design: np.ndarray, per: int):
            """(n_rows, k) sparse columns: each measurement's rows (``per`` of them) times its row of ``design``."""
            repeated = scipy.sparse.csr_matrix(np.repeat(design, per, axis=0))
            entries = repeated.multiply(derivative[rows_of, None]).tocoo()
            return scipy.sparse.csc_matrix((entries.data, (rows_of[entries.row], entries.col)),
                                           shape=(n_rows, design.shape[1]))

        names, columns, now, mean, info = [], [], [], [], []

        def add(name, cols_, prior_mean, prior_info):
            names.append(name)
            columns.append(cols_)
            now.append(p[lay.block(name)])
            mean.append(prior_mean)
            info.append(prior_info)

        # the differences: the step lengths and the heading changes share the step factors' rows, so each needs a
        # graph of its own; the magnetometer headings and the stride lengths ride along with the first
        lengths, turns = self.calibrate or self.scale_steps, "bias" in self.joint_blocks
        others = {}
        if "deviation" in self.joint_blocks:  # the constant term: every magnetometer heading moved alike
            others["mag_deviation_coef"] = np.r_[FD_STEP, np.zeros(len(meas.mag_deviation_coef) - 1)]
        if self.estimate_scales:  # relative: d/d(scale) at once
            others["stride_length_m"] = FD_STEP * problem.stride_length_m
        d_len = d_rows(step_length_m=FD_STEP, **others) if lengths else None
        d_turn = d_rows(dtheta_rad=FD_STEP, **({} if lengths else others)) if turns else None
        d_other = d_len if lengths else d_turn if turns else d_rows(**others)
        if self.calibrate:  # length = features . theta where the features are known
            design = np.where(self.feats_ok[:, None], np.nan_to_num(problem.features), 0.0)
            add("theta", on_rows(step_rows, d_len, design, 3), self.model_prior.theta,
                np.linalg.inv(self.model_prior.covariance))
        if self.scale_steps:  # length = k x the steps' own lengths
            add("step_scale", on_rows(step_rows, d_len, problem.step_length_m[:, None], 3), np.ones(1),
                np.array([[self.step_scale_prior_std ** -2]]))
        if turns:  # heading change = measured - b(t) dt, b linear between knots
            j, frac = series_weights(self.bias0, self.t_step)
            weights = np.zeros((problem.n_steps, len(self.bias0.values)))
            np.add.at(weights, (np.arange(problem.n_steps), j), 1.0 - frac)
            np.add.at(weights, (np.arange(problem.n_steps), j + 1), frac)
            add("bias", on_rows(step_rows, d_turn, -self.dt[:, None] * weights, 3), np.zeros(weights.shape[1]),
                series_prior_information(self.bias0, self.fusion.gyro_bias_rw_radps_per_sqrt_s,
                                         self.fusion.gyro_bias_prior_std_radps))
        if "deviation" in self.joint_blocks:  # magnetometer heading = measured - deviation_design(heading) . c
            design = deviation_design(poses[np.flatnonzero(self.has_mag) + 1, 2])
            add("deviation", on_rows(heading_rows, d_other, design, 1), np.zeros(design.shape[1]),
                np.eye(design.shape[1]) / self.fusion.mag_deviation_prior_std_rad ** 2)
        if self.estimate_scales:  # stride length = measured x its source's scale
            add("stride_scales", on_rows(stride_rows, d_other, np.eye(len(self.scale_prior_std))[self.src], 1),
                np.ones(len(self.scale_prior_std)), np.diag(1.0 / np.square(self.scale_prior_std)))
        j_q = scipy.sparse.hstack(columns).tocsc()
        h_pq = (a_pp.T @ j_q).toarray()
        x = solve_normal(a_pp.T @ a_pp, np.column_stack([h_pq, a_pp.T @ b0]))
        if x is None or not np.isfinite(x).all():
            return None
        s_red = (j_q.T @ j_q).toarray() - h_pq.T @ x[:, :-1]
        r_red = j_q.T @ b0 - h_pq.T @ x[:, -1]
        sizes = {name: len(m) for name, m in zip(names, mean)}
        at = named_blocks(sizes)
        prior = scipy.linalg.block_diag(*info)
        q_now, q_prior = np.concatenate(now), np.concatenate(mean)
        capped_std = {}
        try:
            cov = np.linalg.inv(s_red + prior)
            for name in ("step_scale", "stride_scales"):  # length scales: GNSS's information capped
                if name in at:
                    block = at[name]
                    info_prior = np.diag(prior)[block].copy()
                    info_white = np.maximum(1.0 / np.diag(cov)[block] - info_prior, 0.0)
                    info_cap = self.gnss_scale_info(poses, use, self.scale_spans(name))
                    capped = info_white > info_cap
                    # the capped posterior mean = the white-noise one with a prior of info_prior * info_white / info_cap
                    tighter = info_prior * info_white / np.maximum(info_cap, 1e-12)
                    prior[block, block] = np.diag(np.where(capped, tighter, info_prior))
                    capped_std[name] = 1.0 / np.sqrt(np.minimum(info_white, info_cap) + info_prior)
            step = np.linalg.solve(s_red + prior, r_red - prior @ (q_now - q_prior))
        except np.linalg.LinAlgError:
            return None
        q_new = q_now + step
        std = {name: np.sqrt(np.diag(cov)[at[name]]) for name in names} | capped_std
        return JointStep({name: q_new[at[name]] for name in names}, std)
