"""The foot frame of a shoe-mounted IMU, found from the data (any mounting): x = pitch axis, y = forward, z = up."""

from __future__ import annotations

import numpy as np

from pdr.errors import InputError
from pdr.foot._rotations import cumulative_rotations


def swing_displacements(acc: np.ndarray, gyr: np.ndarray, t: np.ndarray, i_mid: np.ndarray,
                        R_cum: np.ndarray | None = None) -> np.ndarray:
    """Displacement (K, 3) of the sensor over each swing between consecutive mid-stances ``i_mid``, in the sensor
    frame of the first mid-stance, gravity removed; velocity zero at both mid-stances (linear de-drift).

    A plain strapdown integration used only to orient the foot frame (which way is forward)."""
    if R_cum is None:
        R_cum = cumulative_rotations(gyr, np.diff(t))
    out = np.zeros((max(len(i_mid) - 1, 0), 3))
    for k in range(len(i_mid) - 1):
        a, b = int(i_mid[k]), int(i_mid[k + 1]) + 1
        rel = np.swapaxes(R_cum[a], -1, -2) @ R_cum[a:b]
        f = np.einsum("nij,nj->ni", rel, acc[a:b])
        lin = f - acc[max(a - 2, 0):a + 3].mean(axis=0)  # gravity as felt at the first mid-stance
        dt = np.diff(t[a:b])
        v = np.vstack([np.zeros(3), np.cumsum(0.5 * (lin[1:] + lin[:-1]) * dt[:, None], axis=0)])
        ramp = (t[a:b] - t[a]) / max(t[b - 1] - t[a], 1e-9)
        v -= ramp[:, None] * v[-1]
        out[k] = np.sum(0.5 * (v[1:] + v[:-1]) * dt[:, None], axis=0)
    return out


def estimate_foot_frame(acc: np.ndarray, gyr: np.ndarray, t: np.ndarray, stance: np.ndarray, i_mid: np.ndarray,
                        *, max_swings: int = 40) -> np.ndarray:
    """Rotation ``R_fs`` (3, 3) from the sensor frame to the foot frame: ``v_foot = R_fs @ v_sensor``.

    z (up): the mean direction of the specific force during stance. x (pitch axis, pointing to the right of the
    walking direction): the principal axis of the angular rate during swing (the foot mainly rolls heel-to-toe),
    made orthogonal to z. y = z x x (forward); the sign of x is chosen so that the swings move the foot along +y.

    Raises InputError when there are not enough stances and swings to tell the axes.
    """
    if stance.sum() < 3 or (~stance).sum() < 3 or len(i_mid) < 2:
        raise InputError("foot IMU: expected at least two stance phases with a swing between them to find the foot "
                         f"axes, found {len(i_mid)} stance(s)")
    f_st = acc[stance]
    up = (f_st / np.linalg.norm(f_st, axis=1, keepdims=True)).mean(axis=0)
    up /= np.linalg.norm(up)
    w_sw = gyr[~stance]
    _, _, vt = np.linalg.svd(w_sw, full_matrices=False)
    x = vt[0] - (vt[0] @ up) * up
    if np.linalg.norm(x) < 0.3:
        raise InputError("foot IMU: expected the foot to roll about a horizontal axis during swing, found the main "
                         "rotation about the vertical: is the sensor on a foot?")
    x /= np.linalg.norm(x)
    y = np.cross(up, x)
    use = i_mid[: max_swings + 1]
    d = swing_displacements(acc, gyr, t, use, cumulative_rotations(gyr[: use[-1] + 1], np.diff(t[: use[-1] + 1])))
    if np.median(d @ y) < 0:
        x, y = -x, -y
    return np.vstack([x, y, up])
