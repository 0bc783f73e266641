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

import dataclasses
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.io.atomic import atomic_path

CAMERA_KEYS = ("fps", "focal_px", "cx_px", "cy_px", "width_px", "height_px")
MOUNT_KEYS = ("segment", "distance_from_knee_m")
SEGMENTS = ("shank_left", "shank_right", "thigh_left", "thigh_right")
TEXTURES = ("gravel", "brick")
SKY_GREY = 128.0


class Kinematics(Protocol):
    def joint_positions_m(self, t_s: np.ndarray) -> dict[str, np.ndarray]: ...

    def segment_rotation(self, t_s: np.ndarray, segment: str) -> np.ndarray: ...


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


def load_texture(name_or_path: str | Path, datasets: Path | None = None) -> np.ndarray:
    """A grey ground texture: ``gravel`` / ``brick`` from ``ground_textures_cc0`` (the project's ``datasets/``
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


# ----------------------------------------------------------------------------------------------------------------
# A sagittal walking model for the renderer's own tests and benchmark (richer than SLIP): joint angles as
# Fourier series of the gait phase, the pelvis carried by the lowest point of either foot (no slipping, double
# support where both feet are down). ``pdr.sim.gait.WalkKinematics`` (the simulator's full-body model) offers
# the same two methods and is rendered the same way.
# ----------------------------------------------------------------------------------------------------------------

# Key points (gait phase from heel strike, degrees) of normal walking, after the textbook curves
# (Winter, Biomechanics and Motor Control of Human Movement, ch. 7): hip flexion, knee flexion, ankle dorsiflexion.
_HIP_KEYS = ((0.0, 25.0), (0.15, 20.0), (0.35, 2.0), (0.52, -12.0), (0.62, -5.0), (0.75, 18.0), (0.87, 27.0), (0.95, 26.0))
_KNEE_KEYS = ((0.0, 4.0), (0.15, 18.0), (0.30, 10.0), (0.42, 5.0), (0.60, 38.0), (0.72, 62.0), (0.85, 35.0), (0.96, 4.0))
_ANKLE_KEYS = ((0.0, 0.0), (0.07, -6.0), (0.30, 5.0), (0.48, 10.0), (0.62, -16.0), (0.72, -4.0), (0.85, 2.0), (0.95, 1.0))
_HARMONICS = 5


def _fourier_fit(keys: tuple[tuple[float, float], ...]) -> np.ndarray:
    """Coefficients (a0, a1, b1, ...) of a 5-harmonic series through periodic key points (least squares on a
    periodic linear interpolation of the keys, then smooth)."""
    ph = np.array([k[0] for k in keys] + [keys[0][0] + 1.0])
    val = np.array([k[1] for k in keys] + [keys[0][1]])
    x = np.linspace(0.0, 1.0, 200, endpoint=False)
    y = np.interp(x, ph, val)
    cols = [np.ones_like(x)]
    for h in range(1, _HARMONICS + 1):
        cols += [np.cos(2 * np.pi * h * x), np.sin(2 * np.pi * h * x)]
    return np.linalg.lstsq(np.column_stack(cols), y, rcond=None)[0]


def _fourier_eval(coef: np.ndarray, phase: np.ndarray) -> np.ndarray:
    out = np.full_like(phase, coef[0], dtype=float)
    for h in range(1, _HARMONICS + 1):
        out += coef[2 * h - 1] * np.cos(2 * np.pi * h * phase) + coef[2 * h] * np.sin(2 * np.pi * h * phase)
    return out


class FourierLegWalk:
    """Straight walk along +x (east) from sagittal joint-angle Fourier series (hip, knee, ankle).

    Parameters
    ----------
    stride_time_s : gait cycle duration.
    amplitude : scale of the hip and knee excursions about their means (longer strides at 1.1-1.3).
    thigh_length_m, shank_length_m : segment lengths; foot: ankle 0.08 m above the sole, heel 0.05 m behind
        and toe 0.15 m ahead of the ankle.
    duration_s : length of the walk.

    Methods ``joint_positions_m(t)`` and ``segment_rotation(t, segment)`` follow ``pdr.sim.gait.WalkKinematics``;
    ``true_strides(side)`` gives heel strike to heel strike lengths.
    """

    def __init__(self, *, stride_time_s: float = 1.1, amplitude: float = 1.0, thigh_length_m: float = 0.45,
                 shank_length_m: float = 0.45, duration_s: float = 20.0, rate_hz: float = 1000.0):
        self.stride_time_s = stride_time_s
        self.amplitude = amplitude
        self.lth, self.lsh = thigh_length_m, shank_length_m
        self.heel_off = np.array([-0.05, -0.08])
        self.toe_off = np.array([0.15, -0.08])
        self._coef = {k: _fourier_fit(v) for k, v in (("hip", _HIP_KEYS), ("knee", _KNEE_KEYS), ("ankle", _ANKLE_KEYS))}
        self._t = np.arange(0.0, duration_s + 1.0 / rate_hz, 1.0 / rate_hz)
        rel = {side: self._leg(self._t, side) for side in ("left", "right")}
        sole = np.stack([rel[s][p][:, 1] for s in rel for p in ("heel", "toe")], axis=1)  # z of 4 sole points
        lowest = np.argmin(sole, axis=1)
        pel_z = -sole[np.arange(len(self._t)), lowest]
        xs = np.stack([rel[s][p][:, 0] for s in rel for p in ("heel", "toe")], axis=1)
        vx = np.gradient(xs, self._t, axis=0)[np.arange(len(self._t)), lowest]
        pel_x = np.concatenate([[0.0], np.cumsum(0.5 * (-vx[1:] - vx[:-1]) * np.diff(self._t))])
        self._pelvis = np.column_stack([pel_x, pel_z])
        self._rel = rel

    def _angles(self, t: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        phase = np.mod(t / self.stride_time_s + (0.0 if side == "left" else 0.5), 1.0)
        hip = np.radians(_fourier_eval(self._coef["hip"], phase))
        knee = np.radians(_fourier_eval(self._coef["knee"], phase))
        ankle = np.radians(_fourier_eval(self._coef["ankle"], phase))
        hip = np.radians(self._coef["hip"][0]) + self.amplitude * (hip - np.radians(self._coef["hip"][0]))
        knee = np.radians(self._coef["knee"][0]) + self.amplitude * (knee - np.radians(self._coef["knee"][0]))
        return hip, hip - knee, hip - knee + ankle  # thigh, shank (from vertical), foot pitch

    def _leg(self, t: np.ndarray, side: str) -> dict[str, np.ndarray]:
        th, sh, ft = self._angles(t, side)
        knee = self.lth * np.column_stack([np.sin(th), -np.cos(th)])
        ankle = knee + self.lsh * np.column_stack([np.sin(sh), -np.cos(sh)])
        c, s = np.cos(ft), np.sin(ft)

        def foot_point(off):
            return ankle + np.column_stack([c * off[0] - s * off[1], s * off[0] + c * off[1]])

        return {"knee": knee, "ankle": ankle, "heel": foot_point(self.heel_off), "toe": foot_point(self.toe_off)}

    def joint_positions_m(self, t_s: np.ndarray) -> dict[str, np.ndarray]:
        t = np.asarray(t_s, float)
        if t.min() < self._t[0] or t.max() > self._t[-1]:
            raise InputError(f"FourierLegWalk: expected times within 0..{self._t[-1]:.1f} s, found {t.min():.2f}..{t.max():.2f}")
        px = np.interp(t, self._t, self._pelvis[:, 0])
        pz = np.interp(t, self._t, self._pelvis[:, 1])
        out = {"pelvis": np.column_stack([px, np.zeros_like(t), pz])}
        for side, y in (("left", 0.1), ("right", -0.1)):
            out[f"hip_{side}"] = np.column_stack([px, np.full_like(t, y), pz])
            for name, p in self._leg(t, side).items():
                out[f"{name}_{side}"] = np.column_stack([px + p[:, 0], np.full_like(t, y), pz + p[:, 1]])
        return out

    def segment_rotation(self, t_s: np.ndarray, segment: str) -> np.ndarray:
        part, side = segment.split("_")
        th, sh, ft = self._angles(np.asarray(t_s, float), side)
        ang = {"thigh": th, "shank": sh}.get(part)
        if ang is None:
            raise InputError(f"FourierLegWalk: expected a thigh or shank segment, found {segment!r}")
        c, s = np.cos(ang), np.sin(ang)
        z = np.zeros_like(c)
        # columns: x forward normal (c, 0, s), y = z x x = (0, -1, 0), z along the segment (s, 0, -c)
        return np.stack([np.stack([c, z, s], -1), np.stack([z, z - 1.0, z], -1), np.stack([s, z, -c], -1)], axis=-1)

    def true_strides(self, side: str = "left") -> pd.DataFrame:
        """Heel strike (phase 0) to heel strike of one leg, length = heel advance (``reference/strides.csv``)."""
        offset = 0.0 if side == "left" else 0.5 * self.stride_time_s
        hs = np.arange(offset, self._t[-1], self.stride_time_s)
        heel = self.joint_positions_m(hs)[f"heel_{side}"][:, 0]
        return pd.DataFrame({"t_start_s": hs[:-1], "t_end_s": hs[1:], "foot": side, "length_m": np.diff(heel)})


def camera_from_section(section: dict[str, Any]) -> CameraModel:
    """The camera of a scenario's ``[camera]`` section (keys of camera.toml's [camera] plus ``segment`` and
    ``distance_from_knee_m``); defaults: 160x120 at 100 fps, focal 120 px, left shank, 0.25 m below the knee."""
    sec = dict(section or {})
    known = {"fps", "focal_px", "width_px", "height_px", "cx_px", "cy_px", "segment", "distance_from_knee_m",
             "texture", "texture_m_per_px", "exposure_s", "noise_std", "gain_drift"}
    unknown = sorted(set(sec) - known)
    if unknown:
        raise InputError(f"scenario [camera]: unknown key(s) {', '.join(unknown)}; expected some of {', '.join(sorted(known))}")
    w, h = int(sec.get("width_px", 160)), int(sec.get("height_px", 120))
    cfg = {"camera": {"fps": sec.get("fps", 100.0), "focal_px": sec.get("focal_px", 120.0), "width_px": w, "height_px": h,
                      "cx_px": sec.get("cx_px", (w - 1) / 2.0), "cy_px": sec.get("cy_px", (h - 1) / 2.0)},
           "mount": {"segment": sec.get("segment", "shank_left"), "distance_from_knee_m": sec.get("distance_from_knee_m", 0.25)}}
    return CameraModel.from_toml(cfg, what="scenario [camera]")


def write_leg_camera(rec_dir: str | Path, kin: Kinematics, section: dict[str, Any], t_start_s: float, t_end_s: float,
                     *, seed: int = 0) -> CameraModel:
    """Render the walk into ``rec_dir``: ``video.avi``, ``frames.csv`` and ``camera.toml`` (CONTRACT.md).

    The hook of ``pdr.sim.simulate`` for a scenario ``[camera]`` section; the true strides of the camera leg go to
    ``reference/strides.csv`` from the walk itself.
    """
    from pdr.io.atomic import write_csv, write_text
    from pdr.io.tomlio import dumps_toml

    cam = camera_from_section(section)
    params = {k: section[k] for k in ("texture_m_per_px", "exposure_s", "noise_std", "gain_drift") if k in section}
    texture = load_texture(section.get("texture", "gravel"))
    frames, table = render_leg_camera(kin, cam, t_start_s, t_end_s, texture, seed=seed, **params)
    rec_dir = Path(rec_dir)
    write_video(rec_dir / "video.avi", frames, cam.fps)
    write_csv(rec_dir / "frames.csv", table)
    write_text(rec_dir / "camera.toml", dumps_toml(cam.to_toml()))
    return cam
