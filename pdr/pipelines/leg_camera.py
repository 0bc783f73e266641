"""Strides from a leg-camera video: the camera's floor odometry scaled by the leg (default), or the SLIP model fitted
to the optical flow (Liu, MS thesis).

Config sections: ``[leg_camera] method = "odometry" | "slip_of"``; ``[homography]`` and ``[odometry]``
(:class:`pdr.flow.HomographyCameraMotion` and :class:`pdr.slip.FloorOdometryStride` parameters; the image centre's
flow of the homographies cuts the strides at heel strikes) or ``[flow]`` and ``[slip_of]`` (CorrelationOpticalFlow
parameters, defaults scaled to the frame size, and SlipOpticalFlowStride parameters). Body lengths come from the
recording's ``[subject]`` by :meth:`pdr.slip.model.SlipBody.from_user` (the lengths given, Winter's ratios to the
height for the others; the SLIP's foot, the lever of its toe pivot, Winter's for the height, not ``foot_length_m``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.flow import CameraModel, CorrelationOpticalFlow, HomographyCameraMotion, read_video
from pdr.io.recording import Recording
from pdr.slip import FloorOdometryStride, SlipOpticalFlowStride, segment_strides
from pdr.slip.model import ANKLE_HEIGHT_RATIO, SlipBody

DEFAULT_HEIGHT_M = 1.75  # a subject without a height: an adult of average height
STRIDE_METHODS = ("odometry", "slip_of")  # [leg_camera] method; its parameters are the section of that name
# each method's parameters that `pdr calibrate` fits and `pdr run --model` gives it (the SLIP-OF's sigma has no
# term for the scale's own uncertainty)
CALIBRATED_PARAMS = {"odometry": ("length_scale", "length_scale_std"), "slip_of": ("length_scale",)}


def stride_method(config: dict) -> str:
    """The ``[leg_camera] method`` of a configuration (default "odometry"); its parameters are the section of that name."""
    section = dict(config.get("leg_camera") or {})
    unknown = sorted(set(section) - {"method"})
    method = section.get("method", "odometry")
    if unknown or method not in STRIDE_METHODS:
        raise InputError(f"configuration [leg_camera]: expected only method = {' or '.join(map(repr, STRIDE_METHODS))}, "
                         f"found {section!r}")
    return method


def camera_sections(config: dict) -> tuple[str, dict]:
    """The stride method and the leg camera's sections of a configuration (``[leg_camera]``, ``[flow]``,
    ``[homography]`` and the method's), as :func:`camera_strides` takes them."""
    method = stride_method(config)
    return method, {key: dict(config.get(key) or {}) for key in ("leg_camera", "flow", "homography", method)}


def forward_flow(flow: pd.DataFrame) -> np.ndarray:
    """Flow along the walking direction: the principal axis of the 2-D flow, signed so that swing bursts
    (the largest excursions) are positive."""
    xy = flow[["flow_x_pxps", "flow_y_pxps"]].to_numpy()
    ok = np.isfinite(xy).all(axis=1)
    if ok.sum() < 3:
        return np.full(len(xy), np.nan)
    _, _, vt = np.linalg.svd(xy[ok], full_matrices=False)
    proj = xy @ vt[0]
    lo, hi = np.nanpercentile(proj, [1, 99])
    return proj if hi >= -lo else -proj


