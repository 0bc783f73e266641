"""Optical flow measurement of a leg-camera video (Liu, MS thesis ch. 2): per frame pair, px/s, with a quality; and the
camera's own motion over the floor from the plane homography between frames."""

from pdr.flow.camera import CameraModel
from pdr.flow.homography import MOTION_COLUMNS, HomographyCameraMotion
from pdr.flow.methods import (
    FLOW_COLUMNS,
    CorrelationOpticalFlow,
    InterpolationOpticalFlow,
    PhaseCorrelationOpticalFlow,
)
from pdr.flow.video import check_video, read_video

__all__ = [
    "CameraModel", "FLOW_COLUMNS", "MOTION_COLUMNS", "CorrelationOpticalFlow", "HomographyCameraMotion", "InterpolationOpticalFlow", "PhaseCorrelationOpticalFlow", "check_video", "read_video",
]
