"""The SLIP walking model and its fit to leg-camera optical flow (Liu, MS thesis ch. 3-4)."""

from pdr.slip.model import SlipBody, SlipStep, StrideKinematics, simulate_flow, simulate_step, stride_kinematics

__all__ = ["SlipBody", "SlipStep", "StrideKinematics", "simulate_flow", "simulate_step", "stride_kinematics"]
