"""Per-step heading: device yaw from the offline VQF attitude, the device-to-walking-direction offset, the magnetic heading."""

from pdr.heading.step_heading import AttitudeStepHeading, gait_phase_sign, walking_direction

__all__ = ["AttitudeStepHeading", "gait_phase_sign", "walking_direction"]
