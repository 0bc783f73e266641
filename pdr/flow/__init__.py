"""Optical flow measurement of a leg-camera video (Liu, MS thesis ch. 2): per frame pair, px/s, with a quality."""

from pdr.flow.camera import CameraModel
from pdr.flow.methods import (
    FLOW_COLUMNS,
    CorrelationOpticalFlow,
    InterpolationOpticalFlow,
    PhaseCorrelationOpticalFlow,
)
from pdr.flow.video import check_video, read_video

__all__ = [
    "CameraModel",    "FLOW_COLUMNS", "CorrelationOpticalFlow", "InterpolationOpticalFlow", "PhaseCorrelationOpticalFlow", "check_video", "read_video",
]
