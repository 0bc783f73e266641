"""The signals of one IMU that several stages of a run read, each computed once, on first use."""

from __future__ import annotations

from functools import cached_property

import pandas as pd

from pdr.signals.attitude import Attitude, estimate_attitude
from pdr.signals.resample import UniformImu, uniform_imu


class ImuSignals:
    """An IMU table's uniform resampling (:func:`uniform_imu`, its gap warning once) and attitude
    (:func:`estimate_attitude` of it), computed when a stage first asks and then shared (treat them as read-only)."""

    def __init__(self, imu: pd.DataFrame):
        self.imu = imu

    @cached_property
    def uniform(self) -> UniformImu:
        return uniform_imu(self.imu)

    @cached_property
    def attitude(self) -> Attitude:
        return estimate_attitude(self.uniform)
