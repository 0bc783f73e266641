"""Closed-form (linear least-squares) updates of the parameters that enter the step factors linearly.

The step length ``A + B f + C v``, a heading-rate bias ``b(t)`` (gyro) and the deviation of the magnetometer heading
(a function of heading) enter the per-step measurements linearly. Given the poses, each is a small weighted least-squares problem with a
Gaussian prior; :class:`~pdr.fusion.graph.FactorGraphFusion` alternates these with the pose solve (block coordinate
descent on the joint objective), which keeps every per-step factor a built-in one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solveh_banded


@dataclass
class StepModelParams:
    """A linear step model ``length = features . theta`` as arrays: ``theta`` and its prior covariance. The
    regression ``length = a + b f + c v`` has ``theta = [a, b, c]``; a scale of given lengths has ``theta = [k]``."""

    theta: np.ndarray
    covariance: np.ndarray
    residual_std_m: float


def step_model_params(model, prior_std: tuple[float, float, float]) -> StepModelParams:
    """Read a RegressionStepLength-like object (``a_m, b_m_per_hz, c_m_per_m2ps4, residual_std_m, covariance``)."""
    theta = np.array([model.a_m, model.b_m_per_hz, model.c_m_per_m2ps4], float)
    cov = getattr(model, "covariance", None)
    cov = np.diag(np.square(prior_std)) if cov is None else np.asarray(cov, float).reshape(3, 3)
    return StepModelParams(theta=theta, covariance=cov, residual_std_m=float(model.residual_std_m))


def solve_step_model(distance_m: np.ndarray, features: np.ndarray, std_m: np.ndarray,
                     prior: StepModelParams, nonnegative: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """MAP of ``theta`` for ``distance_i = features_i . theta + e_i``, ``e_i ~ N(0, std_i^2)``, prior ``N(theta0, P0)``,
    with the parameters of index ``nonnegative`` held at >= 0 (:func:`bounded_map`).

    Returns ``(theta, covariance)``; the covariance is conditional on the distances (the poses)."""
    w = 1.0 / np.square(std_m)
    p0_inv = np.linalg.inv(prior.covariance)
    info = features.T @ (features * w[:, None]) + p0_inv
    rhs = features.T @ (w * distance_m) + p0_inv @ prior.theta
    return bounded_map(info, rhs, nonnegative)


def bounded_map(info: np.ndarray, rhs: np.ndarray, nonnegative: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """The maximum of the Gaussian with information matrix ``info`` and vector ``rhs`` (mean ``info^-1 rhs``) subject
    to ``theta[j] >= 0`` for ``j`` in ``nonnegative``: a parameter whose unconstrained value is negative is held at 0
    and the others take their conditional mean (the exact constrained optimum when one bound is active); returns
    ``(theta, covariance)``, the covariance that of the unconstrained Gaussian (a held parameter stays uncertain)."""
    p = len(rhs)
    cov = np.linalg.inv(info)
    held: list[int] = []
    while True:
        free = [j for j in range(p) if j not in held]
        theta = np.zeros(p)
        theta[free] = np.linalg.solve(info[np.ix_(free, free)], rhs[free])
        negative = [j for j in nonnegative if j in free and theta[j] < 0]
        if not negative:
            return theta, cov
        held.append(min(negative, key=lambda j: theta[j]))


def deviation_design(heading_rad: np.ndarray) -> np.ndarray:
    """Compass deviation as a function of heading: ``[1, cos h, sin h, cos 2h, sin 2h]`` (a constant offset,
    hard iron -> first harmonic, soft iron -> second harmonic; the classic deviation curve of a compass)."""
    h = np.asarray(heading_rad, float)
    return np.column_stack([np.ones(len(h)), np.cos(h), np.sin(h), np.cos(2 * h), np.sin(2 * h)])


def solve_deviation(y_rad: np.ndarray, heading_rad: np.ndarray, std_rad: np.ndarray, prior_std_rad: float) -> np.ndarray:
    """MAP deviation coefficients for ``y = deviation_design(heading) . c + e``, zero-mean prior ``prior_std_rad``."""
    a = deviation_design(heading_rad)
    w = 1.0 / np.square(std_rad)
    info = a.T @ (a * w[:, None]) + np.eye(a.shape[1]) / prior_std_rad ** 2
    return np.linalg.solve(info, a.T @ (w * y_rad))


@dataclass
class SmoothSeries:
    """A scalar function of time, piecewise linear between knots spaced ``knot_s`` apart, with a random-walk prior
    between knots (``rw_per_sqrt_s``) and a zero-mean prior of ``prior_std`` on the first knot."""

    t0_s: float
    knot_s: float
    values: np.ndarray

    def __call__(self, t_s: np.ndarray) -> np.ndarray:
        knots = self.t0_s + self.knot_s * np.arange(len(self.values))
        return np.interp(t_s, knots, self.values)


def zero_series(t_s: np.ndarray, knot_s: float) -> SmoothSeries:
    n = int(np.ceil((t_s[-1] - t_s[0]) / knot_s)) + 2
    return SmoothSeries(t0_s=float(t_s[0]), knot_s=knot_s, values=np.zeros(n))


def series_weights(like: SmoothSeries, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each time, the index of the knot before it and its fraction of the way to the next one (linear
    interpolation: ``f(t) = (1 - frac) v[j] + frac v[j + 1]``)."""
    n = len(like.values)
    u = (np.asarray(t_s, float) - like.t0_s) / like.knot_s
    j = np.clip(np.floor(u).astype(int), 0, n - 2)
    return j, np.clip(u - j, 0.0, 1.0)


