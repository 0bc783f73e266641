"""The leg camera of a recording (``camera.toml`` of CONTRACT.md): a pinhole camera and its mount on the shank."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pdr.errors import InputError

CAMERA_KEYS = ("fps", "focal_px", "cx_px", "cy_px", "width_px", "height_px")
MOUNT_KEYS = ("segment", "distance_from_knee_m")
SEGMENTS = ("shank_left", "shank_right", "thigh_left", "thigh_right")


@dataclasses.dataclass(frozen=True)
class CameraModel:
    """A pinhole camera and its mount (the contents of ``camera.toml``)."""

    fps: float
    focal_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int
    segment: str
    distance_from_knee_m: float

    @classmethod
    def from_toml(cls, cfg: dict[str, Any], what: str = "camera.toml") -> "CameraModel":
        """Validate a parsed ``camera.toml`` (``[camera]`` and ``[mount]`` tables)."""
        cam, mount = cfg.get("camera"), cfg.get("mount")
        if not isinstance(cam, dict) or not isinstance(mount, dict):
            raise InputError(f"{what}: expected tables [camera] and [mount], found {', '.join(sorted(cfg)) or 'none'}")
        missing = [f"camera.{k}" for k in CAMERA_KEYS if k not in cam] + [f"mount.{k}" for k in MOUNT_KEYS if k not in mount]
        if missing:
            raise InputError(f"{what}: expected keys {', '.join(missing)}, found them missing")
        for k in CAMERA_KEYS + ("distance_from_knee_m",):
            v = cam.get(k, mount.get(k))
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
                raise InputError(f"{what}: expected a positive number for {k}, found {v!r}")
        if mount["segment"] not in SEGMENTS:
            raise InputError(f"{what}: expected mount.segment one of {', '.join(SEGMENTS)}, found {mount['segment']!r}")
        if not mount["segment"].startswith("shank"):
            raise InputError(f"{what}: expected a shank mount (the stride model looks along the shank), found {mount['segment']!r}")
        return cls(fps=float(cam["fps"]), focal_px=float(cam["focal_px"]), cx_px=float(cam["cx_px"]),
                   cy_px=float(cam["cy_px"]), width_px=int(cam["width_px"]), height_px=int(cam["height_px"]),
                   segment=str(mount["segment"]), distance_from_knee_m=float(mount["distance_from_knee_m"]))

    def to_toml(self) -> dict[str, dict[str, Any]]:
        return {"camera": {"fps": self.fps, "focal_px": self.focal_px, "cx_px": self.cx_px, "cy_px": self.cy_px,
                           "width_px": self.width_px, "height_px": self.height_px},
                "mount": {"segment": self.segment, "distance_from_knee_m": self.distance_from_knee_m}}

    @property
    def side(self) -> str:
        return self.segment.split("_")[1]

    def intrinsics(self, scale: float = 1.0) -> np.ndarray:
        return np.array([[self.focal_px * scale, 0.0, (self.cx_px + 0.5) * scale - 0.5],
                         [0.0, self.focal_px * scale, (self.cy_px + 0.5) * scale - 0.5],
                         [0.0, 0.0, 1.0]])
