"""A synthetic shoe-IMU walk for the foot tests: rigid-foot kinematics sampled exactly (richer than the estimators'
models: 3-D rotation with pitch, roll and yaw, heel-rise before toe-off, turning path, mounting rotation)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from pdr.constants import GRAVITY_MPS2


def simulate_foot_walk(*, n_strides: int = 12, stride_m: float | np.ndarray = 1.4, stance_s: float = 0.45,
                       swing_s: float = 0.65, turn_rad_per_stride: float = 0.0, rate_hz: float = 200.0,
                       mounting_rotvec: tuple = (0.3, -0.5, 2.0), rest_s: float = 1.0, toe_out_rad: float = 0.0, gyr_bias_radps: float = 0.0,
                       noise: float = 0.0, seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(imu, truth): a canonical IMU table of one foot and the true strides (``t_start_s, t_end_s, length_m``,
    mid-stance to mid-stance). ``toe_out_rad`` turns the foot (not its path) about the vertical."""
    fine = 10
    dt = 1.0 / (rate_hz * fine)
    lengths = np.broadcast_to(np.asarray(stride_m, dtype=float), (n_strides,))
    cycle = stance_s + swing_s
    total = 2 * rest_s + n_strides * cycle + stance_s
    t = np.arange(0.0, total, dt)
    pos = np.zeros((len(t), 3))
    pitch, roll, yaw = np.zeros(len(t)), np.zeros(len(t)), np.zeros(len(t))
    x0, heading = np.zeros(2), 0.0
    truth = []
    t_sw0 = rest_s + stance_s
    pos[:, :2] = x0
    for k in range(n_strides):
        a, b = t_sw0 + k * cycle, t_sw0 + k * cycle + swing_s
        new_heading = heading + turn_rad_per_stride
        x1 = x0 + lengths[k] * np.array([np.cos(0.5 * (heading + new_heading)), np.sin(0.5 * (heading + new_heading))])
        m = t >= a
        tau = np.clip((t[m] - a) / swing_s, 0.0, 1.0)
        prog = tau - np.sin(2 * np.pi * tau) / (2 * np.pi)  # zero velocity and acceleration at both ends
        pos[m, :2] = x0 + prog[:, None] * (x1 - x0)
        side = np.array([-(x1 - x0)[1], (x1 - x0)[0]]) / lengths[k]
        pos[m, :2] += (0.03 * np.sin(np.pi * tau) ** 2)[:, None] * side
        pos[m, 2] = 0.12 * np.sin(np.pi * tau) ** 2 * (1 + 0.5 * np.sin(2 * np.pi * tau))
        # toe down after the heel rise (continuing its -0.05 rad), toe up before landing, flat at both ends
        pitch[m] = -0.05 * (1.0 - prog) - 0.9 * np.sin(np.pi * tau) ** 2 * np.cos(np.pi * tau)
        roll[m] = 0.15 * np.sin(2 * np.pi * tau) * (tau < 1.0)
        yaw[m] = heading + (new_heading - heading) * prog
        # heel rise in the last 0.15 s of the stance: pitch down a little before the swing
        hr = (t >= a - 0.15) & (t < a)
        pitch[hr] = -0.05 * np.sin(0.5 * np.pi * (t[hr] - (a - 0.15)) / 0.15) ** 2
        truth.append((a - 0.5 * stance_s, b + 0.5 * stance_s, float(lengths[k])))
        x0, heading = x1, new_heading
    # foot -> world (z, then x, then y about the turned axes); foot x right, y forward, z up
    R_foot = Rotation.from_euler("ZXY", np.column_stack([yaw - np.pi / 2 + toe_out_rad, pitch, roll])).as_matrix()
    R_mount = Rotation.from_rotvec(np.asarray(mounting_rotvec, dtype=float)).as_matrix()  # sensor -> foot
    R = R_foot @ R_mount
    # body rate from dR: R^T dR/dt = [w x]; specific force f = R^T (a + g)
    dR = np.gradient(R, dt, axis=0)
    W = np.swapaxes(R, 1, 2) @ dR
    w = np.column_stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]])
    acc_w = np.gradient(np.gradient(pos, dt, axis=0), dt, axis=0)
    acc_w[:, 2] += GRAVITY_MPS2
    f = np.einsum("nji,nj->ni", R, acc_w)
    sel = slice(0, None, fine)
    rng = np.random.default_rng(seed)
    t, f, w = t[sel], f[sel], w[sel]
    f = f + noise * 0.05 * rng.standard_normal(f.shape)
    w = w + noise * 0.005 * rng.standard_normal(w.shape) + gyr_bias_radps
    imu = pd.DataFrame({"t_s": t, "acc_x_mps2": f[:, 0], "acc_y_mps2": f[:, 1], "acc_z_mps2": f[:, 2],
                        "gyr_x_radps": w[:, 0], "gyr_y_radps": w[:, 1], "gyr_z_radps": w[:, 2]})
    return imu, pd.DataFrame(truth, columns=["t_start_s", "t_end_s", "length_m"])
