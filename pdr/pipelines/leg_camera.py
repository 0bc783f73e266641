"""Strides from a leg-camera video: optical flow, then the SLIP model fitted to it (Liu, MS thesis).

Config sections: ``[flow]`` (CorrelationOpticalFlow parameters; defaults scaled to the frame size) and
``[slip_of]`` (SlipOpticalFlowStride parameters; body lengths default to the recording's ``[subject]``).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.flow import CorrelationOpticalFlow, read_video
from pdr.io.recording import Recording
from pdr.slip.fit import SlipOpticalFlowStride

CAMERA_KEYS = ("fps", "focal_px", "cx_px", "cy_px", "width_px", "height_px")
ANKLE_HEIGHT_RATIO = 0.039  # ankle height / body height (Winter 2009, Table 4.1)
DEFAULT_HEIGHT_M = 1.75
# the SLIP's shank reaches the ground (knee to heel), the subject's shank_length_m ends at the ankle


def _camera(cfg: dict[str, Any]) -> tuple[dict[str, float], dict[str, Any]]:
    cam, mount = cfg.get("camera"), cfg.get("mount")
    if not isinstance(cam, dict) or not isinstance(mount, dict):
        raise InputError(f"camera.toml: expected tables [camera] and [mount], found {', '.join(sorted(cfg)) or 'none'}")
    missing = [f"camera.{k}" for k in CAMERA_KEYS if k not in cam]
    missing += [f"mount.{k}" for k in ("segment", "distance_from_knee_m") if k not in mount]
    if missing:
        raise InputError(f"camera.toml: expected keys {', '.join(missing)}, found them missing")
    for key in CAMERA_KEYS:
        v = cam[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
            raise InputError(f"camera.toml: expected a positive number for camera.{key}, found {v!r}")
    if not str(mount["segment"]).startswith("shank_"):
        raise InputError(f"camera.toml: expected mount.segment shank_left or shank_right, found {mount['segment']!r}")
    return cam, mount


def forward_flow(flow: pd.DataFrame) -> np.ndarray:
    """Flow along the walking direction: the principal axis of the 2-D flow, signed so that swing bursts
    (the largest excursions) are positive."""
    xy = flow[["flow_x_pxps", "flow_y_pxps"]].to_numpy()
    ok = np.isfinite(xy).all(axis=1)
    if ok.sum() < 3:
        return np.full(len(xy), np.nan)
    _, _, vt = np.linalg.svd(xy[ok] - 0.0, full_matrices=False)
    proj = xy @ vt[0]
    lo, hi = np.nanpercentile(proj, [1, 99])
    return proj if hi >= -lo else -proj


def camera_strides(rec: Recording, config: dict) -> pd.DataFrame | None:
    """Strides of the camera leg (``t_start_s, t_end_s, foot, length_m, length_std_m, source``), None without video."""
    if rec.video_path is None:
        return None
    if rec.camera is None:
        raise InputError(f"{rec.video_path}: expected camera.toml beside the video, found none")
    cam, mount = _camera(rec.camera)
    n_expected = len(rec.frames) if rec.frames is not None else None
    frames = read_video(rec.video_path, expected_frames=n_expected)
    if frames.shape[1:] != (int(cam["height_px"]), int(cam["width_px"])):
        raise InputError(f"{rec.video_path}: expected {cam['width_px']}x{cam['height_px']} frames as camera.toml says, "
                         f"found {frames.shape[2]}x{frames.shape[1]}")
    t = rec.frames["t_s"].to_numpy() if rec.frames is not None else np.arange(len(frames)) / float(cam["fps"])
    side = min(frames.shape[1:])
    patch = max(12, side // 5)
    flow_defaults = {"patch_px": patch, "grid_step_px": patch, "max_shift_px": max(4, patch // 2 - 2), "predict": True}
    flow_est = CorrelationOpticalFlow.from_config({**flow_defaults, **config.get("flow", {})}).estimate(frames, t)
    flow = flow_est.flow_
    subject = rec.subject
    slip_defaults = {
        "camera_from_knee_m": float(mount["distance_from_knee_m"]),
        "focal_px": float(cam["focal_px"]),
        "foot": str(mount["segment"]).split("_")[1],
    }
    if "thigh_length_m" in subject:
        slip_defaults["thigh_length_m"] = float(subject["thigh_length_m"])
    if "shank_length_m" in subject:
        ankle = ANKLE_HEIGHT_RATIO * float(subject.get("height_m", DEFAULT_HEIGHT_M))
        slip_defaults["shank_length_m"] = float(subject["shank_length_m"]) + ankle
    if "foot_length_m" in subject:
        slip_defaults["foot_length_m"] = float(subject["foot_length_m"])
    if "mass_kg" in subject:
        slip_defaults["mass_kg"] = float(subject["mass_kg"])
    est = SlipOpticalFlowStride.from_config({**slip_defaults, **config.get("slip_of", {})})
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        est.estimate(flow["t_s"].to_numpy(), forward_flow(flow), flow["quality"].to_numpy())
    return est.strides_.reset_index(drop=True)