def flow_defaults(height_px: int, width_px: int) -> dict:
    """``[flow]`` defaults for a frame size: square patches of a fifth of the shorter side on a 3x3 grid, searched
    just under half a patch around the predicted shift, after a Gaussian pre-blur of a twelfth of a patch (2 px at
    the 24 px patches of 160x120 frames). The thesis' blur (1 px) lets patches lock on a repeating floor: on the
    leg-camera benchmark's tuning walks the tracker's own stride error (beyond a perfect tracker's) is -10.4 / -4.9
    / -3.2 / -3.2% on brick at 1 px, -1.5 / -0.6 / +1.3 / +0.1% at 2 px; gravel and grass stay within a point but
    for the 60 fps gravel walk whose flow locks at a heel strike (+2.5 -> +9.4%); mean |error| 2.4% at 1 px, 2.9 /
    1.4 / 3.9 / 4.4% at 1.5 / 2 / 2.5 / 3 px."""
    patch = max(12, min(height_px, width_px) // 5)
    return {"patch_px": patch, "grid_step_px": patch, "max_shift_px": max(4, patch // 2 - 2), "predict": True,
            "blur_sigma_px": patch / 12.0}


def cut_strides(flow: pd.DataFrame) -> pd.DataFrame:
    """The camera leg's strides, heel strike to heel strike, cut from a flow series (``t_s, flow_x_pxps, flow_y_pxps,
    quality``: :class:`CorrelationOpticalFlow`'s or :class:`HomographyCameraMotion`'s) by
    :func:`pdr.slip.segment_strides` of its forward flow where measured."""
    quality = flow["quality"].to_numpy()
    return segment_strides(flow["t_s"].to_numpy(), np.where(quality > 0, forward_flow(flow), np.nan))


def camera_strides(rec: Recording, config: dict) -> pd.DataFrame | None:
    """Strides of the camera leg (``t_start_s, t_end_s, foot, length_m, length_std_m, source``), None without video."""
    if rec.video_path is None:
        return None
    method = stride_method(config)
    if rec.camera is None:
        raise InputError(f"{rec.video_path}: expected camera.toml beside the video, found none")
    cam = CameraModel.from_toml(rec.camera, what=f"{rec.path or rec.id}/camera.toml")
    n_expected = len(rec.frames) if rec.frames is not None else None
    frames = read_video(rec.video_path, expected_frames=n_expected)
    if frames.shape[1:] != (cam.height_px, cam.width_px):
        raise InputError(f"{rec.video_path}: expected {cam.width_px}x{cam.height_px} frames as camera.toml says, "
                         f"found {frames.shape[2]}x{frames.shape[1]}")
    t = rec.frames["t_s"].to_numpy() if rec.frames is not None else np.arange(len(frames)) / cam.fps
    subject = rec.subject
    lengths = {k: float(subject[k]) for k in ("leg_length_m", "shank_length_m", "thigh_length_m")
               if k in subject}
    height_m = float(subject.get("height_m", DEFAULT_HEIGHT_M))
    body = SlipBody.from_user(height_m, **lengths)
    if method == "odometry":
        motion = HomographyCameraMotion.from_config({"focal_px": cam.focal_px, "cx_px": cam.cx_px, "cy_px": cam.cy_px,
                                                     **config.get("homography", {})}).estimate(frames, t).motion_
        est = FloorOdometryStride.from_config({"shank_length_m": body.shank_length_m,
                                               "ankle_height_m": ANKLE_HEIGHT_RATIO * height_m,
                                               "camera_from_knee_m": cam.distance_from_knee_m, "foot": cam.side,
                                               **config.get("odometry", {})})
        return est.estimate(motion, cut_strides(motion)).strides_.reset_index(drop=True)
    slip_defaults = {
        "thigh_length_m": body.thigh_length_m,
        "shank_length_m": body.shank_length_m,
        "foot_length_m": body.foot_length_m,
        "camera_from_knee_m": cam.distance_from_knee_m,
        "focal_px": cam.focal_px,
        "foot": cam.side,
    }
    flow = CorrelationOpticalFlow.from_config({**flow_defaults(*frames.shape[1:]), **config.get("flow", {})}
                                              ).estimate(frames, t).flow_
    est = SlipOpticalFlowStride.from_config({**slip_defaults, **config.get("slip_of", {})})
    est.estimate(flow["t_s"].to_numpy(), forward_flow(flow), flow["quality"].to_numpy())
    return est.strides_.reset_index(drop=True)
