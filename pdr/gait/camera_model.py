"""The thigh camera of the wearable-camera gait estimator (Watanabe, Hatanaka, Komuro & Ishikawa, WACV 2011):
pinhole intrinsics and the mount on the thigh, and the batched axis rotations the observation model is built from.

Frames: world = local east-north-up (m), heading counter-clockwise from east. Body frame: origin on the ground below
the walker on the path, ``f`` forward along the heading, ``l`` to the left, ``u`` up. Thigh frame (as
:mod:`pdr.sim.gait`): x forward, y to the right, z along the thigh from hip to knee. Camera frame: x = image right
(u), y = image down (v), z = optical axis.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pdr.errors import InputError

TWO_PI = 2.0 * np.pi
SIDES = ("left", "right")
JOINTS = ("pelvis", "hip_left", "knee_left", "ankle_left", "hip_right", "knee_right", "ankle_right")


# ----------------------------------------------------------------------------------------------------------------
# Rotations (batched over leading axes). Hand-written: scipy has no derivative of a rotation (``_drot``), and
# ``Rotation.from_euler(...).as_matrix()`` takes 72 us per call against 14 us here on the batches of 1-200 the
# observation model rotates twice per frame and filter iteration (scipy 1.17, loaded machine).
# ----------------------------------------------------------------------------------------------------------------
def _rot(axis: int, a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., axis, axis] = 1.0
    r[..., i, i] = c
    r[..., j, j] = c
    r[..., i, j] = -s
    r[..., j, i] = s
    return r


def _drot(axis: int, a: np.ndarray) -> np.ndarray:
    """d/da of :func:`_rot`."""
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    r = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[..., i, i] = -s
    r[..., j, j] = -s
    r[..., i, j] = -c
    r[..., j, i] = c
    return r


# ----------------------------------------------------------------------------------------------------------------
# The camera
# ----------------------------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ThighCameraModel:
    """A pinhole camera (no lens distortion, as the paper's undistorted images) fixed to a thigh.

    Parameters
    ----------
    fps, focal_px, cx_px, cy_px, width_px, height_px : frame rate and intrinsics.
    side : ``"left"`` or ``"right"`` thigh (the paper: the outer side of the right thigh).
    along_thigh_m : distance of the optical centre from the hip joint centre along the thigh.
    outward_m : offset from the thigh axis to the outer side (skin and mount).
    tilt_out_deg : the optical axis points down the thigh, turned outward by this angle (so that it sees the floor
        beside the foot rather than the own leg).
    """

    fps: float = 100.0
    focal_px: float = 200.0
    cx_px: float = 159.5
    cy_px: float = 119.5
    width_px: int = 320
    height_px: int = 240
    side: str = "right"
    along_thigh_m: float = 0.15
    outward_m: float = 0.08
    tilt_out_deg: float = 20.0

    def __post_init__(self):
        if self.side not in SIDES:
            raise InputError(f"thigh camera: expected side 'left' or 'right', found {self.side!r}")
        positive = ("fps", "focal_px", "width_px", "height_px", "along_thigh_m")
        for k in positive + ("cx_px", "cy_px", "outward_m", "tilt_out_deg"):
            v = getattr(self, k)
            try:
                x = float(v)
            except (TypeError, ValueError, OverflowError):
                x = float("nan")
            if not np.isfinite(x) or (k in positive and x <= 0):
                raise InputError(f"thigh camera: expected a {'positive ' if k in positive else ''}number for {k}, found {v!r}")

    @property
    def _out(self) -> float:
        return 1.0 if self.side == "right" else -1.0  # thigh y points right: outward on the right leg

    @property
    def offset_thigh_m(self) -> np.ndarray:
        """Optical centre in the thigh frame (x fwd, y right, z hip->knee)."""
        return np.array([0.0, self._out * self.outward_m, self.along_thigh_m])

    @property
    def rotation_thigh(self) -> np.ndarray:
        """Camera axes (columns: image x, image y, optical axis) in the thigh frame."""
        return _rot(0, -self._out * np.radians(self.tilt_out_deg))

    @property
    def intrinsics(self) -> np.ndarray:
        return np.array([[self.focal_px, 0.0, self.cx_px], [0.0, self.focal_px, self.cy_px], [0.0, 0.0, 1.0]])

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ThighCameraModel":
        return cls(**d)
