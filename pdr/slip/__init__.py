"""The SLIP walking model and its fit to leg-camera optical flow (Liu, MS thesis ch. 3-4)."""

from pdr.slip.fit import SlipOpticalFlowStride, calibrated_length_scale, segment_strides
from pdr.slip.model import SlipBody, SlipStep, StrideKinematics, simulate_flow, simulate_step, stride_kinematics

__all__ = [
    "SlipOpticalFlowStride", "calibrated_length_scale", "segment_strides","SlipBody", "SlipStep", "StrideKinematics", "simulate_flow", "simulate_step", "stride_kinematics"]
