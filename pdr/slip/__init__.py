"""The SLIP walking model and its fit to leg-camera optical flow (Liu, MS thesis ch. 3-4), and the camera's floor
odometry scaled by the leg's stance geometry."""

from pdr.slip.fit import SlipOpticalFlowStride, calibrated_length_scale, segment_strides
from pdr.slip.model import SlipBody, SlipStep, StrideKinematics, simulate_flow, simulate_step, stride_kinematics
from pdr.slip.odometry import FloorOdometryStride

__all__ = [
    "FloorOdometryStride", "SlipOpticalFlowStride", "calibrated_length_scale", "segment_strides", "SlipBody", "SlipStep",
    "StrideKinematics", "simulate_flow", "simulate_step", "stride_kinematics"]
