"""Body-frame and earth-frame signals from a recording's IMU table.

- :func:`uniform_imu`: the IMU on a uniform time grid (linear interpolation), with a mask of the samples that fall
  in a gap of the original clock (never interpolated across silently);
- :func:`estimate_attitude`: the offline VQF attitude (Laidig & Seel 2023), 6D and, with a magnetometer, 9D;
- :func:`earth_acceleration`: specific force rotated into the east-north-up frame, gravity removed;
- :func:`gravity_direction_lowpass`: the gravity direction without a gyroscope (moving average of the accelerometer);
- :class:`ImuSignals`: the resampling and the attitude of one IMU, computed once for every stage of a run.
"""

from pdr.signals.attitude import (
    Attitude, earth_acceleration, estimate_attitude, gravity_direction_lowpass, rotate, yaw_increments, yaw_of,
)
from pdr.signals.resample import UniformImu, moving_average, uniform_imu
from pdr.signals.shared import ImuSignals

__all__ = [
    "Attitude", "ImuSignals", "UniformImu", "earth_acceleration", "estimate_attitude", "gravity_direction_lowpass", "moving_average",
    "rotate", "uniform_imu", "yaw_increments", "yaw_of",
]
