"""The leg-camera renderer: a camera on the shank, looking along it at a textured ground plane.

Every frame is a projective warp (``cv2.warpPerspective``) of a real ground texture (tiled by mirroring) through
the homography between the ground plane z = 0 and the image of the camera at its pose of that instant; the pose
comes from the walking kinematics (``WalkKinematics.joint_positions_m`` / ``segment_rotation``). Motion blur
(sub-frame renders averaged over the exposure), sensor noise, a slowly drifting exposure gain and a 2x
super-sampling against aliasing make it look like a camera, not a lookup. Pixels whose ray misses the ground
(above the horizon) are a flat grey.

Camera frame: optical axis = the shank z axis (knee to ankle); image x = the shank x axis, image y = the shank
y axis (a right-handed camera, x right, y down, z into the scene).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.flow.camera import CAMERA_KEYS, MOUNT_KEYS, CameraModel  # noqa: F401 (re-exported for pdr.sim.simulator)
from pdr.io.atomic import atomic_path

TEXTURES = ("gravel", "brick", "grass")
SKY_GREY = 128.0


class Kinematics(Protocol):
    def joint_positions_m(self, t_s: np.ndarray) -> dict[str, np.ndarray]: ...

    def segment_rotation(self, t_s: np.ndarray, segment: str) -> np.ndarray: ...


def load_texture(name_or_path: str | Path, datasets: Path | None = None) -> np.ndarray:
    """A grey ground texture: ``gravel`` / ``brick`` / ``grass`` from ``ground_textures_cc0`` (the project's ``datasets/``
    copy or ``../shared/datasets``), or a path to an image file."""
    path = Path(name_or_path)
    if str(name_or_path) in TEXTURES:
        root = Path(__file__).resolve().parents[2]
        candidates = ([datasets] if datasets else []) + [root / "datasets", root.parent / "shared" / "datasets"]
        for base in candidates:
            p = base / "ground_textures_cc0" / f"{name_or_path}.png"
            if p.is_file():
                path = p
                break
        else:
            raise InputError(f"texture {name_or_path!r}: expected ground_textures_cc0/{name_or_path}.png under datasets/, found none")
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise InputError(f"texture {path}: expected an image file OpenCV can read, found {'nothing' if not path.exists() else 'unreadable content'}")
    return img


class LegCameraRenderer:
    """Renders the frames of a shank camera walking over a textured ground plane.

    Parameters
    ----------
    camera : the camera model and its mount.
    texture : grey texture image (uint8), tiled over the ground by mirroring.
    texture_m_per_px : ground size of one texture pixel.
    exposure_s : exposure time; motion blur averages ``blur_samples`` poses over it.
    noise_std : sensor noise, grey levels (1-sigma).
    gain_drift : amplitude of the slow exposure gain change (0.1: +/-10% over ~7 s), plus 1% per-frame jitter.
    seed : random seed of the noise and the gain.
    """

    def __init__(self, camera: CameraModel, texture: np.ndarray, *, texture_m_per_px: float = 0.002,
                 exposure_s: float = 0.002, blur_samples: int = 4, noise_std: float = 2.0, gain_drift: float = 0.1,
                 supersample: int = 2, seed: int = 0):
        self.camera = camera
        self.texture_m_per_px = texture_m_per_px
        self.exposure_s = exposure_s
        self.blur_samples = max(1, int(blur_samples))
        self.noise_std = noise_std
        self.gain_drift = gain_drift
        self.supersample = max(1, int(supersample))
        self.seed = seed
        tex = np.asarray(texture)
        if tex.ndim != 2 or min(tex.shape) < 16:
            raise InputError(f"texture: expected a grey image of at least 16x16 px, found shape {tex.shape}")
        block = np.block([[tex, tex[:, ::-1]], [tex[::-1, :], tex[::-1, ::-1]]])  # one mirrored period
        self._period = np.array(block.shape[::-1], float)  # (width, height) in texture px
        self._mosaic = np.tile(block, (3, 3)).astype(np.uint8)

    def _pose(self, kin: Kinematics, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        side = self.camera.side
        knee = np.asarray(kin.joint_positions_m(t)[f"knee_{side}"], float)
        rot = np.asarray(kin.segment_rotation(t, self.camera.segment), float)
        centre = knee + self.camera.distance_from_knee_m * rot[:, :, 2]
        return centre, rot

    def _warp(self, centre: np.ndarray, rot: np.ndarray) -> np.ndarray:
        s = self.supersample
        w, h = self.camera.width_px * s, self.camera.height_px * s
        k = self.camera.intrinsics(s)
        r_cw = rot.T  # world -> camera
        h_g2i = k @ np.column_stack([r_cw[:, 0], r_cw[:, 1], -r_cw @ centre])  # ground (x, y, 1) -> image
        # ground metres -> texture pixels, shifted by whole mirrored periods to stay in the central block
        sc = 1.0 / self.texture_m_per_px
        u0, v0 = centre[0] * sc, -centre[1] * sc
        off_u = self._period[0] * (1.0 - np.floor(u0 / self._period[0]))
        off_v = self._period[1] * (1.0 - np.floor(v0 / self._period[1]))
        g2t = np.array([[sc, 0.0, off_u], [0.0, -sc, off_v], [0.0, 0.0, 1.0]])
        i2t = g2t @ np.linalg.inv(h_g2i)
        img = cv2.warpPerspective(self._mosaic, i2t, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                  borderMode=cv2.BORDER_REFLECT).astype(np.float32)
        # rays that do not go down to the ground see a flat background
        ki = np.linalg.inv(k)
        down = (rot @ ki)[2]  # world z of the ray direction, linear in (u, v, 1)
        uu, vv = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        sky = down[0] * uu + down[1] * vv + down[2] >= -1e-3
        img[sky] = SKY_GREY
        return img

    def render(self, kin: Kinematics, t_s: np.ndarray) -> np.ndarray:
        """(N, H, W) uint8 frames at times ``t_s`` (the middle of each exposure)."""
        t = np.asarray(t_s, float)
        n_sub = self.blur_samples
        offsets = (np.arange(n_sub) + 0.5) / n_sub - 0.5 if n_sub > 1 else np.zeros(1)
        t_all = (t[:, None] + offsets[None, :] * self.exposure_s).ravel()
        centres, rots = self._pose(kin, t_all)
        if (centres[:, 2] <= 0).any():
            raise InputError("leg camera: expected the camera above the ground (z > 0), found it at or below")
        rng = np.random.default_rng(self.seed)
        phase = rng.uniform(0, 2 * np.pi)
        gain = 1.0 + self.gain_drift * np.sin(2 * np.pi * t / 7.0 + phase) + 0.01 * rng.standard_normal(len(t))
        out = np.empty((len(t), self.camera.height_px, self.camera.width_px), np.uint8)
        size = (self.camera.width_px, self.camera.height_px)
        for i in range(len(t)):
            acc = None
            for j in range(n_sub):
                img = self._warp(centres[i * n_sub + j], rots[i * n_sub + j])
                acc = img if acc is None else acc + img
            frame = cv2.resize(acc / n_sub, size, interpolation=cv2.INTER_AREA) if self.supersample > 1 else acc / n_sub
            frame = frame * gain[i] + self.noise_std * rng.standard_normal(frame.shape)
            out[i] = np.clip(np.rint(frame), 0, 255).astype(np.uint8)
        return out


def write_video(path: str | Path, frames: np.ndarray, fps: float) -> None:
    """Grey frames to a lossless FFV1 AVI (atomically); read back by ``pdr.flow.read_video``."""
    frames = np.asarray(frames, np.uint8)
    h, w = frames.shape[1:]
    with atomic_path(path) as tmp:
        avi = tmp.with_suffix(".avi")
        writer = cv2.VideoWriter(str(avi), cv2.VideoWriter_fourcc(*"FFV1"), float(fps), (w, h), isColor=False)
        try:
            if not writer.isOpened():
                raise InputError(f"{path}: expected OpenCV to open an FFV1 AVI writer, found it unavailable")
            for f in frames:
                writer.write(f)
        finally:
            writer.release()
        avi.replace(tmp)


def render_leg_camera(kin: Kinematics, camera: CameraModel, t_start_s: float, t_end_s: float, texture: np.ndarray,
                      **renderer_params: Any) -> tuple[np.ndarray, pd.DataFrame]:
    """Frames of the walk between two times at the camera's rate, and ``frames.csv`` (``t_s`` per frame)."""
    n = int(np.floor((t_end_s - t_start_s) * camera.fps)) + 1
    t = t_start_s + np.arange(n) / camera.fps
    frames = LegCameraRenderer(camera, texture, **renderer_params).render(kin, t)
    return frames, pd.DataFrame({"t_s": t})
