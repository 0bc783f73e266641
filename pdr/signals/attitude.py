"""Attitude with the offline VQF and earth-frame (east-north-up) acceleration.

VQF (Laidig & Seel, Information Fusion 2023) returns the sensor-to-earth quaternion; its 9D earth frame is
east-north-up (checked in ``tests/test_heading.py``); the 6D frame has the same up axis and an arbitrary yaw.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import vqf
from scipy.spatial.transform import Rotation

from pdr.constants import GRAVITY_MPS2
from pdr.signals.resample import UniformImu, moving_average

ROTATE_BLOCK = 1 << 18  # rows per block in :func:`rotate` and :func:`yaw_increments` (bounded temporaries)
GRAVITY_LOWPASS_S = 1.0  # without a gyroscope: gravity = mean specific force over about two steps


@dataclasses.dataclass
class Attitude:
    """Sensor-to-earth attitude on the grid of a :class:`UniformImu`.

    Attributes
    ----------
    q_wxyz : (N, 4) 6D quaternion (gyro + acc; tilt only, yaw 0, without a gyroscope).
    q9_wxyz : (N, 4) 9D quaternion (with the magnetometer; yaw from magnetic north) or None.
    mag_disturbed : (N,) VQF's magnetic disturbance flag (all True without a magnetometer).
    bias_sigma_radps : (N,) VQF's gyro-bias uncertainty (NaN without a gyroscope).
    has_gyro : whether yaw changes are observable at all.
    """

    q_wxyz: np.ndarray
    q9_wxyz: np.ndarray | None
    mag_disturbed: np.ndarray
    bias_sigma_radps: np.ndarray
    has_gyro: bool


def quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product of (N, 4) w-x-y-z quaternions."""
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], axis=-1)


def rotate(q_wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (N, 3, or one (3,)) by unit quaternions (N, 4): ``q v q*``.

    In blocks of ``ROTATE_BLOCK`` rows: scipy's ``Rotation.apply`` makes rotation matrices of the input's size,
    which for a 10-hour recording at 100 Hz would add a quarter of a gigabyte to the peak memory of ``pdr run``.
    """
    q_wxyz, v = np.asarray(q_wxyz), np.asarray(v)
    out = np.empty(np.broadcast_shapes(v.shape, q_wxyz[:, 1:].shape), np.result_type(q_wxyz, v, float))
    for a in range(0, len(out), ROTATE_BLOCK):
        vb = v[a: a + ROTATE_BLOCK] if len(v) == len(q_wxyz) else v
        out[a: a + ROTATE_BLOCK] = Rotation.from_quat(q_wxyz[a: a + ROTATE_BLOCK], scalar_first=True).apply(vb)
    return out


def yaw_of(q_wxyz: np.ndarray) -> np.ndarray:
    """Yaw (CCW about up) of the sensor x axis; ill-defined when x is near vertical (use :func:`yaw_increments`)."""
    x_earth = rotate(q_wxyz, np.array([1.0, 0.0, 0.0]))
    return np.arctan2(x_earth[:, 1], x_earth[:, 0])


def yaw_increments(q_wxyz: np.ndarray) -> np.ndarray:
    """Rotation about the earth's up axis between consecutive samples (N-1,), rad.

    The earth-frame increment ``q[k+1] q[k]*`` is turned into a rotation vector; its up component is the change of
    heading of every horizontal direction fixed to the body, whatever the device's orientation (no gimbal lock).
    Hand-written (:func:`quat_mul`) for speed: 0.27 s of CPU per million samples, where scipy's
    ``(r[1:] * r[:-1].inv()).as_rotvec()`` takes 1.6 s (scipy 1.17, loaded machine).
    """
    q_wxyz = np.asarray(q_wxyz)
    out = np.empty(max(len(q_wxyz) - 1, 0), np.result_type(q_wxyz, float))
    for a in range(0, len(out), ROTATE_BLOCK):  # blocks: bounded temporaries on long recordings
        q = q_wxyz[a: a + ROTATE_BLOCK + 1]
        conj = q[:-1] * np.array([1.0, -1.0, -1.0, -1.0])
        d = quat_mul(q[1:], conj)
        d = d * np.where(d[:, :1] < 0, -1.0, 1.0)
        vnorm = np.linalg.norm(d[:, 1:], axis=1)
        angle = 2.0 * np.arctan2(vnorm, d[:, 0])
        scale = np.where(vnorm > 1e-12, angle / np.maximum(vnorm, 1e-300), 2.0)
        out[a: a + ROTATE_BLOCK] = d[:, 3] * scale
    return out


def gravity_direction_lowpass(acc_mps2: np.ndarray, rate_hz: float, window_s: float = GRAVITY_LOWPASS_S) -> np.ndarray:
    """Unit gravity ("up") direction in the sensor frame from the mean specific force (no gyroscope)."""
    g = moving_average(acc_mps2, int(round(window_s * rate_hz)), axis=0)
    return g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-9)


def _tilt_quaternion(up_sensor: np.ndarray) -> np.ndarray:
    """Quaternions (yaw 0) rotating the sensor-frame up direction onto the earth z axis."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up_sensor, z)
    s = np.linalg.norm(axis, axis=1)
    c = up_sensor @ z
    axis = np.where(s[:, None] > 1e-12, axis / np.maximum(s[:, None], 1e-300), np.array([1.0, 0.0, 0.0]))
    return Rotation.from_rotvec(axis * np.arctan2(s, c)[:, None]).as_quat(scalar_first=True)


def estimate_attitude(u: UniformImu) -> Attitude:
    """Offline VQF on the uniform IMU (gyro + acc, + mag with its disturbance rejection when present).

    Without a gyroscope only the tilt is known: a yaw-free quaternion from the low-passed accelerometer.
    """
    n = len(u)
    if u.gyr_radps is None:
        up = gravity_direction_lowpass(u.acc_mps2, u.rate_hz)
        return Attitude(q_wxyz=_tilt_quaternion(up), q9_wxyz=None, mag_disturbed=np.ones(n, bool),
                        bias_sigma_radps=np.full(n, np.nan), has_gyro=False)
    gyr = np.ascontiguousarray(u.gyr_radps, dtype=float)
    acc = np.ascontiguousarray(u.acc_mps2, dtype=float)
    mag = None if u.mag_ut is None else np.ascontiguousarray(u.mag_ut, dtype=float)
    out = vqf.offlineVQF(gyr, acc, mag, 1.0 / u.rate_hz)
    q9 = out.get("quat9D") if mag is not None else None
    dist = np.asarray(out["magDistDetected"], bool) if mag is not None else np.ones(n, bool)
    return Attitude(q_wxyz=np.asarray(out["quat6D"]), q9_wxyz=None if q9 is None else np.asarray(q9), mag_disturbed=dist,
                    bias_sigma_radps=np.asarray(out["biasSigma"], float), has_gyro=True)


def earth_acceleration(acc_mps2: np.ndarray, q_wxyz: np.ndarray) -> np.ndarray:
    """Specific force rotated into the earth frame with gravity removed (up positive), m/s²."""
    a = rotate(q_wxyz, acc_mps2)
    a[:, 2] -= GRAVITY_MPS2
    return a
