"""Shoe-mounted IMUs: stance/swing segmentation, FootStep-Tracker stride length, zero-velocity-aided foot INS.

- :class:`ZeroVelocityDetection` - stance and swing phases (SHOE detector, minimum stance and swing durations).
- :class:`FootStepTrackerStride` - critical times (Algorithm 1), pitch (eq. 3), horizontal projection (eq. 2),
  toe-in / toe-out (eq. 1), double integration with zero velocity at rest (FootStep-Tracker, seed 002).
- :class:`DoubleFeetCalibration` - combines the two shoes' measures of each gait cycle.
- :class:`ZuptInsStride` - error-state Kalman INS per foot with zero-velocity updates; strides with covariance.
"""

from pdr.foot.double_feet import DoubleFeetCalibration
from pdr.foot.footstep_tracker import FootStepTrackerStride
from pdr.foot.frame import estimate_foot_frame
from pdr.foot.zero_velocity import ZeroVelocityDetection
from pdr.foot.zupt_ins import ZuptInsStride

__all__ = ["DoubleFeetCalibration", "FootStepTrackerStride", "ZeroVelocityDetection", "ZuptInsStride",
           "estimate_foot_frame"]
