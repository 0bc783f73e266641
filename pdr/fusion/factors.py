"""The factors of the PDR graph (all gtsam code of `pdr` lives in :mod:`pdr.fusion`).

Built-in factors wherever one exists: ``BetweenFactorPose2`` (a step), ``RangeFactorPose2`` (a stride),
``PoseRotationPrior2D`` (magnetometer heading), ``PoseTranslationPrior2D`` (a GNSS fix moved to the nearest epoch),
``PriorFactorPose2`` (the start). One Python ``CustomFactor``, :func:`gnss_interpolated_factor`, ties a fix to the
position interpolated between the two poses around it; its Jacobian is checked numerically in the tests.
"""

from __future__ import annotations

from functools import lru_cache, partial

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

ANCHOR_STD = (1e-3, 1e-3, 1e-4)  # start pose of a walk without absolute information: fixed at origin / first heading
WEAK_START_STD = (1e4, 1e4, np.pi)  # start pose with GNSS: only removes the gauge freedom a single fix would leave


def pose_key(i: int) -> int:
    return X(int(i))


def step_factor(i: int, length_m: float, dtheta_rad: float, length_std_m: float, dtheta_std_rad: float,
                lateral_std_m: float, noise_length_m: float | None = None) -> gtsam.BetweenFactorPose2:
    """Step ``i`` from epoch ``i`` to ``i + 1``: ``length_m`` along the new heading (the previous heading turned by
    ``dtheta_rad``). Noise: along-track ``length_std_m`` and heading ``dtheta_std_rad`` mapped through the step
    geometry of a step of ``noise_length_m`` (default ``length_m``; full covariance), plus ``lateral_std_m`` across
    the step."""
    lever = length_m if noise_length_m is None else noise_length_m
    # BetweenFactor errors live in the tangent space at the measured relative pose, i.e. in the frame of the pose at
    # the end of the step, whose x axis is the step direction: along = x, across = y (coupled with the heading).
    c, s = np.cos(dtheta_rad), np.sin(dtheta_rad)
    cov = np.array([[length_std_m ** 2, 0.0, 0.0],
                    [0.0, (lever * dtheta_std_rad) ** 2 + lateral_std_m ** 2, lever * dtheta_std_rad ** 2],
                    [0.0, lever * dtheta_std_rad ** 2, dtheta_std_rad ** 2]])
    return gtsam.BetweenFactorPose2(pose_key(i), pose_key(i + 1), gtsam.Pose2(length_m * c, length_m * s, dtheta_rad),
                                    gtsam.noiseModel.Gaussian.Covariance(cov))


def robust(model: gtsam.noiseModel.Base, huber_k: float) -> gtsam.noiseModel.Base:
    return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k), model)


@lru_cache(maxsize=1 << 16)
def gnss_noise(std_m: float, huber_k: float) -> gtsam.noiseModel.Base:
    """Isotropic 2-D noise behind a Huber kernel; cached (noise models are shared, immutable, and a graph is rebuilt
    at every alternation with the same ones)."""
    return robust(gtsam.noiseModel.Isotropic.Sigma(2, float(std_m)), huber_k)


@lru_cache(maxsize=1 << 16)
def heading_noise(std_rad: float, huber_k: float) -> gtsam.noiseModel.Base:
    return robust(gtsam.noiseModel.Isotropic.Sigma(1, float(std_rad)), huber_k)


def _interpolated_error(alpha: float, measured: np.ndarray, this: gtsam.CustomFactor, values: gtsam.Values,
                        jacobians: list[np.ndarray] | None) -> np.ndarray:
    p0 = values.atPose2(this.keys()[0])
    p1 = values.atPose2(this.keys()[1])
    error = (1.0 - alpha) * p0.translation() + alpha * p1.translation() - measured
    if jacobians is not None:
        # d translation / d local coordinates (x, y, theta) of Pose2 retract = [R, 0]
        jacobians[0] = (1.0 - alpha) * np.hstack([p0.rotation().matrix(), np.zeros((2, 1))])
        jacobians[1] = alpha * np.hstack([p1.rotation().matrix(), np.zeros((2, 1))])
    return error


def gnss_interpolated_factor(k: int, alpha: float, measured_en_m: np.ndarray, noise: gtsam.noiseModel.Base
                             ) -> gtsam.CustomFactor:
    """A fix at fraction ``alpha`` of the way from epoch ``k`` to ``k + 1``: error = ``(1 - alpha) t_k + alpha t_k+1 - z``
    (linear interpolation of the position between the two step epochs; exact for a straight step)."""
    measured = np.asarray(measured_en_m, float).reshape(2)
    return gtsam.CustomFactor(noise, [pose_key(k), pose_key(k + 1)], partial(_interpolated_error, float(alpha), measured))


def gnss_shifted_factor(k: int, measured_en_m: np.ndarray, shift_en_m: np.ndarray,
                        noise: gtsam.noiseModel.Base) -> gtsam.PoseTranslationPrior2D:
    """The built-in alternative: the fix moved by ``shift_en_m`` (pose at epoch ``k`` minus the interpolated position
    at the fix time, from the current estimate) onto the nearest epoch ``k``."""
    z = np.asarray(measured_en_m, float).reshape(2) + np.asarray(shift_en_m, float).reshape(2)
    return gtsam.PoseTranslationPrior2D(pose_key(k), z, noise)


def heading_factor(i: int, heading_rad: float, std_rad: float, huber_k: float) -> gtsam.PoseRotationPrior2D:
    """Absolute heading (magnetometer, offset removed) of the pose at epoch ``i``, robust (Huber)."""
    return gtsam.PoseRotationPrior2D(pose_key(i), gtsam.Rot2(float(heading_rad)), heading_noise(float(std_rad), huber_k))


def stride_factor(k0: int, k1: int, length_m: float, std_m: float, huber_k: float) -> gtsam.RangeFactorPose2:
    """A stride (any source) as the distance between the poses at its start and end epochs, robust (Huber)."""
    return gtsam.RangeFactorPose2(pose_key(k0), pose_key(k1), float(length_m),
                                  robust(gtsam.noiseModel.Isotropic.Sigma(1, float(std_m)), huber_k))


def start_prior(pose: gtsam.Pose2, anchored: bool) -> gtsam.PriorFactorPose2:
    std = ANCHOR_STD if anchored else WEAK_START_STD
    return gtsam.PriorFactorPose2(pose_key(0), pose, gtsam.noiseModel.Diagonal.Sigmas(np.array(std)))


def world_position_cov(pose_cov: np.ndarray, heading_rad: float) -> np.ndarray:
    """Pose2 marginal covariance is in the body frame (tangent space): rotate its translation block to east-north."""
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    rot = np.array([[c, -s], [s, c]])
    return rot @ pose_cov[:2, :2] @ rot.T
