"""Rotation helpers of the foot INS and the stride estimators (rotation matrices act on column vectors).

``R`` maps sensor-frame vectors into the reference frame: ``v_ref = R @ v_sensor``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def cumulative_rotations(gyr_radps: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Attitude of the sensor relative to its first sample, ``R[k] = R[k-1] @ exp(w dt)``, as an (N, 3, 3) array.

    The sample-to-sample increments use the mean rate of the two samples (trapezoid; scipy's rotation vectors). The
    running product is a blocked scan of the matrices: prefix products inside blocks of ~sqrt(N) samples vectorised
    across blocks, then one pass over the blocks, so an hour at 200 Hz takes well under a second in numpy (scipy's
    ``Rotation`` has no cumulative product, and composing two stacks of a million of them takes 1.0 s of CPU, loaded).
    """
    n = len(gyr_radps)
    if n == 0:
        return np.zeros((0, 3, 3))
    inc = np.empty((n, 3, 3))
    inc[0] = np.eye(3)
    inc[1:] = Rotation.from_rotvec(0.5 * (gyr_radps[1:] + gyr_radps[:-1]) * dt_s[:, None]).as_matrix()
    block = max(1, int(np.ceil(np.sqrt(n))))
    n_blocks = int(np.ceil(n / block))
    padded = np.broadcast_to(np.eye(3), (n_blocks * block, 3, 3)).copy()
    padded[:n] = inc
    padded = padded.reshape(n_blocks, block, 3, 3)
    for i in range(1, block):  # prefix products inside every block at once
        padded[:, i] = padded[:, i - 1] @ padded[:, i]
    carry = np.empty((n_blocks, 3, 3))
    carry[0] = np.eye(3)
    for b in range(1, n_blocks):
        carry[b] = carry[b - 1] @ padded[b - 1, -1]
    out = (carry[:, None] @ padded).reshape(-1, 3, 3)[:n]
    return out


def align_to_gravity(f_sensor: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) that takes the mean specific force at rest onto +z (up); yaw is left at zero-twist."""
    up = np.asarray(f_sensor, dtype=float)
    up = up / np.linalg.norm(up)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = np.linalg.norm(axis), float(up @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return Rotation.from_rotvec(axis / s * np.arctan2(s, c)).as_matrix()
