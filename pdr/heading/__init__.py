"""Per-step heading: device yaw from the offline VQF attitude, the device-to-walking-direction offset, the magnetic heading."""

from pdr.heading.step_heading import AttitudeStepHeading, walking_direction

__all__ = ["AttitudeStepHeading", "walking_direction"]