def series_prior_information(like: SmoothSeries, rw_per_sqrt_s: float, prior_std: float) -> np.ndarray:
    """The (n, n) information matrix of the knots' prior: a random walk between knots, ``prior_std`` on the first."""
    n = len(like.values)
    rw = 1.0 / (rw_per_sqrt_s ** 2 * like.knot_s)
    diff = np.diff(np.eye(n), axis=0)
    info = rw * diff.T @ diff
    info[0, 0] += 1.0 / prior_std ** 2
    return info


def solve_series(like: SmoothSeries, t_s: np.ndarray, y: np.ndarray, scale: np.ndarray, std: np.ndarray,
                 rw_per_sqrt_s: float, prior_std: float) -> SmoothSeries:
    """MAP knot values for ``y_i = scale_i f(t_i) + e_i``; a tridiagonal normal system solved in O(n)."""
    n = len(like.values)
    j, frac = series_weights(like, t_s)
    a0, a1 = scale * (1.0 - frac), scale * frac
    w = 1.0 / np.square(std)
    diag = np.zeros(n)
    off = np.zeros(n - 1)
    rhs = np.zeros(n)
    np.add.at(diag, j, w * a0 * a0)
    np.add.at(diag, j + 1, w * a1 * a1)
    np.add.at(off, j, w * a0 * a1)
    np.add.at(rhs, j, w * a0 * y)
    np.add.at(rhs, j + 1, w * a1 * y)
    rw = 1.0 / (rw_per_sqrt_s ** 2 * like.knot_s)
    diag[:-1] += rw
    diag[1:] += rw
    off -= rw
    diag[0] += 1.0 / prior_std ** 2
    banded = np.zeros((2, n))
    banded[0, 1:] = off
    banded[1] = diag
    return SmoothSeries(t0_s=like.t0_s, knot_s=like.knot_s, values=solveh_banded(banded, rhs))


def solve_stride_scales(distance_m: np.ndarray, length_m: np.ndarray, std_m: np.ndarray, group: np.ndarray,
                        prior_std: np.ndarray, current: np.ndarray, huber_k: float) -> tuple[np.ndarray, np.ndarray]:
    """MAP multiplicative length scale of each stride source, ``distance_j = s_g length_j + e_j``, prior
    ``N(1, prior_std_g^2)``; each stride weighted as its Huber factor is at the ``current`` scales.

    Returns ``(scale, std)`` per source; the std is conditional on the distances (the poses)."""
    n = len(prior_std)
    r = np.abs(distance_m - current[group] * length_m) / std_m
    w = np.where(r <= huber_k, 1.0, huber_k / np.maximum(r, 1e-12)) / np.square(std_m)
    p0 = 1.0 / np.square(prior_std)
    info = np.bincount(group, w * length_m ** 2, minlength=n) + p0
    rhs = np.bincount(group, w * length_m * distance_m, minlength=n) + p0
    return rhs / info, 1.0 / np.sqrt(info)
